//! Times the pieces of a build on a `.tri` file: `cargo run --release --example prof_build FILE`.
use dynbvh::bvh::{BuildParams, Bvh, MeshBvh};
use dynbvh::geom::Aabb;
use std::time::Instant;

#[path = "common/cpu.rs"]
mod cpu;
use cpu::cpu_s;

fn main() {
    let path = std::env::args()
        .nth(1)
        .expect("usage: prof_build FILE.tri [bins]");
    let bins: usize = std::env::args().nth(2).map_or(16, |s| s.parse().unwrap());
    let mesh = dynbvh::io::read_tri(path.as_ref()).unwrap();
    let all_axes = std::env::var("WIDEST").is_err();
    let p = BuildParams {
        all_axes,
        ..BuildParams::binned(bins)
    };
    let iters: usize = std::env::args().nth(3).map_or(3, |s| s.parse().unwrap());
    for _ in 0..iters {
        let c = cpu_s();
        let t = Instant::now();
        let boxes: Vec<Aabb> = (0..mesh.len()).map(|i| mesh.triangle_bounds(i)).collect();
        let t1 = t.elapsed();
        let bvh = Bvh::build(&boxes, &p);
        let t2 = t.elapsed();
        let m = MeshBvh::build(&mesh, &p);
        let t3 = t.elapsed();
        println!(
            "boxes {:?} build {:?} meshbvh {:?} cpu total {:.1} ms sah {}",
            t1,
            t2 - t1,
            t3 - t2,
            (cpu_s() - c) * 1e3,
            bvh.sah_cost() + m.bvh().sah_cost() * 0.0
        );
    }
}
