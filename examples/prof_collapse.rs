//! Compares the collapses of one binary tree into BVH8 on one thread:
//! `cargo run --release --example prof_collapse MESH.tri RAYS.rays...`
//!
//! The greedy collapse against the SAH one (`CollapseMethod::SAH`, and any further costs in
//! `COSTS="node,leaf,block,tri;..."`): collapse time (CPU, median of 5 into the tree's own
//! storage), size, SAH, nodes and triangles per ray (all rays), and closest-hit Mrays/s (CPU
//! time, median of `PASSES` (default 5) passes, the variants interleaved within each pass).
//! `LEAF=n` builds the binary tree with leaves of at most `n` triangles (default 8).
use dynbvh::bvh::{BuildParams, CollapseMethod, MeshBvh, MeshBvh8, TraversalStats, WideCost};
use dynbvh::geom::Hit;

#[path = "common/cpu.rs"]
mod cpu;
use cpu::{cpu_s, median, one_thread};

fn main() {
    one_thread();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mesh = dynbvh::io::read_tri(args[0].as_ref()).unwrap();
    let mut params = BuildParams::BINNED;
    if let Ok(l) = std::env::var("LEAF") {
        params.max_leaf_size = l.parse().unwrap();
    }
    let passes: usize = std::env::var("PASSES").map_or(5, |p| p.parse().unwrap());
    let c = cpu_s();
    let bin = MeshBvh::build(&mesh, &params);
    println!(
        "{}: {} triangles, binary build {:.1} ms cpu, {} nodes, max leaf {}",
        args[0],
        mesh.len(),
        (cpu_s() - c) * 1e3,
        bin.bvh().nodes().len(),
        params.max_leaf_size
    );
    let mut methods = vec![("greedy".to_string(), CollapseMethod::Greedy)];
    methods.push(("sah".into(), CollapseMethod::SAH));
    if let Ok(costs) = std::env::var("COSTS") {
        for c in costs.split(';').filter(|c| !c.is_empty()) {
            let v: Vec<f32> = c.split(',').map(|x| x.parse().unwrap()).collect();
            let cost = WideCost {
                node: v[0],
                leaf: v[1],
                block: v[2],
                tri: v[3],
            };
            methods.push((format!("sah({c})"), CollapseMethod::Sah(cost)));
        }
    }
    if std::env::var_os("COLLAPSE_ONLY").is_some() {
        // For profilers: nothing but SAH collapses.
        let mut w = MeshBvh8::from_mesh_bvh_with(&bin, methods[1].1);
        for _ in 0..20 {
            w.collapse_from(&bin);
        }
        return;
    }
    let mut trees = Vec::new();
    for (name, m) in &methods {
        let mut w = MeshBvh8::from_mesh_bvh_with(&bin, *m);
        let ms = median(
            (0..5)
                .map(|_| {
                    let c = cpu_s();
                    w.collapse_from(&bin);
                    (cpu_s() - c) * 1e3
                })
                .collect(),
        );
        w.validate(&mesh).unwrap();
        println!(
            "{name:>24}: collapse {ms:.1} ms cpu, {} nodes, fill {:.2}, depth {}, {} blocks, {:.1} MiB, sah {:.3} (default costs)",
            w.nodes().len(),
            w.fill(),
            w.depth(),
            w.blocks().len(),
            w.memory_bytes() as f64 / 1048576.0,
            w.sah_cost(WideCost::DEFAULT)
        );
        trees.push(w);
    }
    let same = |a: Option<Hit>, b: Option<Hit>| match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => a.t == b.t,
        _ => false,
    };
    for f in &args[1..] {
        let rays = dynbvh::io::read_rays(f.as_ref()).unwrap();
        println!("{f}: {} rays", rays.len());
        let step = (rays.len() / 4096).max(1);
        let mut mrays = vec![Vec::new(); trees.len()];
        for _ in 0..passes {
            for (w, v) in trees.iter().zip(&mut mrays) {
                let c = cpu_s();
                let n = rays.iter().filter(|r| w.closest_hit(r).is_some()).count();
                std::hint::black_box(n);
                v.push(rays.len() as f64 / (cpu_s() - c) / 1e6);
            }
        }
        for ((name, _), (w, v)) in methods.iter().zip(trees.iter().zip(mrays)) {
            let mut s = TraversalStats::default();
            for r in &rays {
                let _ = w.closest_hit_counted(r, &mut s);
            }
            let mis = (rays.iter().step_by(step))
                .filter(|r| !same(bin.closest_hit(r), w.closest_hit(r)))
                .count();
            println!(
                "{name:>24}: {:.2} nodes {:.2} tris per ray, closest {:.3} Mrays/s cpu (passes {}), mismatches {mis}/{}",
                s.nodes as f64 / rays.len() as f64,
                s.prims as f64 / rays.len() as f64,
                median(v.clone()),
                v.iter()
                    .map(|x| format!("{x:.2}"))
                    .collect::<Vec<_>>()
                    .join(" "),
                rays.len().div_ceil(step)
            );
        }
    }
}
