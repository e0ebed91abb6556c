//! Stage-wise progress display for builds that take longer than a second: a background thread
//! prints the current stage and elapsed time to stderr; silent for fast builds and cache hits.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

static CURRENT: Mutex<Option<(String, Instant)>> = Mutex::new(None);

/// Marks the start of a pipeline stage (cheap; used by the build).
pub fn stage(name: &str) {
    tracing::debug!(stage = name, "pipeline stage");
    if let Ok(mut c) = CURRENT.lock() {
        if let Some((s, _)) = c.as_mut() {
            *s = name.to_string();
        }
    }
}

/// Shows progress on stderr while alive (only after the first second).
pub struct Progress {
    stop: Arc<AtomicBool>,
    handle: Option<std::thread::JoinHandle<()>>,
}

impl Progress {
    pub fn start(title: &str) -> Progress {
        if let Ok(mut c) = CURRENT.lock() {
            *c = Some((title.to_string(), Instant::now()));
        }
        let stop = Arc::new(AtomicBool::new(false));
        let s2 = stop.clone();
        let t0 = Instant::now();
        let handle = std::thread::spawn(move || {
            let mut shown = false;
            while !s2.load(Ordering::Relaxed) {
                std::thread::park_timeout(Duration::from_millis(200));
                let el = t0.elapsed();
                if el < Duration::from_secs(1) || s2.load(Ordering::Relaxed) {
                    continue;
                }
                let name = CURRENT.lock().ok().and_then(|c| c.as_ref().map(|(s, _)| s.clone())).unwrap_or_default();
                eprint!("\r\x1b[2Kstrip model: {name} ... {:.1} s", el.as_secs_f64());
                shown = true;
            }
            if shown {
                eprintln!("\r\x1b[2Kstrip model: done in {:.2} s", t0.elapsed().as_secs_f64());
            }
        });
        Progress { stop, handle: Some(handle) }
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            h.thread().unpark();
            let _ = h.join();
        }
        if let Ok(mut c) = CURRENT.lock() {
            *c = None;
        }
    }
}
