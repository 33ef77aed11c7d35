//! What each structure costs per frame on a deforming animation, single-threaded CPU time:
//! the kd-tree, grid and octree rebuilt every frame, the BVH (binned16) and the BIH built on
//! the first frame and refitted on the others, each then tracing the frame's camera rays.
//! `cargo run --release --example prof_accel_frames FILE.glb [FRAMES] [RAYS_PER_SIDE]`
use dynbvh::accel::{Accel, AccelKind, Bih, BihParams};
use dynbvh::anim::Scene;
use dynbvh::bvh::{BuildParams, MeshBvh};
use dynbvh::geom::TriMesh;
use dynbvh::report::rays::camera_rays;

#[path = "common/cpu.rs"]
mod cpu;
use cpu::cpu_s;

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().expect("a .glb file");
    let frames: usize = args.next().map_or(30, |s| s.parse().unwrap());
    let side: usize = args.next().map_or(256, |s| s.parse().unwrap());
    let (scene, _) = Scene::load(&path).unwrap();
    let duration = scene.animations.first().map_or(0.0, |a| a.duration);
    let mut poser = scene.poser(Some(0)).unwrap();
    let names = ["bvh-refit", "bih-refit", "kdtree", "grid", "octree"];
    let (mut update, mut trace) = ([0.0f64; 5], [0.0f64; 5]);
    let mut mesh = TriMesh::default();
    let mut bvh: Option<MeshBvh> = None;
    let mut bih: Option<Bih> = None;
    let mut hits = [0usize; 5];
    for f in 0..frames {
        poser.pose(duration * f as f32 / frames.max(2).saturating_sub(1) as f32);
        poser.flatten_into(&mut mesh);
        let rays = camera_rays(&mesh.bounds(), side, side);
        for (k, name) in names.iter().enumerate() {
            let c = cpu_s();
            let built: Box<dyn Accel>;
            let s: &dyn Accel = match *name {
                "bvh-refit" => match &mut bvh {
                    Some(b) => {
                        b.refit(&mesh);
                        b
                    }
                    None => bvh.insert(MeshBvh::build(&mesh, &BuildParams::BINNED)),
                },
                "bih-refit" => match &mut bih {
                    Some(b) => {
                        b.refit_to(&mesh);
                        b
                    }
                    None => bih.insert(Bih::build(&mesh, &BihParams::default())),
                },
                other => {
                    built = other.parse::<AccelKind>().unwrap().build(&mesh);
                    built.as_ref()
                }
            };
            let u = cpu_s();
            hits[k] += rays.iter().filter(|r| s.closest_hit(r).is_some()).count();
            update[k] += u - c;
            trace[k] += cpu_s() - u;
        }
    }
    println!(
        "{path}: {} triangles, {frames} frames, {} camera rays a frame, ms per frame (CPU)",
        mesh.len(),
        side * side
    );
    println!(
        "{:<10} {:>9} {:>9} {:>9} {:>10}",
        "structure", "update", "trace", "total", "hits"
    );
    for k in 0..names.len() {
        let n = frames as f64;
        println!(
            "{:<10} {:>9.2} {:>9.2} {:>9.2} {:>10}",
            names[k],
            update[k] * 1e3 / n,
            trace[k] * 1e3 / n,
            (update[k] + trace[k]) * 1e3 / n,
            hits[k]
        );
    }
}
