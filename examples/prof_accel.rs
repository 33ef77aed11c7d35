//! Build time (CPU), size and traversal work per ray of the other structures beside the binned
//! BVH, single-threaded: `cargo run --release --example prof_accel MESH.tri RAYS.rays [NAMES]`
//! (NAMES comma-separated, default all; `bvh` is binned16; `KD_CI`: the kd-tree's
//! intersection cost, traversal cost 1).
use dynbvh::accel::{Accel, AccelKind, KdParams, KdTree};
use dynbvh::bvh::{BuildParams, MeshBvh, TraversalStats};

#[path = "common/cpu.rs"]
mod cpu;
use cpu::cpu_s;

fn main() {
    let mut args = std::env::args().skip(1);
    let mesh = dynbvh::io::read_tri(args.next().expect("mesh").as_ref()).unwrap();
    let rays = dynbvh::io::read_rays(args.next().expect("rays").as_ref()).unwrap();
    let names = args
        .next()
        .unwrap_or_else(|| "bvh,kdtree,kdtree-naive,bih,grid,octree".into());
    for name in names.split(',') {
        let c = cpu_s();
        let ci = std::env::var("KD_CI")
            .ok()
            .map(|v| v.parse::<f32>().unwrap());
        let s: Box<dyn Accel> = if name == "bvh" {
            Box::new(MeshBvh::build(&mesh, &BuildParams::BINNED))
        } else if let (Some(ci), "kdtree") = (ci, name) {
            let params = KdParams {
                intersection_cost: ci,
                ..KdParams::default()
            };
            Box::new(KdTree::build(&mesh, &params))
        } else {
            name.parse::<AccelKind>().unwrap().build(&mesh)
        };
        let build = cpu_s() - c;
        let mut st = TraversalStats::default();
        for r in &rays {
            let _ = s.closest_hit_counted(r, &mut st);
        }
        let c = cpu_s();
        let hits = rays.iter().filter(|r| s.closest_hit(r).is_some()).count();
        let trace = cpu_s() - c;
        println!(
            "{name:<13} build {:8.1} ms cpu  nodes {:9}  MiB {:6.1}  sah {:7.2}  nodes/ray {:6.1}  tris/ray {:6.1}  {hits} hits  {:.2} Mrays/s cpu",
            build * 1e3,
            s.nodes(),
            s.memory_bytes() as f64 / (1 << 20) as f64,
            s.sah().unwrap_or(f32::NAN),
            st.nodes as f64 / rays.len() as f64,
            st.prims as f64 / rays.len() as f64,
            rays.len() as f64 / trace / 1e6
        );
    }
}
