//! Times binned-SAH builds over a `.tri` file's triangle boxes, cold (`Bvh::build`: fresh
//! buffers, page faults included) and warm (`Bvh::rebuild` into a grown tree and workspace, as
//! the engine rebuilds), and prints the medians of CPU and wall time with the SAH cost; then the
//! same for the whole `MeshBvh` (triangle boxes, tree, triangles copied in leaf order: what
//! `dynbvh build-bench` times, cold); then the 8-wide tree, built and collapsed:
//!
//! `cargo run --release --example prof_build FILE.tri [bins] [runs]`
//!
//! `WIDEST=1` bins only the widest axis; `METHOD=sweep` or `METHOD=median` times that builder
//! instead; `RAYON_NUM_THREADS` sets the thread count.
use dynbvh::bvh::{BuildParams, BuildWorkspace, Bvh, MeshBvh, MeshBvh8};
use dynbvh::geom::Aabb;
use std::time::Instant;

#[path = "common/cpu.rs"]
mod cpu;
use cpu::cpu_s;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let path = std::env::args()
        .nth(1)
        .expect("usage: prof_build FILE.tri [bins] [runs]");
    let bins: usize = std::env::args().nth(2).map_or(16, |s| s.parse().unwrap());
    let runs: usize = std::env::args().nth(3).map_or(5, |s| s.parse().unwrap());
    let mesh = dynbvh::io::read_tri(path.as_ref()).unwrap();
    let mut p = BuildParams {
        all_axes: std::env::var("WIDEST").is_err(),
        ..BuildParams::binned(bins)
    };
    match std::env::var("METHOD").as_deref() {
        Ok("sweep") => p = BuildParams::SWEEP,
        Ok("median") => p = BuildParams::MEDIAN,
        _ => {}
    }
    let boxes: Vec<Aabb> = (0..mesh.len()).map(|i| mesh.triangle_bounds(i)).collect();
    let report = |what: &str, (cold, warm): (Times, Times), sah: f32| {
        println!(
            "{what} {} {} threads: cold {:.1} ms cpu ({:.1} wall), warm {:.1} ms cpu ({:.1} wall), sah {sah:.3}",
            p.name(),
            rayon::current_num_threads(),
            median(cold.0),
            median(cold.1),
            median(warm.0),
            median(warm.1),
        );
    };

    let mut ws = BuildWorkspace::default();
    let mut tree = Bvh::build(&boxes, &p);
    tree.rebuild(&boxes, &p, &mut ws);
    let times = cold_and_warm(
        runs,
        || drop(Bvh::build(&boxes, &p)),
        || tree.rebuild(&boxes, &p, &mut ws),
    );
    report("bvh", times, tree.sah_cost());

    let mut ws = BuildWorkspace::default();
    let mut m = MeshBvh::build(&mesh, &p);
    m.rebuild_indexed(&mesh.positions, &mesh.indices, &p, &mut ws);
    let times = cold_and_warm(
        runs,
        || drop(MeshBvh::build(&mesh, &p)),
        || m.rebuild_indexed(&mesh.positions, &mesh.indices, &p, &mut ws),
    );
    report("mesh", times, m.bvh().sah_cost());

    // The 8-wide tree: the binary build and its collapse, cold (as the peers bench times it)
    // and warm (a rebuild collapsed into the grown wide tree, as the engine does).
    let mut w = MeshBvh8::from_mesh_bvh(&m);
    let times = cold_and_warm(
        runs,
        || drop(MeshBvh8::build(&mesh, &p)),
        || {
            m.rebuild_indexed(&mesh.positions, &mesh.indices, &p, &mut ws);
            w.collapse_from(&m);
        },
    );
    report("bvh8", times, m.bvh().sah_cost());
}

/// CPU and wall-clock milliseconds of each run.
type Times = (Vec<f64>, Vec<f64>);

/// Times `runs` alternations of a cold build (`cold`, its result dropped inside) and a warm
/// one (`warm`).
fn cold_and_warm(runs: usize, mut cold: impl FnMut(), mut warm: impl FnMut()) -> (Times, Times) {
    let (mut c_t, mut w_t) = ((vec![], vec![]), (vec![], vec![]));
    for _ in 0..runs {
        for (f, t) in [
            (&mut cold as &mut dyn FnMut(), &mut c_t),
            (&mut warm, &mut w_t),
        ] {
            let (c, w) = (cpu_s(), Instant::now());
            f();
            t.0.push((cpu_s() - c) * 1e3);
            t.1.push(w.elapsed().as_secs_f64() * 1e3);
        }
    }
    (c_t, w_t)
}
