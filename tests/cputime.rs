//! The CPU clock reads a running thread's time to the microsecond, not in scheduler ticks.
//! Its own test binary, so that no other test's threads add their time to the process's.

use dynbvh::cputime::{CpuClock, thread_times_ns};

#[test]
fn short_spans_read_no_more_cpu_than_wall_clock() {
    if thread_times_ns().is_none() {
        eprintln!("no per-thread CPU times on this system: nothing to check");
        return;
    }
    let mut x = 0u64;
    for _ in 0..50 {
        let c = CpuClock::now();
        let mut e = c.elapsed_ms();
        while e.wall_ms < 1.0 {
            for _ in 0..1000 {
                x = std::hint::black_box(x.wrapping_add(1));
            }
            e = c.elapsed_ms();
        }
        // One thread cannot run longer than the wall clock; a count that was brought up to
        // date only at a scheduler tick inside the span would read up to a tick more.
        assert!(e.cpu_ms <= e.wall_ms + 0.25, "{e:?}");
    }
}
