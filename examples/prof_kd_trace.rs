//! Camera (or any) rays through kd-trees built with different settings, against the binary
//! BVH, all built once in one process and traced in alternating passes, so that every kd pass
//! is divided by the BVH pass just before it:
//! `cargo run --release --example prof_kd_trace MESH.tri RAYS.rays [PASSES] [SETTING...]`
//! (PASSES default 8). Each SETTING is `default`, a triangle count or `none` (the nodes split
//! perfectly above that many triangles, or in none), or comma-separated `key=value` pairs
//! among `above`, `ci` (intersection cost), `ct` (traversal cost) and `eb` (empty bonus), e.g.
//! `ci=0.3,eb=0.5`; what a setting does not name is the default. Default: `default`. Run with
//! `RAYON_NUM_THREADS=1 taskset -c 1`; `KD_CI` sets the intersection cost of every kd-tree
//! that does not name its own. Prints each tree's build time (CPU), size and the median and
//! every pass of kd rate ÷ BVH rate (CPU time).
use dynbvh::accel::{Accel, KdParams, KdTree};
use dynbvh::bvh::{BuildParams, MeshBvh};

#[path = "common/cpu.rs"]
mod cpu;
use cpu::{cpu_s, median};

/// The parameters a SETTING names, on top of `base`.
fn setting(arg: &str, base: KdParams) -> KdParams {
    let above = |v: &str| {
        if v == "none" {
            usize::MAX
        } else {
            v.parse().expect("a triangle count or none")
        }
    };
    if arg == "default" {
        return base;
    }
    if !arg.contains('=') {
        return KdParams {
            perfect_splits_above: above(arg),
            ..base
        };
    }
    let mut p = base;
    for pair in arg.split(',') {
        let (k, v) = pair.split_once('=').expect("key=value");
        let f = || v.parse::<f32>().expect("a number");
        match k {
            "above" => p.perfect_splits_above = above(v),
            "ci" => p.intersection_cost = f(),
            "ct" => p.traversal_cost = f(),
            "eb" => p.empty_bonus = f(),
            _ => panic!("unknown key {k} (above, ci, ct, eb)"),
        }
    }
    p
}

fn main() {
    let mut args = std::env::args().skip(1);
    let mesh = dynbvh::io::read_tri(args.next().expect("mesh").as_ref()).unwrap();
    let rays = dynbvh::io::read_rays(args.next().expect("rays").as_ref()).unwrap();
    let passes: usize = args.next().map_or(8, |v| v.parse().unwrap());
    let mut names: Vec<String> = args.collect();
    if names.is_empty() {
        names.push("default".into());
    }
    let d = KdParams::default();
    let base = KdParams {
        intersection_cost: std::env::var("KD_CI")
            .ok()
            .map_or(d.intersection_cost, |v| v.parse().unwrap()),
        ..d
    };
    let bvh = MeshBvh::build(&mesh, &BuildParams::BINNED);
    let kds: Vec<KdTree> = names
        .iter()
        .map(|name| {
            let c = cpu_s();
            let kd = KdTree::build(&mesh, &setting(name, base));
            println!(
                "{name}: build {:.1} ms cpu, {} nodes, sah {:.2}",
                (cpu_s() - c) * 1e3,
                kd.nodes(),
                kd.sah().unwrap_or(f32::NAN)
            );
            kd
        })
        .collect();
    let mut ratios = vec![Vec::new(); kds.len()];
    for _ in 0..passes {
        let c = cpu_s();
        let bvh_hits = rays.iter().filter(|r| bvh.closest_hit(r).is_some()).count();
        let bvh_s = cpu_s() - c;
        for (kd, r) in kds.iter().zip(&mut ratios) {
            let c = cpu_s();
            let kd_hits = rays.iter().filter(|r| kd.closest_hit(r).is_some()).count();
            r.push(bvh_s / (cpu_s() - c));
            assert_eq!(bvh_hits, kd_hits, "the kd-tree and the BVH disagree");
        }
    }
    for (name, r) in names.iter().zip(&ratios) {
        println!(
            "{name}: kd rate / bvh rate median {:.3}  {r:.3?}",
            median(r.clone())
        );
    }
}
