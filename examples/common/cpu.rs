//! Shared by the profiling examples.

/// CPU time of all this process's threads in seconds (robust to the machine being shared).
pub fn cpu_s() -> f64 {
    dynbvh::cputime::thread_times_ns().map_or(0.0, |(run, _)| run as f64 * 1e-9)
}

/// The median of `v` (the upper one of an even count).
#[allow(dead_code)]
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Makes rayon's global pool one thread, so that what a profile measures runs on one core.
#[allow(dead_code)]
pub fn one_thread() {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build_global()
        .unwrap();
}
