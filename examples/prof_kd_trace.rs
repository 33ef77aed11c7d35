//! Camera (or any) rays through kd-trees built with different perfect-split thresholds,
//! against the binary BVH, all built once in one process and traced in alternating passes,
//! so that every kd pass is divided by the BVH pass just before it:
//! `cargo run --release --example prof_kd_trace MESH.tri RAYS.rays [PASSES] [ABOVE...]`
//! (PASSES default 8; each ABOVE a triangle count or `none`, default `none`). Run with
//! `RAYON_NUM_THREADS=1 taskset -c 1`; `KD_CI` sets the intersection cost of every kd-tree.
//! Prints each tree's build time (CPU), size and the median and every pass of kd rate ÷ BVH
//! rate (CPU time).
use dynbvh::accel::{Accel, KdParams, KdTree};
use dynbvh::bvh::{BuildParams, MeshBvh};

#[path = "common/cpu.rs"]
mod cpu;
use cpu::{cpu_s, median};

fn main() {
    let mut args = std::env::args().skip(1);
    let mesh = dynbvh::io::read_tri(args.next().expect("mesh").as_ref()).unwrap();
    let rays = dynbvh::io::read_rays(args.next().expect("rays").as_ref()).unwrap();
    let passes: usize = args.next().map_or(8, |v| v.parse().unwrap());
    let mut aboves: Vec<usize> = args
        .map(|v| {
            if v == "none" {
                usize::MAX
            } else {
                v.parse().unwrap()
            }
        })
        .collect();
    if aboves.is_empty() {
        aboves.push(usize::MAX);
    }
    let name = |a: usize| {
        if a == usize::MAX {
            "none".to_string()
        } else {
            a.to_string()
        }
    };
    let ci: Option<f32> = std::env::var("KD_CI").ok().map(|v| v.parse().unwrap());
    let bvh = MeshBvh::build(&mesh, &BuildParams::BINNED);
    let kds: Vec<KdTree> = aboves
        .iter()
        .map(|&a| {
            let c = cpu_s();
            let d = KdParams::default();
            let params = KdParams {
                perfect_splits_above: a,
                intersection_cost: ci.unwrap_or(d.intersection_cost),
                ..d
            };
            let kd = KdTree::build(&mesh, &params);
            println!(
                "perfect above {}: build {:.1} ms cpu, {} nodes, sah {:.2}",
                name(a),
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
    for (a, r) in aboves.iter().zip(&ratios) {
        println!(
            "perfect above {}: kd rate / bvh rate median {:.3}  {r:.3?}",
            name(*a),
            median(r.clone())
        );
    }
}
