//! The CPU time of the calling thread, for the analysis's share of the mask work
//! (`Timings::analysis_cpu_s`).

use std::time::Instant;

/// Measures the CPU time of the calling thread (so a busy machine preempting the worker
/// does not count), or wall time where the platform has no per-thread clock.
pub(super) struct ThreadClock {
    cpu: Option<f64>,
    wall: Instant,
}

impl ThreadClock {
    /// Starts measuring on the calling thread.
    pub(super) fn start() -> ThreadClock {
        ThreadClock {
            cpu: thread_cpu_s(),
            wall: Instant::now(),
        }
    }

    /// Seconds since [`start`](Self::start), on the same thread.
    pub(super) fn elapsed_s(&self) -> f64 {
        match (self.cpu, thread_cpu_s()) {
            (Some(a), Some(b)) => (b - a).max(0.0),
            _ => self.wall.elapsed().as_secs_f64(),
        }
    }
}

/// CPU time consumed by the calling thread, s.
#[cfg(unix)]
fn thread_cpu_s() -> Option<f64> {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes one timespec through a valid, exclusive pointer.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    (rc == 0).then_some(ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9)
}

/// CPU time consumed by the calling thread: not available here.
#[cfg(not(unix))]
fn thread_cpu_s() -> Option<f64> {
    None
}

#[cfg(test)]
mod tests {
    use super::ThreadClock;

    #[test]
    fn thread_clock_counts_work_not_sleep() {
        let c = ThreadClock::start();
        std::thread::sleep(std::time::Duration::from_millis(60));
        let slept = c.elapsed_s();
        let c = ThreadClock::start();
        let mut x = 1u64;
        let t = std::time::Instant::now();
        while t.elapsed().as_millis() < 60 {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1);
        }
        std::hint::black_box(x);
        let busy = c.elapsed_s();
        assert!(busy > 0.0 && busy >= slept, "busy {busy} slept {slept}");
        if cfg!(unix) {
            // A sleeping thread uses (almost) no CPU.
            assert!(slept < 0.03, "{slept}");
        }
    }
}
