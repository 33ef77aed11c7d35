//! Posing throughput with wall and CPU time, 1 and 2 threads alternating: the figures of
//! `benches/pose.rs` in a form that survives a shared machine.
//!
//! ```sh
//! cargo run --release --example prof_pose -- [ROUNDS] [POSES]
//! ```
//!
//! Loads four copies of the generated 1,000,042-vertex skinned tube (4 weights per vertex;
//! about 190 MB of rest positions, joints, weights and output, far beyond the L3) and one
//! 23,817-vertex tube (in cache), then for `ROUNDS` rounds (default 5) poses each regime
//! `POSES` times (default 40) in a 1-thread pool, then in a 2-thread pool. Per regime and
//! thread count it prints the median over rounds of: wall time per pose, M vertices/s by wall
//! time, and M vertices per CPU-second (all threads of the process). With both cores to
//! itself, a 2-thread run whose CPU time per pose matches the 1-thread one scales by 2; when
//! the second thread's cycles go into waiting on memory, its CPU throughput drops by as much.

use dynbvh::anim::generate::{TubeWeights, skinned_tube};
use dynbvh::anim::{LoadOptions, Scene};
use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

#[path = "common/cpu.rs"]
mod cpu;
use cpu::cpu_s;

fn tubes(triangles: usize, copies: usize) -> Vec<Scene> {
    let g = skinned_tube(triangles, 16, TubeWeights::Cubic);
    (0..copies)
        .map(|_| {
            Scene::from_slice(Path::new("tube.glb"), &g.glb, &LoadOptions::default())
                .expect("the generated tube loads")
                .0
        })
        .collect()
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("ROUNDS and POSES are numbers"))
        .collect();
    let rounds = args.first().copied().unwrap_or(5);
    let poses = args.get(1).copied().unwrap_or(40);
    let big = tubes(1_882_400, 4);
    let small = tubes(44_800, 1);
    let regimes: [(&str, &[Scene]); 3] = [
        ("tube_1m_x4 (DRAM)", &big),
        ("tube_1m (one copy)", &big[..1]),
        ("tube_24k (cache)", &small),
    ];
    let pools: Vec<_> = [1, 2]
        .map(|n| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .expect("a rayon pool")
        })
        .into();
    // [regime][threads] -> (wall s per pose, vertices per CPU-second) per round.
    let mut wall = vec![[Vec::new(), Vec::new()]; regimes.len()];
    let mut cpu = vec![[Vec::new(), Vec::new()]; regimes.len()];
    for _ in 0..rounds {
        for (r, (_, scenes)) in regimes.iter().enumerate() {
            let verts = scenes[0].vertex_count() as f64;
            // Small meshes take more poses for a measurable time.
            let n = poses * (1_000_000 / scenes[0].vertex_count()).max(1);
            for (k, pool) in pools.iter().enumerate() {
                pool.install(|| {
                    let mut posers: Vec<_> =
                        scenes.iter().map(|s| s.poser(Some(0)).unwrap()).collect();
                    for p in &mut posers {
                        p.pose(0.0);
                    }
                    let (w0, c0) = (Instant::now(), cpu_s());
                    for i in 0..n {
                        let p = &mut posers[i % scenes.len()];
                        p.pose(i as f32 / 60.0);
                        black_box(p.positions(0).last().copied());
                    }
                    let (w, c) = (w0.elapsed().as_secs_f64(), cpu_s() - c0);
                    wall[r][k].push(w / n as f64);
                    cpu[r][k].push(verts * n as f64 / c);
                });
            }
        }
    }
    println!("| regime | threads | wall per pose | M vertices/s (wall) | M vertices per CPU-s |");
    println!("|---|---|---|---|---|");
    for (r, (name, scenes)) in regimes.iter().enumerate() {
        let verts = scenes[0].vertex_count() as f64;
        for k in 0..2 {
            let w = median(&mut wall[r][k]);
            let c = median(&mut cpu[r][k]);
            println!(
                "| {name} | {} | {:.3} ms | {:.0} | {:.0} |",
                k + 1,
                w * 1e3,
                verts / w / 1e6,
                c / 1e6
            );
        }
    }
}
