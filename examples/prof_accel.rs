//! Build time (CPU), size and traversal work per ray of the other structures beside the binned
//! BVH, single-threaded: `cargo run --release --example prof_accel MESH RAYS [NAMES]`
//! (MESH and RAYS as `common/input.rs` reads them: `.tri`, `.obj` or glTF; `.rays`,
//! `camera:SIDE` or `random:N`; NAMES comma-separated, default all; `bvh` is binned16; `KD_CI`, `KD_CT`, `KD_EB`,
//! `KD_DEPTH`, `KD_PERFECT_ABOVE` (a triangle count, or `none`), `KD_LONGEST` (0 or 1): the
//! kd-tree's intersection cost, traversal cost, empty bonus, depth limit, the nodes split
//! perfectly and the longest-axis sweep in place of the defaults). Run with
//! `RAYON_NUM_THREADS=1` to build the BVH on one thread.
use dynbvh::accel::{Accel, AccelKind, KdParams, KdTree};
use dynbvh::bvh::{BuildParams, MeshBvh, TraversalStats};

#[path = "common/cpu.rs"]
mod cpu;
use cpu::cpu_s;
#[path = "common/input.rs"]
mod input;

fn main() {
    let mut args = std::env::args().skip(1);
    let mesh = input::mesh(&args.next().expect("mesh"));
    let rays = input::rays(&args.next().expect("rays"), &mesh);
    let names = args
        .next()
        .unwrap_or_else(|| "bvh,kdtree,kdtree-naive,bih,grid,octree".into());
    for name in names.split(',') {
        let c = cpu_s();
        let env = |k: &str| std::env::var(k).ok().map(|v| v.parse::<f32>().unwrap());
        let ci = [
            "KD_CI",
            "KD_CT",
            "KD_EB",
            "KD_DEPTH",
            "KD_PERFECT_ABOVE",
            "KD_LONGEST",
        ]
        .iter()
        .any(|k| std::env::var(k).is_ok())
        .then_some(());
        let s: Box<dyn Accel> = if name == "bvh" {
            Box::new(MeshBvh::build(&mesh, &BuildParams::BINNED))
        } else if let (Some(()), "kdtree") = (ci, name) {
            let d = KdParams::default();
            let params = KdParams {
                intersection_cost: env("KD_CI").unwrap_or(d.intersection_cost),
                traversal_cost: env("KD_CT").unwrap_or(d.traversal_cost),
                empty_bonus: env("KD_EB").unwrap_or(d.empty_bonus),
                max_depth: env("KD_DEPTH").map(|v| v as usize).or(d.max_depth),
                perfect_splits_above: std::env::var("KD_PERFECT_ABOVE").ok().map_or(
                    d.perfect_splits_above,
                    |v| {
                        if v == "none" {
                            usize::MAX
                        } else {
                            v.parse().unwrap()
                        }
                    },
                ),
                longest_axis_only: env("KD_LONGEST").map_or(d.longest_axis_only, |v| v != 0.0),
                ..d
            };
            Box::new(KdTree::build(&mesh, &params))
        } else {
            name.parse::<AccelKind>().unwrap().build(&mesh)
        };
        let build = cpu_s() - c;
        let mut st = TraversalStats::default();
        // The work of the rays that hit and of those that miss, apart.
        let (mut hit, mut miss, mut hits) =
            (TraversalStats::default(), TraversalStats::default(), 0);
        for r in &rays {
            let mut one = TraversalStats::default();
            if s.closest_hit_counted(r, &mut one).is_some() {
                hit += one;
                hits += 1;
            } else {
                miss += one;
            }
            st += one;
        }
        let per = |s: TraversalStats, n: usize| {
            let n = n.max(1) as f64;
            (s.nodes as f64 / n, s.prims as f64 / n)
        };
        let (hit, miss) = (per(hit, hits), per(miss, rays.len() - hits));
        let c = cpu_s();
        let hit_count = rays.iter().filter(|r| s.closest_hit(r).is_some()).count();
        let trace = cpu_s() - c;
        println!(
            "{name:<13} build {:8.1} ms cpu  nodes {:9}  MiB {:6.1}  sah {:7.2}  nodes/ray {:6.1}  tris/ray {:6.1} (hits {:.1}, {:.1}; misses {:.1}, {:.1})  {hit_count} hits  {:.2} Mrays/s cpu",
            build * 1e3,
            s.nodes(),
            s.memory_bytes() as f64 / (1 << 20) as f64,
            s.sah().unwrap_or(f32::NAN),
            st.nodes as f64 / rays.len() as f64,
            st.prims as f64 / rays.len() as f64,
            hit.0,
            hit.1,
            miss.0,
            miss.1,
            rays.len() as f64 / trace / 1e6
        );
    }
}
