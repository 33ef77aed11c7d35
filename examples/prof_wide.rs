//! Times the wide trees against the binary one on one thread:
//! `cargo run --release --example prof_wide MESH.tri [DEFORMED.tri] RAYS.rays...`
//! (closest and any hit, CPU time, agreement with the binary tree; refit to the deformed mesh).
use dynbvh::bvh::{BuildParams, MeshBvh, MeshBvh4, MeshBvh8, TraversalStats};
use dynbvh::geom::{Hit, Ray, TriMesh};
use std::time::Instant;

#[path = "common/cpu.rs"]
mod cpu;
use cpu::{cpu_s, median, one_thread};

/// Median Mrays/s (CPU time) of three passes.
fn mrays(rays: &[Ray], f: impl Fn(&Ray) -> bool) -> f64 {
    let mut v: Vec<f64> = (0..3)
        .map(|_| {
            let c = cpu_s();
            let n = rays.iter().filter(|r| f(r)).count();
            std::hint::black_box(n);
            rays.len() as f64 / (cpu_s() - c) / 1e6
        })
        .collect();
    v.sort_by(f64::total_cmp);
    v[1]
}

fn refit_ms(a: &TriMesh, b: &TriMesh, mut f: impl FnMut(&TriMesh)) -> f64 {
    let v: Vec<f64> = (0..9)
        .map(|i| {
            let m = if i % 2 == 0 { b } else { a };
            let c = cpu_s();
            f(m);
            (cpu_s() - c) * 1e3
        })
        .collect();
    median(v)
}

fn main() {
    one_thread();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mesh = dynbvh::io::read_tri(args[0].as_ref()).unwrap();
    let (def, ray_files) = if args.len() > 1 && args[1].ends_with(".tri") {
        (
            Some(dynbvh::io::read_tri(args[1].as_ref()).unwrap()),
            &args[2..],
        )
    } else {
        (None, &args[1..])
    };
    let t = Instant::now();
    let mut bin = MeshBvh::build(&mesh, &BuildParams::BINNED);
    println!("binary build {:.1} ms", t.elapsed().as_secs_f64() * 1e3);
    let c = cpu_s();
    let mut w4 = MeshBvh4::from_mesh_bvh(&bin);
    let c4 = (cpu_s() - c) * 1e3;
    let c = cpu_s();
    let mut w8 = MeshBvh8::from_mesh_bvh(&bin);
    let c8 = (cpu_s() - c) * 1e3;
    // The same tree copied by `Clone`, whose buffers get no huge-page hint (4 KiB pages where
    // transparent huge pages are in `madvise` mode).
    let w8s = w8.clone();
    // The same tree with the plain slab test, in huge pages as `w8`.
    let mut w8p = MeshBvh8::from_mesh_bvh(&bin);
    w8p.bench_plain_slab();
    let huge = std::fs::read_to_string("/proc/self/smaps_rollup")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("AnonHugePages"))
                .map(str::to_owned)
        });
    println!("{}", huge.unwrap_or_default());
    println!(
        "bvh4: collapse {c4:.1} ms, {} nodes, fill {:.2}, depth {}, {:.1} MiB; bvh8: collapse {c8:.1} ms, {} nodes, fill {:.2}, depth {}, {:.1} MiB",
        w4.nodes().len(),
        w4.fill(),
        w4.depth(),
        w4.memory_bytes() as f64 / 1048576.0,
        w8.nodes().len(),
        w8.fill(),
        w8.depth(),
        w8.memory_bytes() as f64 / 1048576.0
    );
    let same = |a: Option<Hit>, b: Option<Hit>| match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => a.t == b.t,
        _ => false,
    };
    for f in ray_files {
        let rays = dynbvh::io::read_rays(f.as_ref()).unwrap();
        if std::env::var_os("ONLY_BVH8").is_some() {
            // For profilers: nothing but BVH8 closest hits.
            for _ in 0..5 {
                std::hint::black_box(rays.iter().filter(|r| w8.closest_hit(r).is_some()).count());
            }
            continue;
        }
        let step = (rays.len() / 4096).max(1);
        let sample: Vec<Ray> = rays.iter().step_by(step).copied().collect();
        let mis4 = sample
            .iter()
            .filter(|r| {
                !same(bin.closest_hit(r), w4.closest_hit(r)) || bin.any_hit(r) != w4.any_hit(r)
            })
            .count();
        let mis8 = sample
            .iter()
            .filter(|r| {
                !same(bin.closest_hit(r), w8.closest_hit(r)) || bin.any_hit(r) != w8.any_hit(r)
            })
            .count();
        let (mut s2, mut s4, mut s8) = Default::default();
        for r in &sample {
            let _ = bin.closest_hit_counted(r, &mut s2);
            let _ = w4.closest_hit_counted(r, &mut s4);
            let _ = w8.closest_hit_counted(r, &mut s8);
        }
        let per = |s: TraversalStats| {
            format!(
                "{:.1} nodes {:.1} tris",
                s.nodes as f64 / sample.len() as f64,
                s.prims as f64 / sample.len() as f64
            )
        };
        println!(
            "{f}: mismatches bvh4 {mis4}/{n} bvh8 {mis8}/{n}; per ray: bin {} | bvh4 {} | bvh8 {}",
            per(s2),
            per(s4),
            per(s8),
            n = sample.len()
        );
        println!(
            "  closest Mrays/s cpu: bin {:.2} bvh4 {:.2} bvh8 {:.2} bvh8 4k pages {:.2} bvh8 plain slab {:.2}",
            mrays(&rays, |r| bin.closest_hit(r).is_some()),
            mrays(&rays, |r| w4.closest_hit(r).is_some()),
            mrays(&rays, |r| w8.closest_hit(r).is_some()),
            mrays(&rays, |r| w8s.closest_hit(r).is_some()),
            mrays(&rays, |r| w8p.closest_hit(r).is_some())
        );
        println!(
            "  any     Mrays/s cpu: bin {:.2} bvh4 {:.2} bvh8 {:.2} bvh8 4k pages {:.2} bvh8 plain slab {:.2}",
            mrays(&rays, |r| bin.any_hit(r)),
            mrays(&rays, |r| w4.any_hit(r)),
            mrays(&rays, |r| w8.any_hit(r)),
            mrays(&rays, |r| w8s.any_hit(r)),
            mrays(&rays, |r| w8p.any_hit(r))
        );
    }
    if let Some(def) = def {
        println!(
            "refit ms cpu (1 thread): bin {:.2} bvh4 {:.2} bvh8 {:.2}",
            refit_ms(&mesh, &def, |m| bin.refit(m)),
            refit_ms(&mesh, &def, |m| w4.refit(m)),
            refit_ms(&mesh, &def, |m| w8.refit(m))
        );
        // The last refit went to the deformed mesh.
        w8.validate(&def).unwrap();
        w4.validate(&def).unwrap();
    }
}
