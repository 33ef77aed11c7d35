//! Interleaved timing for the query benches: several methods measured in turn, repeat after
//! repeat, so that they share the machine's load; medians of wall and CPU time per repeat.

#[path = "../../examples/common/cpu.rs"]
mod cpu;

/// The medians of one method's repeats, ms.
#[derive(Clone, Copy, Debug, Default)]
pub struct Timed {
    /// Median wall-clock time of a repeat.
    pub wall_ms: f64,
    /// Median CPU time (all the process's threads) of a repeat.
    pub cpu_ms: f64,
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Runs every method once per repeat, in a rotating order, `repeats` times.
pub fn interleaved(repeats: usize, methods: &mut [&mut dyn FnMut()]) -> Vec<Timed> {
    let n = methods.len();
    let mut wall = vec![Vec::with_capacity(repeats); n];
    let mut cpu_t = vec![Vec::with_capacity(repeats); n];
    for rep in 0..repeats {
        for k in 0..n {
            let i = (k + rep) % n;
            let c = cpu::cpu_s();
            let t = std::time::Instant::now();
            (methods[i])();
            wall[i].push(t.elapsed().as_secs_f64() * 1e3);
            cpu_t[i].push((cpu::cpu_s() - c) * 1e3);
        }
    }
    (0..n)
        .map(|i| Timed {
            wall_ms: median(&mut wall[i]),
            cpu_ms: median(&mut cpu_t[i]),
        })
        .collect()
}
