//! BVH8 closest hit alone, for A/B runs of two builds of the traversal one after the other:
//! `cargo run --release --example prof_bvh8 -- DIR INPUT...` with `DIR/INPUT.tri`,
//! `DIR/INPUT_primary.rays`, `DIR/INPUT_random.rays`. Prints the leaf sizes, the work per ray,
//! the agreement with the binary tree on a sample, and Mrays/s in CPU time (median of `PASSES`,
//! default 5, over the first `RAYS` rays of each set, default 2^18). `VARIANTS=a,b,..` times
//! `MeshBvh8::bench_closest_hit` with those switches instead, interleaved pass by pass, and
//! prints each one's median and its median ratio to the first. `BATCH=1` times
//! `MeshBvh8::closest_hit_batch` (incoherent sets reordered first) against the loop instead.
//! `PARAMS=ct:ci:leaf,...` builds one tree per set of the binary build's traversal cost,
//! intersection cost and largest leaf (`1:1:8` is `BuildParams::BINNED`) and times their
//! closest hits interleaved pass by pass, each against the first.
use dynbvh::bvh::{BuildParams, Child, MeshBvh, MeshBvh8, TraversalStats};
use dynbvh::geom::Ray;

#[path = "common/cpu.rs"]
mod cpu;
use cpu::{cpu_s, median, one_thread};

fn env(name: &str, default: usize) -> usize {
    std::env::var(name)
        .ok()
        .map_or(default, |s| s.parse().expect(name))
}

fn main() {
    one_thread();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir = &args[0];
    let passes = env("PASSES", 5);
    let count = env("RAYS", 1 << 18);
    for name in &args[1..] {
        let mesh = dynbvh::io::read_tri(format!("{dir}/{name}.tri").as_ref()).unwrap();
        if let Ok(list) = std::env::var("PARAMS") {
            params(dir, name, &mesh, &list, passes, count);
            continue;
        }
        let bin = MeshBvh::build(&mesh, &BuildParams::BINNED);
        let w8 = MeshBvh8::from_mesh_bvh(&bin);
        // Leaves by number of blocks of four, and triangles per leaf.
        let mut by_blocks = [0usize; 5];
        let (mut leaves, mut tris) = (0usize, 0usize);
        for n in w8.nodes() {
            for i in 0..8 {
                if let Child::Leaf { first, count } = n.child(i) {
                    // `count` is in blocks.
                    by_blocks[(count as usize).min(4)] += 1;
                    leaves += 1;
                    let b = &w8.blocks()[first as usize..(first + count) as usize];
                    tris += b
                        .iter()
                        .flat_map(|b| b.prims)
                        .filter(|&p| p != u32::MAX)
                        .count();
                }
            }
        }
        println!(
            "{name}: {} nodes, {} blocks, {leaves} leaves of {:.2} triangles; leaves of 1, 2, 3, 4+ blocks {:?}",
            w8.nodes().len(),
            w8.blocks().len(),
            tris as f64 / leaves as f64,
            &by_blocks[1..]
        );
        for set in ["primary", "random"] {
            let rays = ray_set(dir, name, set, count);
            let step = (rays.len() / 4096).max(1);
            let sample: Vec<Ray> = rays.iter().step_by(step).copied().collect();
            let mismatches = sample
                .iter()
                .filter(|r| {
                    bin.closest_hit(r).map(|h| h.t) != w8.closest_hit(r).map(|h| h.t)
                        || bin.any_hit(r) != w8.any_hit(r)
                })
                .count();
            let mut st = TraversalStats::default();
            for r in &sample {
                let _ = w8.closest_hit_counted(r, &mut st);
            }
            if let Ok(list) = std::env::var("VARIANTS") {
                let variants: Vec<u32> = list.split(',').map(|v| v.parse().unwrap()).collect();
                for &x in &variants {
                    let bad = sample
                        .iter()
                        .filter(|r| {
                            w8.bench_closest_hit(r, x).map(|h| (h.t, h.u, h.v))
                                != w8.closest_hit(r).map(|h| (h.t, h.u, h.v))
                        })
                        .count();
                    assert_eq!(bad, 0, "variant {x} differs");
                }
                // speeds[variant][pass]
                let mut speeds = vec![Vec::new(); variants.len()];
                for _ in 0..passes {
                    for (i, &x) in variants.iter().enumerate() {
                        let c = cpu_s();
                        let n = rays
                            .iter()
                            .filter(|r| w8.bench_closest_hit(r, x).is_some())
                            .count();
                        std::hint::black_box(n);
                        speeds[i].push(rays.len() as f64 / (cpu_s() - c) / 1e6);
                    }
                }
                let line: Vec<String> = variants
                    .iter()
                    .enumerate()
                    .map(|(i, x)| {
                        let ratio = median_ratio(&speeds[i], &speeds[0]);
                        format!("v{x} {:.2} ({ratio:.3})", median(speeds[i].clone()))
                    })
                    .collect();
                println!("  {set}: {}", line.join(", "));
                continue;
            }
            if std::env::var_os("BATCH").is_some() {
                // The batch call (reordered when incoherent) against the loop, pass by pass.
                let mut order = dynbvh::bvh::ray_order::RayBatch::default();
                let mut hits = vec![None; rays.len()];
                let (mut lp, mut bt) = (Vec::new(), Vec::new());
                for _ in 0..passes {
                    let c = cpu_s();
                    let n = rays.iter().filter(|r| w8.closest_hit(r).is_some()).count();
                    std::hint::black_box(n);
                    lp.push(rays.len() as f64 / (cpu_s() - c) / 1e6);
                    let c = cpu_s();
                    w8.closest_hit_batch(&rays, &mut hits, &mut order);
                    std::hint::black_box(&hits);
                    bt.push(rays.len() as f64 / (cpu_s() - c) / 1e6);
                }
                let ratio = median_ratio(&bt, &lp);
                println!(
                    "  {set}: loop {:.2} Mrays/s, batch {:.2} Mrays/s, batch / loop {ratio:.3}",
                    median(lp),
                    median(bt)
                );
                continue;
            }
            let mut v: Vec<f64> = (0..passes)
                .map(|_| {
                    let c = cpu_s();
                    let n = rays.iter().filter(|r| w8.closest_hit(r).is_some()).count();
                    std::hint::black_box(n);
                    rays.len() as f64 / (cpu_s() - c) / 1e6
                })
                .collect();
            v.sort_by(f64::total_cmp);
            println!(
                "  {set}: {:.2} Mrays/s (passes {:?}); {:.2} nodes {:.2} tris per ray; mismatches {mismatches}/{}",
                v[v.len() / 2],
                v.iter()
                    .map(|x| (x * 100.0).round() / 100.0)
                    .collect::<Vec<_>>(),
                st.nodes as f64 / sample.len() as f64,
                st.prims as f64 / sample.len() as f64,
                sample.len()
            );
        }
    }
}

/// The median over passes of `a`'s rate over `b`'s in the same pass.
fn median_ratio(a: &[f64], b: &[f64]) -> f64 {
    median(a.iter().zip(b).map(|(a, b)| a / b).collect())
}

/// The first `count` rays of `DIR/NAME_SET.rays`; a square camera image as the peers bench
/// takes it: every 2nd row and column, in the order of packet tiles.
fn ray_set(dir: &str, name: &str, set: &str, count: usize) -> Vec<Ray> {
    let mut rays = dynbvh::io::read_rays(format!("{dir}/{name}_{set}.rays").as_ref()).unwrap();
    let side = (rays.len() as f64).sqrt().round() as usize;
    if set == "primary" && side * side == rays.len() {
        let half: Vec<Ray> = (0..side * side)
            .filter(|i| (i / side).is_multiple_of(2) && (i % side).is_multiple_of(2))
            .map(|i| rays[i])
            .collect();
        rays.clear();
        dynbvh::bvh::image_tiles(side / 2, side / 2, |idx| {
            rays.extend(idx.iter().map(|&i| half[i]));
        });
    }
    rays.truncate(count);
    rays
}

/// The `PARAMS` mode: trees from several build settings, timed interleaved.
fn params(
    dir: &str,
    name: &str,
    mesh: &dynbvh::geom::TriMesh,
    list: &str,
    passes: usize,
    count: usize,
) {
    let sets: Vec<BuildParams> = list
        .split(',')
        .map(|s| {
            let f: Vec<&str> = s.split(':').collect();
            BuildParams {
                traversal_cost: f[0].parse().unwrap(),
                intersection_cost: f[1].parse().unwrap(),
                max_leaf_size: f[2].parse().unwrap(),
                ..BuildParams::BINNED
            }
        })
        .collect();
    let trees: Vec<(MeshBvh, MeshBvh8)> = sets
        .iter()
        .map(|p| {
            let c = cpu_s();
            let bin = MeshBvh::build(mesh, p);
            let b = cpu_s();
            let w8 = MeshBvh8::from_mesh_bvh(&bin);
            let e = cpu_s();
            println!(
                "{name} ct {} ci {} leaf {}: build {:.1} + collapse {:.1} ms cpu, {} nodes, {} blocks, SAH {:.2}",
                p.traversal_cost,
                p.intersection_cost,
                p.max_leaf_size,
                (b - c) * 1e3,
                (e - b) * 1e3,
                w8.nodes().len(),
                w8.blocks().len(),
                bin.bvh().sah_cost()
            );
            (bin, w8)
        })
        .collect();
    for set in ["primary", "random"] {
        let rays = ray_set(dir, name, set, count);
        let step = (rays.len() / 4096).max(1);
        for (bin, w8) in &trees {
            let bad = rays
                .iter()
                .step_by(step)
                .filter(|r| bin.closest_hit(r).map(|h| h.t) != w8.closest_hit(r).map(|h| h.t))
                .count();
            assert_eq!(bad, 0, "a tree disagrees with its binary tree");
        }
        let work: Vec<(f64, f64)> = trees
            .iter()
            .map(|(_, w8)| {
                let mut st = TraversalStats::default();
                let mut n = 0;
                for r in rays.iter().step_by(step) {
                    let _ = w8.closest_hit_counted(r, &mut st);
                    n += 1;
                }
                (st.nodes as f64 / n as f64, st.prims as f64 / n as f64)
            })
            .collect();
        let mut speeds = vec![Vec::new(); trees.len()];
        for _ in 0..passes {
            for (i, (_, w8)) in trees.iter().enumerate() {
                let c = cpu_s();
                let n = rays.iter().filter(|r| w8.closest_hit(r).is_some()).count();
                std::hint::black_box(n);
                speeds[i].push(rays.len() as f64 / (cpu_s() - c) / 1e6);
            }
        }
        let line: Vec<String> = (0..trees.len())
            .map(|i| {
                let ratio = median_ratio(&speeds[i], &speeds[0]);
                format!(
                    "{}:{}:{} {:.2} ({ratio:.3}; {:.2} n {:.2} t)",
                    sets[i].traversal_cost,
                    sets[i].intersection_cost,
                    sets[i].max_leaf_size,
                    median(speeds[i].clone()),
                    work[i].0,
                    work[i].1
                )
            })
            .collect();
        println!("  {set}: {}", line.join(", "));
    }
}
