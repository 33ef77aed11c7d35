//! Times refit from a mesh to its deformed version: `cargo run --release --example prof_refit A.tri B.tri`,
//! or `prof_refit bumpy:N` for an indexed mesh (shared vertices): a bumpy sphere of about `N`
//! triangles and its sine deformation by 10% of its box.
use dynbvh::bvh::{BuildParams, MeshBvh};
use dynbvh::geom::{TriMesh, shapes};
use std::time::Instant;

#[path = "common/cpu.rs"]
mod cpu;
use cpu::cpu_s;

fn main() {
    let mut args = std::env::args().skip(1);
    let first = args.next().expect("mesh");
    let (a, b) = if let Some(n) = first.strip_prefix("bumpy:") {
        let a = shapes::bumpy_sphere(n.parse().expect("triangle count"));
        let mut b = a.clone();
        shapes::sine_deform(&a.positions, &mut b.positions, 0.1, 0.0);
        (a, b)
    } else {
        let read = |p: String| -> TriMesh { dynbvh::io::read_tri(p.as_ref()).unwrap() };
        (read(first), read(args.next().expect("deformed mesh")))
    };
    let mut bvh = MeshBvh::build(&a, &BuildParams::BINNED);
    // CPU time is read from the scheduler's counters, which may advance only at ticks: the
    // mean over all refits is the precise figure, the median of single refits a rough one.
    let n = 21;
    let mut times = Vec::new();
    let t0 = thread_cpu_s();
    let c0 = cpu_s();
    for i in 0..n {
        let m = if i % 2 == 0 { &b } else { &a };
        let (t, c) = (Instant::now(), cpu_s());
        bvh.refit(m);
        times.push((t.elapsed().as_secs_f64() * 1e3, (cpu_s() - c) * 1e3));
    }
    let mean_cpu = (cpu_s() - c0) * 1e3 / f64::from(n);
    // Each thread's share (on several threads, the busiest one bounds the wall time on an
    // otherwise idle machine).
    let mut shares: Vec<f64> = thread_cpu_s()
        .into_iter()
        .map(|(tid, s)| {
            let before = t0.iter().find(|t| t.0 == tid).map_or(0.0, |t| t.1);
            (s - before) * 1e3 / f64::from(n)
        })
        .filter(|&ms| ms > 0.01)
        .collect();
    shares.sort_by(|x, y| y.total_cmp(x));
    times.sort_by(|x, y| x.0.total_cmp(&y.0));
    let (wall, cpu) = times[times.len() / 2];
    println!(
        "refit median {wall:.2} ms wall ({cpu:.2} ms cpu), mean {mean_cpu:.2} ms cpu \
         (per thread {shares:.2?}), sah {:.2}",
        bvh.bvh().sah_cost()
    );
}

/// CPU seconds of each of this process's threads, by thread id.
fn thread_cpu_s() -> Vec<(String, f64)> {
    let Ok(dir) = std::fs::read_dir("/proc/self/task") else {
        return Vec::new();
    };
    dir.filter_map(|e| {
        let e = e.ok()?;
        let s = std::fs::read_to_string(e.path().join("schedstat")).ok()?;
        let ns = s.split_whitespace().next()?.parse::<u64>().ok()?;
        Some((
            e.file_name().to_string_lossy().into_owned(),
            ns as f64 * 1e-9,
        ))
    })
    .collect()
}
