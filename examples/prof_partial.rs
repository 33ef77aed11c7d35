//! Times the partial rebuild against a full one on a generated clip:
//! `cargo run --release --example prof_partial KIND TRIANGLES WEIGHT [SHARE...]`
//!
//! KIND is `explode` or `swap` (their one morph target at weight 0 is the build's pose, at
//! WEIGHT the refitted one). For each share (default 0.25 0.5 0.75 1) and for the full
//! rebuild: wall and CPU milliseconds (medians of `REPEATS`, default 9, each on a fresh copy
//! of the refitted tree) and the share of the SAH lost to refitting that it won back.
//! `ONLY=SHARE` runs that partial rebuild alone 200 times (for profilers).
use dynbvh::anim::generate::{Kind, generate};
use dynbvh::anim::{LoadOptions, Scene};
use dynbvh::bvh::partial::{PartialCut, PartialScratch};
use dynbvh::bvh::topology::RestructureWorkspace;
use dynbvh::bvh::{BuildParams, BuildWorkspace, MeshBvh};
use glam::Vec3;
use std::time::Instant;

#[path = "common/cpu.rs"]
mod cpu;
use cpu::{cpu_s, median};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let kind = match args[0].as_str() {
        "explode" => Kind::Explode,
        "swap" => Kind::Swap,
        k => panic!("unknown kind {k}"),
    };
    let n: usize = args[1].parse().unwrap();
    let w: f32 = args[2].parse().unwrap();
    let mut shares: Vec<f32> = args[3..].iter().map(|s| s.parse().unwrap()).collect();
    if shares.is_empty() {
        shares = vec![0.25, 0.5, 0.75, 1.0];
    }
    let repeats: usize = std::env::var("REPEATS").map_or(9, |r| r.parse().unwrap());
    let g = generate(kind, n, 1);
    let (a, b) = (&g.checks[0].1, &g.checks[1].1);
    let pos: Vec<Vec3> = a.iter().zip(b).map(|(a, b)| *a + w * (*b - *a)).collect();
    let (scene, _) = Scene::from_slice(
        std::path::Path::new("generated.glb"),
        &g.glb,
        &LoadOptions::default(),
    )
    .unwrap();
    let indices = scene.meshes[0].indices.clone();
    let params = BuildParams::BINNED;
    let mut refitted = MeshBvh::build_indexed(a, &indices, &params);
    let mut cut = PartialCut::default();
    let mut ps = PartialScratch::default();
    cut.reset(&refitted, &mut ps);
    refitted.refit_indexed(&pos, &indices);
    let fresh = MeshBvh::build_indexed(&pos, &indices, &params);
    let (refit_sah, fresh_sah) = (refitted.bvh().sah_cost(), fresh.bvh().sah_cost());
    let mut ws = RestructureWorkspace::default();
    ws.reserve(indices.len());
    if let Ok(only) = std::env::var("ONLY") {
        let share: f32 = only.parse().unwrap();
        let (mut t, mut c) = (refitted.clone(), cut.clone());
        for _ in 0..200 {
            t.clone_from(&refitted);
            c.clone_from(&cut);
            t.partial_rebuild(&mut c, share, &params, &mut ws, &mut ps);
        }
        return;
    }
    println!(
        "{:?} {} triangles at weight {w}: SAH refitted {refit_sah:.2}, fresh {fresh_sah:.2}, {} threads",
        kind,
        indices.len(),
        rayon::current_num_threads()
    );
    let mut bws = BuildWorkspace::default();
    let time = |f: &mut dyn FnMut(&mut MeshBvh)| {
        let (mut walls, mut cpus, mut sah) = (vec![], vec![], 0.0);
        for _ in 0..repeats {
            let mut t = refitted.clone();
            let (s, c) = (Instant::now(), cpu_s());
            f(&mut t);
            cpus.push((cpu_s() - c) * 1e3);
            walls.push(s.elapsed().as_secs_f64() * 1e3);
            sah = t.bvh().sah_cost();
        }
        (
            median(walls),
            median(cpus),
            (refit_sah - sah) / (refit_sah - fresh_sah),
        )
    };
    let (rw, rc, _) = time(&mut |t| t.rebuild_indexed(&pos, &indices, &params, &mut bws));
    println!("rebuild        wall {rw:7.2} ms  cpu {rc:7.2} ms");
    for share in shares {
        let (pw, pc, rec) = time(&mut |t| {
            let mut c = cut.clone();
            t.partial_rebuild(&mut c, share, &params, &mut ws, &mut ps);
        });
        println!(
            "partial:{share:<5} wall {pw:7.2} ms  cpu {pc:7.2} ms  x rebuild {:.3} (cpu {:.3})  SAH won back {:.0}%",
            pw / rw,
            pc / rc,
            100.0 * rec
        );
    }
}
