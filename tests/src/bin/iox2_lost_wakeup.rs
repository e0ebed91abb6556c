//! `iox2-lost-wakeup [ROUNDS]`: a minimal program, for an upstream report, showing that an
//! iceoryx2 0.10 event listener's file descriptor can stay unreadable after `Notifier::notify`
//! returned Ok: a waiter that sleeps on the fd (poll/epoll, as iceoryx2's WaitSet does) misses
//! the wake-up. It uses only iceoryx2's public API and its default configuration, none of the
//! rig's code.
//!
//! Each round, a notifier thread notifies without pause for 200 µs while the main thread does what
//! every fd-based waiter does: when the fd is readable, `Listener::try_wait`. When the burst is
//! over and the fd is quiet, one more `notify` must make the fd readable; if it does not within
//! 100 ms, the wake-up was lost (and every later `notify` is lost too, until something calls
//! `try_wait` on the listener: the program does, and counts the activations it finds).
//!
//! Why (iceoryx2-cal 0.10, `event/common.rs`): the listener's notifiers share one notification
//! state, idle → pending → notified. `notify` activates its event id, moves idle → pending, sends
//! a datagram and then moves pending → notified; while the state is notified, `notify` sends no
//! datagram. `try_wait` moves notified → idle and then empties the socket. A `notify` that
//! starts after that move and sends before the socket is emptied has its datagram eaten, and
//! its late pending → notified lands after the drain: state "notified", socket empty. From then
//! on no `notify` sends a datagram. One notifier is enough; two controllers answering the same
//! tick hit it in the rig (issue 22). Exit status: 0 when no wake-up was lost, 1 when one was.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use iceoryx2::prelude::*;
use iceoryx2_bb_posix::file_descriptor::FileDescriptorBased;

/// How long each round's notifier notifies without pause.
const BURST: Duration = Duration::from_micros(200);

fn readable(fd: i32, timeout: Duration) -> bool {
    let mut pfd = libc::pollfd { fd, events: libc::POLLIN, revents: 0 };
    // SAFETY: one valid pollfd.
    unsafe { libc::poll(&mut pfd, 1, timeout.as_millis() as i32) > 0 }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let rounds: u64 = std::env::args().nth(1).map_or(Ok(2000), |s| s.parse())?;
    let service = format!("iox2-lost-wakeup-{}", std::process::id());
    let node = NodeBuilder::new().create::<ipc::Service>()?;
    let event = node.service_builder(&service.as_str().try_into()?).event().open_or_create()?;
    let listener = event.listener_builder().create()?;
    let probe = event.notifier_builder().create()?;
    // SAFETY: the fd lives as long as `listener`, which outlives every use below.
    let fd = unsafe { listener.file_descriptor().native_handle() };

    // The notifier thread: its own node and notifier (ipc ports stay on their thread).
    let go = Arc::new(AtomicU64::new(0));
    let done = Arc::new(AtomicU64::new(0));
    let stop = Arc::new(AtomicBool::new(false));
    let t = {
        let (go, done, stop, service) = (go.clone(), done.clone(), stop.clone(), service.clone());
        std::thread::spawn(move || -> Result<(), String> {
            let e = |x: &dyn std::fmt::Debug| format!("{x:?}");
            let node = NodeBuilder::new().create::<ipc::Service>().map_err(|x| e(&x))?;
            let name: ServiceName = service.as_str().try_into().map_err(|x| e(&x))?;
            let event = node.service_builder(&name).event().open_or_create().map_err(|x| e(&x))?;
            let notifier = event.notifier_builder().create().map_err(|x| e(&x))?;
            let mut seen = 0;
            while !stop.load(Ordering::Acquire) {
                let r = go.load(Ordering::Acquire);
                if r == seen {
                    std::hint::spin_loop();
                    continue;
                }
                seen = r;
                let end = std::time::Instant::now() + BURST;
                while std::time::Instant::now() < end {
                    notifier.notify().map_err(|x| e(&x))?;
                }
                done.store(r, Ordering::Release);
            }
            Ok(())
        })
    };

    let mut lost = 0u64;
    for round in 1..=rounds {
        go.store(round, Ordering::Release);
        // Wake and drain as a waiter does, while the burst goes on.
        while done.load(Ordering::Acquire) != round {
            if readable(fd, Duration::ZERO) {
                listener.try_wait(|_| {})?;
            }
        }
        if readable(fd, Duration::ZERO) {
            listener.try_wait(|_| {})?;
        }
        // Quiet now. One more notification must wake a waiter.
        probe.notify()?;
        if !readable(fd, Duration::from_millis(100)) {
            lost += 1;
            let pending = listener.try_wait(|_| {})?;
            println!("round {round}: notify() returned Ok but the listener's fd stayed unreadable for 100 ms; try_wait then found {pending} activation(s)");
        } else {
            listener.try_wait(|_| {})?;
        }
    }
    stop.store(true, Ordering::Release);
    t.join().map_err(|_| "notifier thread panicked")??;
    println!("{lost} lost wake-up(s) in {rounds} rounds of {} µs of notifications", BURST.as_micros());
    std::process::exit(i32::from(lost > 0));
}
