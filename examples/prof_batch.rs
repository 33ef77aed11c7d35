//! The engine's batch query against a loop of single queries, on one thread:
//! `cargo run --release --example prof_batch -- DIR INPUT...` with `DIR/INPUT.tri` and
//! `DIR/INPUT_{primary,random}.rays` (the first 2^18 rays of each). One mesh, one instance;
//! for each ray set, whether `bvh::ray_order` reorders it, and the medians over `PASSES`
//! (default 7) alternated passes of `Engine::closest_hit_batch` and of `closest_hit` ray by
//! ray, in CPU time, with the median of their ratios. The answers are checked to be the same.
use dynbvh::bvh::ray_order::RayOrder;
use dynbvh::engine::{Engine, EngineConfig};

#[path = "common/cpu.rs"]
mod cpu;
use cpu::{cpu_s, median, one_thread};

fn main() {
    one_thread();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let passes: usize = std::env::var("PASSES").map_or(7, |s| s.parse().expect("PASSES"));
    let dir = &args[0];
    for name in &args[1..] {
        let mesh = dynbvh::io::read_tri(format!("{dir}/{name}.tri").as_ref()).unwrap();
        let mut e = Engine::new(EngineConfig::default());
        let id = e.add_mesh(mesh.positions.clone(), mesh.indices.clone());
        e.add_instance(id, glam::Affine3A::IDENTITY);
        e.update();
        for set in ["primary", "random"] {
            let mut rays =
                dynbvh::io::read_rays(format!("{dir}/{name}_{set}.rays").as_ref()).unwrap();
            rays.truncate(1 << 18);
            let reordered = RayOrder::reordered(&rays, &e.bounds());
            let mut one = vec![None; rays.len()];
            let mut batch = vec![None; rays.len()];
            let (mut l, mut b) = (Vec::new(), Vec::new());
            for _ in 0..passes {
                let c = cpu_s();
                for (o, r) in one.iter_mut().zip(&rays) {
                    *o = e.closest_hit(r);
                }
                l.push(cpu_s() - c);
                let c = cpu_s();
                e.closest_hit_batch(&rays, &mut batch);
                b.push(cpu_s() - c);
            }
            assert_eq!(one, batch, "{name} {set}: the batch's answers differ");
            let ratio = median(l.iter().zip(&b).map(|(l, b)| l / b).collect());
            let rate = |t: Vec<f64>| rays.len() as f64 / median(t) / 1e6;
            println!(
                "{name} {set} (reordered: {reordered}): loop {:.2} Mrays/s, batch {:.2} Mrays/s, batch / loop {ratio:.3}",
                rate(l),
                rate(b)
            );
        }
    }
}
