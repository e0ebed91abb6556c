//! `iox2-loan-alloc [SAMPLES]`: a minimal program, for an upstream report, showing that every
//! sample an iceoryx2 0.10 publisher sends allocates on the heap, whichever send API is used
//! (`loan_uninit` + `write_payload` + `send`, or `send_copy`). It uses only iceoryx2's public
//! API and its default configuration, none of the rig's code.
//!
//! Why (iceoryx2 0.10): `SampleMutUninit::new` (sample_mut_uninit.rs:327) creates a
//! `ChunkMutSharedState` for the loaned chunk (port/details/chunk_mut_shared_state.rs:102), whose
//! state lives behind the service's `ArcThreadSafetyPolicy`; for `ipc::Service` that is
//! `SingleThreaded` (iceoryx2-cal arc_sync_policy/single_threaded.rs), an `Rc::new`: one heap
//! block per loan, freed when the sample is sent. A 1 kHz control loop that must not allocate per
//! tick cannot send with iceoryx2 0.10 without it; a pool of these states per publisher (their
//! number is bounded by `max_loaned_samples`) would remove it.
//!
//! A counting global allocator counts the main thread's allocations over SAMPLES sends of each
//! API after a warm-up; the program prints them per sample. Exit status: 0 when sending
//! allocated nothing, 1 when it allocated (the defect is present).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use iceoryx2::prelude::*;

struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

fn allocations() -> u64 {
    ALLOCATIONS.with(Cell::get)
}

// SAFETY: every method forwards to System, which upholds the GlobalAlloc contract.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.with(|n| n.set(n.get() + 1));
        // SAFETY: forwards the caller's GlobalAlloc contract to the system allocator.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.with(|n| n.set(n.get() + 1));
        // SAFETY: forwards the caller's GlobalAlloc contract to the system allocator.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.with(|n| n.set(n.get() + 1));
        // SAFETY: forwards the caller's GlobalAlloc contract to the system allocator.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwards the caller's GlobalAlloc contract to the system allocator.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The payload: six joint torques, as a controller sends them.
#[derive(Debug, Default, Clone, Copy, ZeroCopySend)]
#[type_name("iox2_loan_alloc::Torque")]
#[repr(C)]
struct Torque {
    tau: [f64; 6],
}

const WARM_UP: u64 = 100;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let samples: u64 = std::env::args().nth(1).map_or(Ok(1000), |s| s.parse())?;
    let service = format!("iox2-loan-alloc-{}", std::process::id());
    let node = NodeBuilder::new().create::<ipc::Service>()?;
    let topic = node.service_builder(&service.as_str().try_into()?).publish_subscribe::<Torque>().open_or_create()?;
    let publisher = topic.publisher_builder().create()?;
    let subscriber = topic.subscriber_builder().create()?;

    let mut per_api = Vec::new();
    for api in ["loan_uninit + send", "send_copy"] {
        let mut counted = 0;
        for i in 0..WARM_UP + samples {
            let before = allocations();
            let value = Torque { tau: [i as f64; 6] };
            if api == "send_copy" {
                publisher.send_copy(value)?;
            } else {
                publisher.loan_uninit()?.write_payload(value).send()?;
            }
            if i >= WARM_UP {
                counted += allocations() - before;
            }
            // Receiving is not counted: the subscriber only keeps the queue from filling.
            while subscriber.receive()?.is_some() {}
        }
        per_api.push((api, counted));
    }
    let mut any = false;
    for (api, n) in per_api {
        println!("{api}: {n} allocation(s) in {samples} samples ({:.3} per sample)", n as f64 / samples as f64);
        any |= n > 0;
    }
    std::process::exit(i32::from(any));
}
