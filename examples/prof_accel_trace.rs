//! One structure's closest-hit rate against the binary BVH's, both built once in one process
//! and traced in alternating passes, each pass of the structure divided by the BVH pass just
//! before it: `cargo run --release --example prof_accel_trace MESH RAYS NAME [PASSES]`.
//!
//! MESH and RAYS as `common/input.rs` reads them (`.tri`, `.obj` or glTF; `.rays`,
//! `camera:SIDE` or `random:N`); NAME as `build-bench --methods` takes it (kdtree, bih,
//! grid, octree); PASSES default 12; `BIH_LEAF=n` builds the BIH with leaves of at most `n`
//! triangles, `BIH_SAH=n` with the SAH tried at its nodes of at least 1/n of them (0:
//! nowhere); `ONLY=hits` or `ONLY=misses` keeps the rays that hit (miss) the mesh. Run with
//! `RAYON_NUM_THREADS=1 taskset -c 1`. Prints the median and every pass of the structure's
//! time ÷ the BVH's (CPU), i.e. how many times slower the structure is.
use dynbvh::accel::{Accel, AccelKind, Bih, BihParams};
use dynbvh::bvh::{BuildParams, MeshBvh};

#[path = "common/cpu.rs"]
mod cpu;
use cpu::{cpu_s, median};
#[path = "common/input.rs"]
mod input;

fn main() {
    let mut args = std::env::args().skip(1);
    let mesh = input::mesh(&args.next().expect("mesh"));
    let rays = input::rays(&args.next().expect("rays"), &mesh);
    let kind: AccelKind = args.next().expect("name").parse().unwrap();
    let passes: usize = args.next().map_or(12, |v| v.parse().unwrap());
    let bvh = MeshBvh::build(&mesh, &BuildParams::BINNED);
    let rays: Vec<_> = match std::env::var("ONLY").as_deref() {
        Ok("hits") => rays
            .into_iter()
            .filter(|r| bvh.closest_hit(r).is_some())
            .collect(),
        Ok("misses") => rays
            .into_iter()
            .filter(|r| bvh.closest_hit(r).is_none())
            .collect(),
        _ => rays,
    };
    let bih_env = |k: &str| std::env::var(k).ok().map(|v| v.parse::<usize>().unwrap());
    let s: Box<dyn Accel> = match (bih_env("BIH_LEAF"), bih_env("BIH_SAH")) {
        (None, None) => kind.build(&mesh),
        (leaf, sah) if kind == AccelKind::Bih => {
            let d = BihParams::default();
            Box::new(Bih::build(
                &mesh,
                &BihParams {
                    max_leaf_size: leaf.unwrap_or(d.max_leaf_size),
                    sah_share: sah.unwrap_or(d.sah_share),
                },
            ))
        }
        _ => kind.build(&mesh),
    };
    let mut slower = Vec::new();
    for _ in 0..passes {
        let c = cpu_s();
        let bvh_hits = rays.iter().filter(|r| bvh.closest_hit(r).is_some()).count();
        let bvh_s = cpu_s() - c;
        let c = cpu_s();
        let hits = rays.iter().filter(|r| s.closest_hit(r).is_some()).count();
        slower.push((cpu_s() - c) / bvh_s);
        assert_eq!(bvh_hits, hits, "{kind} and the BVH disagree");
    }
    println!(
        "{kind}: depth {}, {} rays, time / BVH time median {:.3}  {slower:.3?}",
        s.depth(),
        rays.len(),
        median(slower.clone())
    );
}
