//! The kd-tree build's two figures in one process: its time against binned16's on each of two
//! meshes, and how its time per triangle grows from the smaller to the larger, builds of both
//! meshes alternating so that both see the same machine:
//! `cargo run --release --example prof_kd_growth SMALL LARGE [RUNS]` (meshes as
//! `common/input.rs` reads them; RUNS default 5). `KD_CI` and `KD_PERFECT_ABOVE` (a triangle
//! count) replace the default intersection cost and perfect-split threshold. Run with
//! `RAYON_NUM_THREADS=1 taskset -c 1`. Prints the medians (CPU time).
use dynbvh::accel::{KdParams, KdTree};
use dynbvh::bvh::{BuildParams, MeshBvh};

#[path = "common/cpu.rs"]
mod cpu;
use cpu::{cpu_s, median};
#[path = "common/input.rs"]
mod input;

fn main() {
    let mut args = std::env::args().skip(1);
    let small = input::mesh(&args.next().expect("smaller mesh"));
    let large = input::mesh(&args.next().expect("larger mesh"));
    let runs: usize = args.next().map_or(5, |r| r.parse().unwrap());
    let env = |k: &str| std::env::var(k).ok();
    let d = KdParams::default();
    let params = KdParams {
        intersection_cost: env("KD_CI").map_or(d.intersection_cost, |v| v.parse().unwrap()),
        perfect_splits_above: env("KD_PERFECT_ABOVE")
            .map_or(d.perfect_splits_above, |v| v.parse().unwrap()),
        ..d
    };
    let time = |f: &dyn Fn()| {
        let c = cpu_s();
        f();
        (cpu_s() - c) * 1e3
    };
    let (mut kd, mut bvh) = ([Vec::new(), Vec::new()], [Vec::new(), Vec::new()]);
    let mut growth = Vec::new();
    for _ in 0..runs {
        for (i, m) in [&small, &large].into_iter().enumerate() {
            bvh[i].push(time(&|| drop(MeshBvh::build(m, &BuildParams::BINNED))));
            kd[i].push(time(&|| drop(KdTree::build(m, &params))));
        }
        let per_tri = |i: usize, m: &dynbvh::geom::TriMesh| kd[i].last().unwrap() / m.len() as f64;
        growth.push(per_tri(1, &large) / per_tri(0, &small));
    }
    for (i, (name, m)) in [("smaller", &small), ("larger", &large)].iter().enumerate() {
        let (k, b) = (median(kd[i].clone()), median(bvh[i].clone()));
        println!(
            "{name}: {} triangles, kd {k:.1} ms, binned16 {b:.1} ms, {:.3}x",
            m.len(),
            k / b
        );
    }
    let of_medians =
        (median(kd[1].clone()) / large.len() as f64) / (median(kd[0].clone()) / small.len() as f64);
    println!(
        "kd time per triangle, larger / smaller: of the medians {of_medians:.3}, \
         median of the runs' {:.3}  {growth:.3?}",
        median(growth.clone())
    );
}
