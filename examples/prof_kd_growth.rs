//! The kd-tree build's two figures in one process: its time against binned16's on each of two
//! meshes, and how its time per triangle grows from the smaller to the larger, builds of both
//! meshes interleaved so that both see the same machine:
//! `cargo run --release --example prof_kd_growth SMALL LARGE [RUNS]` (meshes as
//! `common/input.rs` reads them; RUNS default 5). `KD_CI` and `KD_PERFECT_ABOVE` (a triangle
//! count) replace the default intersection cost and perfect-split threshold; `KD_NAIVE=1`
//! measures the naive O(N log² N) builder instead. Run with
//! `RAYON_NUM_THREADS=1 taskset -c 1`. Prints the medians (CPU time).
//!
//! Both meshes' builds take fresh pages from the system, as a single build in a new process
//! does: glibc's malloc would otherwise raise its mmap threshold after the first free and serve
//! the smaller mesh's buffers (under 32 MiB) from memory already mapped, while the larger's
//! (over it) are always mapped afresh and zeroed by the kernel, an allocator effect that reads
//! as growth (`KD_WARM=1` keeps glibc's default, to see it).
use dynbvh::accel::{KdParams, KdTree};
use dynbvh::bvh::{BuildParams, MeshBvh};

#[path = "common/cpu.rs"]
mod cpu;
use cpu::{cpu_s, median};
#[path = "common/input.rs"]
mod input;

fn main() {
    if std::env::var_os("KD_WARM").is_none() && std::env::var_os("GLIBC_TUNABLES").is_none() {
        // A fixed threshold turns glibc's dynamic one off: every buffer of 128 KiB or more is
        // mapped when allocated and unmapped when freed. malloc reads it at start-up, so the
        // example runs itself again with it set.
        let status = std::process::Command::new(std::env::current_exe().unwrap())
            .args(std::env::args_os().skip(1))
            .env("GLIBC_TUNABLES", "glibc.malloc.mmap_threshold=131072")
            .status()
            .unwrap();
        std::process::exit(status.code().unwrap_or(1));
    }
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
        build: if env("KD_NAIVE").is_some() {
            KdParams::NAIVE.build
        } else {
            d.build
        },
        ..d
    };
    let time = |f: &dyn Fn()| {
        let c = cpu_s();
        f();
        (cpu_s() - c) * 1e3
    };
    // Each run builds the smaller mesh about as many times as it is smaller, half before and
    // half after one build of the larger, so that both see the machine over the same second:
    // a disturbance shorter than the larger build would otherwise hit single smaller builds
    // whole and the larger one diluted.
    let repeat = (large.len() / small.len().max(1)).max(1);
    let (mut kd, mut bvh) = ([Vec::new(), Vec::new()], [Vec::new(), Vec::new()]);
    let mut growth = Vec::new();
    for _ in 0..runs {
        for (i, m) in [&small, &large].into_iter().enumerate() {
            bvh[i].push(time(&|| drop(MeshBvh::build(m, &BuildParams::BINNED))));
        }
        let mut small_ms = 0.0;
        for k in 0..repeat {
            if k == repeat / 2 {
                kd[1].push(time(&|| drop(KdTree::build(&large, &params))));
            }
            let t = time(&|| drop(KdTree::build(&small, &params)));
            small_ms += t;
            kd[0].push(t);
        }
        let small_per_tri = small_ms / (repeat * small.len()) as f64;
        growth.push(kd[1].last().unwrap() / large.len() as f64 / small_per_tri);
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
