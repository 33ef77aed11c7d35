//! Closest hits in one function that is never inlined, so that callgrind can count the
//! instructions a ray costs: a count that is the same on every run, whatever else the machine
//! does, where times are not. The structure is the BVH8 (`STRUCT=bvh8`, the default), the
//! binary BVH (`bvh`) or one of `build-bench`'s other structures by name (`kdtree`, `bih`,
//! `grid`, `octree`; called through `dyn Accel`). Valgrind does not run AVX-512 code, so build
//! for AVX2:
//!
//! ```sh
//! RUSTFLAGS="-C target-cpu=haswell" CARGO_TARGET_DIR=target/vg \
//!   cargo build --release --example prof_instr
//! valgrind --tool=callgrind --toggle-collect='*trace_rays*' \
//!   target/vg/release/examples/prof_instr DIR INPUT [RAYS]
//! ```
//!
//! with `DIR/INPUT.tri`, `DIR/INPUT_primary.rays` (a square camera image: a coherent subset of
//! about `RAYS` of them in the peers bench's tile order) and `DIR/INPUT_random.rays` (the first
//! `RAYS`, default 16384). Each set is traced three times; the instructions per ray are
//! callgrind's total over `6 * RAYS`. Prints the nodes and triangles per ray of each set.
use dynbvh::accel::AccelKind;
use dynbvh::bvh::{BuildParams, MeshBvh, MeshBvh8, TraversalStats};
use dynbvh::geom::{Hit, Ray};
use std::hint::black_box;

#[inline(never)]
fn trace_rays(closest: &impl Fn(&Ray) -> Option<Hit>, rays: &[Ray]) -> f32 {
    rays.iter()
        .filter_map(|r| closest(black_box(r)))
        .map(|h| h.t)
        .sum()
}

/// Each set traced three times.
fn passes(closest: &impl Fn(&Ray) -> Option<Hit>, camera: &[Ray], random: &[Ray]) -> f32 {
    let mut sum = 0.0;
    for _ in 0..3 {
        sum += trace_rays(closest, camera);
        sum += trace_rays(closest, random);
    }
    sum
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [dir, name] = [&args[0], &args[1]];
    let n: usize = args.get(2).map_or(16384, |s| s.parse().expect("RAYS"));
    let mesh = dynbvh::io::read_tri(format!("{dir}/{name}.tri").as_ref()).expect("mesh");
    let kind = std::env::var("STRUCT").unwrap_or_else(|_| "bvh8".into());
    let bvh = MeshBvh::build(&mesh, &BuildParams::BINNED);
    let w8 = MeshBvh8::from_mesh_bvh(&bvh);
    let other = match kind.as_str() {
        "bvh8" | "bvh" => None,
        k => Some(k.parse::<AccelKind>().expect("STRUCT").build(&mesh)),
    };
    let read = |set: &str| {
        dynbvh::io::read_rays(format!("{dir}/{name}_{set}.rays").as_ref()).expect("rays")
    };
    let image = dynbvh::report::rays::image_subset(&read("primary"), n);
    let side = (image.len() as f64).sqrt().round() as usize;
    let mut camera = Vec::with_capacity(image.len());
    dynbvh::bvh::image_tiles(side, side, |idx| {
        camera.extend(idx.iter().map(|&i| image[i]));
    });
    let random: Vec<Ray> = read("random").into_iter().take(n).collect();
    let sum = match (kind.as_str(), &other) {
        (_, Some(a)) => passes(&|r: &Ray| a.closest_hit(r), &camera, &random),
        ("bvh", _) => passes(&|r: &Ray| bvh.closest_hit(r), &camera, &random),
        _ => passes(&|r: &Ray| w8.closest_hit(r), &camera, &random),
    };
    for (set, rays) in [("camera", &camera), ("random", &random)] {
        let mut st = TraversalStats::default();
        for r in rays {
            let _ = match (kind.as_str(), &other) {
                (_, Some(a)) => a.closest_hit_counted(r, &mut st),
                ("bvh", _) => bvh.closest_hit_counted(r, &mut st),
                _ => w8.closest_hit_counted(r, &mut st),
            };
        }
        let per = |x: u64| x as f64 / rays.len() as f64;
        println!(
            "{kind}, {set}: {} rays, {:.2} nodes and {:.2} triangles a ray",
            rays.len(),
            per(st.nodes),
            per(st.prims)
        );
    }
    println!("(sum of hit distances {sum})");
}
