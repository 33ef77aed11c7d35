//! Times single-threaded closest-hit tracing: `cargo run --release --example prof_trace MESH.tri RAYS.rays`.
use dynbvh::bvh::{BuildParams, MeshBvh, TraversalStats};
use std::time::Instant;

#[path = "common/cpu.rs"]
mod cpu;
use cpu::cpu_s;

fn main() {
    let mut args = std::env::args().skip(1);
    let mesh = dynbvh::io::read_tri(args.next().expect("mesh").as_ref()).unwrap();
    let rays = dynbvh::io::read_rays(args.next().expect("rays").as_ref()).unwrap();
    let ci: f32 = std::env::var("CI_COST")
        .ok()
        .map_or(1.0, |s| s.parse().unwrap());
    let leaf: u32 = std::env::var("MAX_LEAF")
        .ok()
        .map_or(8, |s| s.parse().unwrap());
    let params = BuildParams {
        intersection_cost: ci,
        max_leaf_size: leaf,
        ..BuildParams::BINNED
    };
    let bvh = MeshBvh::build(&mesh, &params);
    let mut st = TraversalStats::default();
    for r in &rays {
        let _ = bvh.closest_hit_counted(r, &mut st);
    }
    println!(
        "sah {:.2} nodes/ray {:.1} tris/ray {:.1}",
        bvh.bvh().sah_cost(),
        st.nodes as f64 / rays.len() as f64,
        st.prims as f64 / rays.len() as f64
    );
    for _ in 0..3 {
        let (t, c) = (Instant::now(), cpu_s());
        let hits = rays.iter().filter(|r| bvh.closest_hit(r).is_some()).count();
        let (s, cs) = (t.elapsed().as_secs_f64(), cpu_s() - c);
        println!(
            "{hits} hits, {:.2} Mrays/s wall, {:.2} Mrays/s cpu",
            rays.len() as f64 / s / 1e6,
            rays.len() as f64 / cs / 1e6
        );
    }
}
