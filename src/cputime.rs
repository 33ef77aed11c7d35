//! CPU time of this process's threads as the kernel counts it, and the time they waited for a
//! core while runnable: on a shared machine, wall clock alone cannot tell the engine's work from
//! other processes' load, these two can.
//!
//! Read from Linux's per-thread scheduler statistics (`/proc/self/task/*/schedstat`: time on a
//! core, time runnable on a run queue, in ns). Elsewhere both read as unknown.

use std::sync::{Mutex, PoisonError};
use std::time::Instant;

/// Threads that wait for a core by design (the background rebuild's worker, which runs only on
/// cores nothing else wants): their CPU time counts, their wait does not, since it says nothing
/// about other processes' load.
static IDLE_CLASS: Mutex<Vec<String>> = Mutex::new(Vec::new());

/// Marks the calling thread, for the rest of its life, as one whose run-queue wait is its own
/// choice (on Linux; elsewhere nothing is counted anyway).
pub fn waits_by_design() {
    thread_local! {
        static MARK: std::cell::RefCell<Option<Mark>> = const { std::cell::RefCell::new(None) };
    }
    let Some(tid) = std::fs::read_link("/proc/thread-self")
        .ok()
        .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
    else {
        return;
    };
    MARK.with(|m| {
        let mut m = m.borrow_mut();
        if m.is_none() {
            IDLE_CLASS
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .push(tid.clone());
            *m = Some(Mark(tid));
        }
    });
}

/// The threads [`waits_by_design`] has marked and that have not ended (their ids).
#[must_use]
pub fn waiting_by_design() -> Vec<String> {
    IDLE_CLASS
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .clone()
}

/// Unmarks its thread when the thread ends.
struct Mark(String);

impl Drop for Mark {
    fn drop(&mut self) {
        IDLE_CLASS
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .retain(|x| *x != self.0);
    }
}

/// Sum over this process's live threads: `(ns on a core, ns runnable but waiting for one)`,
/// the wait of threads marked by [`waits_by_design`] left out.
///
/// The kernel brings a running thread's count up to date only at a scheduler tick or when the
/// thread leaves its core, so the calling thread yields first: without that, a measurement
/// shorter than a few ticks reads whole ticks (`docs/accel.md` has the figures).
#[must_use]
pub fn thread_times_ns() -> Option<(u64, u64)> {
    std::thread::yield_now();
    let dir = std::fs::read_dir("/proc/self/task").ok()?;
    let (mut run, mut wait) = (0u64, 0u64);
    let mut any = false;
    let by_design = waiting_by_design();
    for entry in dir.flatten() {
        let waits = !by_design.iter().any(|t| entry.file_name() == t.as_str());
        let Ok(text) = std::fs::read_to_string(entry.path().join("schedstat")) else {
            continue;
        };
        let mut fields = text.split_ascii_whitespace().map(str::parse::<u64>);
        if let (Some(Ok(r)), Some(Ok(w))) = (fields.next(), fields.next()) {
            run += r;
            if waits {
                wait += w;
            }
            any = true;
        }
    }
    any.then_some((run, wait))
}

/// A stopwatch of wall clock, CPU time and run-queue wait.
#[derive(Clone, Copy, Debug)]
pub struct CpuClock {
    wall: Instant,
    threads: Option<(u64, u64)>,
}

/// What a [`CpuClock`] measured, ms (CPU and wait 0 where unknown).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Elapsed {
    /// Wall clock.
    pub wall_ms: f64,
    /// CPU time of all the process's threads.
    pub cpu_ms: f64,
    /// Time the process's threads were runnable but waited for a core.
    pub wait_ms: f64,
}

impl std::ops::AddAssign for Elapsed {
    fn add_assign(&mut self, o: Self) {
        self.wall_ms += o.wall_ms;
        self.cpu_ms += o.cpu_ms;
        self.wait_ms += o.wait_ms;
    }
}

impl Elapsed {
    /// True when the threads waited for a core more than `share` of the time they ran: other
    /// processes held the cores (for one thread, the wall clock exceeded the CPU time by more
    /// than `share`).
    #[must_use]
    pub fn busy(&self, share: f64) -> bool {
        self.wait_ms > share * self.cpu_ms
    }
}

impl CpuClock {
    /// Starts now.
    #[must_use]
    pub fn now() -> Self {
        Self {
            threads: thread_times_ns(),
            wall: Instant::now(),
        }
    }

    /// Time since [`CpuClock::now`].
    #[must_use]
    pub fn elapsed_ms(&self) -> Elapsed {
        let wall_ms = self.wall.elapsed().as_secs_f64() * 1e3;
        let (cpu_ms, wait_ms) = match (self.threads, thread_times_ns()) {
            (Some((r0, w0)), Some((r1, w1))) => (
                r1.saturating_sub(r0) as f64 * 1e-6,
                w1.saturating_sub(w0) as f64 * 1e-6,
            ),
            _ => (0.0, 0.0),
        };
        Elapsed {
            wall_ms,
            cpu_ms,
            wait_ms,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spinning_counts_cpu_time() {
        let c = CpuClock::now();
        let mut x = 0u64;
        // A short spin, and on until the CPU clock has moved (it ticks coarsely on some
        // machines, and a loaded one may not run this thread at once), at most 2 s.
        let mut e = c.elapsed_ms();
        while e.wall_ms < 30.0 || (e.cpu_ms <= 0.0 && e.wall_ms < 2000.0) {
            for _ in 0..10_000 {
                x = std::hint::black_box(x.wrapping_add(1));
            }
            e = c.elapsed_ms();
        }
        assert!(e.wall_ms >= 30.0);
        if thread_times_ns().is_some() {
            // Spinning for up to 2 s of wall clock is at least some CPU time, never more than the
            // wall clock times the cores.
            assert!(e.cpu_ms > 0.0, "{e:?}");
            assert!(
                e.cpu_ms
                    <= e.wall_ms
                        * 1.1
                        * std::thread::available_parallelism().map_or(64, |n| n.get()) as f64
                        + 5.0,
                "{e:?}"
            );
        }
        let idle = Elapsed {
            wall_ms: 10.0,
            cpu_ms: 10.0,
            wait_ms: 0.5,
        };
        assert!(!idle.busy(0.1));
        assert!(
            Elapsed {
                wait_ms: 2.0,
                ..idle
            }
            .busy(0.1)
        );
    }
}
