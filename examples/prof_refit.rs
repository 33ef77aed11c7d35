//! Times refit from a mesh to its deformed version: `cargo run --release --example prof_refit A.tri B.tri`.
use dynbvh::bvh::{BuildParams, MeshBvh};
use std::time::Instant;

#[path = "common/cpu.rs"]
mod cpu;
use cpu::cpu_s;

fn main() {
    let mut args = std::env::args().skip(1);
    let a = dynbvh::io::read_tri(args.next().expect("mesh").as_ref()).unwrap();
    let b = dynbvh::io::read_tri(args.next().expect("deformed mesh").as_ref()).unwrap();
    let mut bvh = MeshBvh::build(&a, &BuildParams::BINNED);
    let mut times = Vec::new();
    for i in 0..11 {
        let m = if i % 2 == 0 { &b } else { &a };
        let (t, c) = (Instant::now(), cpu_s());
        bvh.refit(m);
        times.push((t.elapsed().as_secs_f64() * 1e3, (cpu_s() - c) * 1e3));
    }
    times.sort_by(|x, y| x.0.total_cmp(&y.0));
    let (wall, cpu) = times[times.len() / 2];
    println!(
        "refit median {wall:.2} ms wall ({cpu:.2} ms cpu), sah {:.2}",
        bvh.bvh().sah_cost()
    );
}
