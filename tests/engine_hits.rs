//! Traversal correctness of the engine after every deformation: for every shipped animation
//! and every animated glTF sample, on every frame (capped), under every policy and with both
//! traversals (binary and 8-wide mesh trees), rays through the engine hit what brute force over
//! the posed world triangles hits, and its packet queries give exactly its single-ray answers. On the same frames,
//! each deforming mesh's 4- and 8-wide trees (built on the first frame, refitted on every
//! later one) and its packet queries give exactly brute force's hits in mesh space. Those runs
//! record a tiny trace time, so `amortized` hardly rebuilds there; the default configuration
//! (default policy, top-level policy and traversal) also runs on `explode.glb` and `swap.glb`
//! with costs that make it rebuild, probe and go back to replaced trees, checked the same way
//! on every frame, and the test asserts that those rebuilds and reverts happened.
//!
//! Rigid and shared-mesh instances are traced in mesh space through an inverse transform, so
//! their distances differ from world-space brute force by rounding: distances are compared with
//! a tolerance, and a ray that one side hits and the other misses must graze a triangle's edge
//! (a barycentric coordinate within 1e-3 of 0). Such grazing rays must stay rare.

use dynbvh::anim::Scene;
use dynbvh::bvh::{MeshBvh4, MeshBvh8, PacketMode, brute_force_any, brute_force_closest};
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::source::FrameSource;
use dynbvh::engine::{
    CostMeasure, Engine, EngineConfig, MeshId, Policy, SceneHit, Timing, TlasPolicy, Traversal,
};
use dynbvh::geom::{Hit, Ray, RayTriPrecomp, TriMesh, intersect_triangle};
use dynbvh::report::rays::{camera_rays, random_rays};
use std::path::{Path, PathBuf};

/// Frames per file, spread over its animations.
const FRAMES_PER_FILE: usize = 36;
const GRAZE: f32 = 1e-3;

fn policies() -> Vec<Policy> {
    let mut p = Policy::standard_set();
    p.push(Policy::Periodic(3));
    p.extend([
        Policy::Optimize(0.05),
        Policy::Partial(0.25),
        Policy::Ladder,
        Policy::Async,
    ]);
    p
}

fn samples_dir() -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/gltf-samples");
    if dir.is_dir() {
        return Some(dir);
    }
    let msg = format!(
        "!!!!! glTF samples folder {} is missing: sample-file engine tests SKIPPED !!!!!",
        dir.display()
    );
    assert!(std::env::var_os("CI").is_none(), "{msg} (CI is set)");
    eprintln!("{msg}");
    None
}

fn gltf_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            if p.file_name().is_some_and(|n| n == "_meta") {
                continue;
            }
            gltf_files(&p, out);
        } else if p
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("glb") || e.eq_ignore_ascii_case("gltf"))
        {
            out.push(p);
        }
    }
}

fn barycentric_min(u: f32, v: f32) -> f32 {
    u.min(v).min(1.0 - u - v)
}

/// World-space test of one flattened triangle.
fn world_hit(mesh: &TriMesh, tri: usize, ray: &Ray) -> Option<(f32, f32, f32)> {
    let [a, b, c] = mesh.triangle(tri);
    intersect_triangle(ray, &RayTriPrecomp::new(ray.dir()), a, b, c, f32::INFINITY)
}

#[derive(Default)]
struct Tally {
    rays: usize,
    grazing: usize,
}

fn compare(
    src: &GltfSource<'_>,
    mesh: &TriMesh,
    ray: &Ray,
    want: Option<Hit>,
    got: Option<SceneHit>,
    tol: f32,
    tally: &mut Tally,
) -> Result<(), String> {
    tally.rays += 1;
    // A hit on a triangle's edge, or right at the ray's origin, may go either way.
    let engine_graze = |g: &SceneHit| barycentric_min(g.u, g.v) < GRAZE || g.t <= tol;
    let brute_graze = |w: &Hit| barycentric_min(w.u, w.v) < GRAZE || w.t <= tol;
    match (want, got) {
        (None, None) => Ok(()),
        (Some(w), Some(g)) => {
            let flat = src.flat_triangle(&g);
            let ok_t = (w.t - g.t).abs() <= tol * w.t.abs().max(1.0);
            // The reported triangle must be hit there in world space too (or grazed).
            let here = world_hit(mesh, flat, ray)
                .is_some_and(|(t, _, _)| (t - g.t).abs() <= tol * t.abs().max(1.0));
            if ok_t && (here || engine_graze(&g)) {
                if !here {
                    tally.grazing += 1;
                }
                return Ok(());
            }
            let nearer_grazes = if g.t < w.t {
                engine_graze(&g)
            } else {
                brute_graze(&w)
            };
            if nearer_grazes {
                tally.grazing += 1;
                Ok(())
            } else {
                Err(format!(
                    "brute force t {} tri {}, engine t {} tri {flat} (instance {:?} prim {})",
                    w.t, w.prim, g.t, g.instance, g.prim
                ))
            }
        }
        (Some(w), None) if brute_graze(&w) => {
            tally.grazing += 1;
            Ok(())
        }
        (None, Some(g)) if engine_graze(&g) => {
            tally.grazing += 1;
            Ok(())
        }
        (w, g) => Err(format!("brute force {w:?}, engine {g:?}")),
    }
}

/// The wide trees of one deforming mesh, refitted frame after frame.
struct Wide {
    bvh4: MeshBvh4,
    bvh8: MeshBvh8,
}

/// Closest hits equal brute force exactly (a different triangle only at the same distance, and
/// really hit there).
fn same_hit(mesh: &TriMesh, ray: &Ray, want: Option<Hit>, got: Option<Hit>) -> bool {
    match (want, got) {
        (None, None) => true,
        (Some(w), Some(g)) => {
            w.t == g.t
                && (w.prim == g.prim
                    || world_hit(mesh, g.prim as usize, ray).is_some_and(|h| h.0 == g.t))
        }
        _ => false,
    }
}

/// The deforming meshes of engine `e` through the wide trees (refitted to this frame) and
/// through packets of its binary tree and of the BVH8, against brute force in mesh space.
fn check_wide_and_packets(name: &str, f: usize, e: &Engine, meshes: &[MeshId], wide: &mut [Wide]) {
    for (m, w) in meshes.iter().zip(wide) {
        let (pos, idx) = (e.positions(*m), e.indices(*m));
        w.bvh4.refit_indexed(pos, idx);
        w.bvh8.refit_indexed(pos, idx);
        let mesh = TriMesh::new(pos.to_vec(), idx.to_vec());
        let bounds = mesh.bounds();
        if bounds.is_empty() {
            continue;
        }
        let mut rays = camera_rays(&bounds, 12, 12);
        let pad = glam::Vec3::splat(0.1 * bounds.extent().length().max(1e-6));
        let padded = dynbvh::geom::Aabb::new(bounds.min - pad, bounds.max + pad);
        rays.extend(random_rays(&padded, 64, f as u64 + 7));
        let mut packet = vec![None; rays.len()];
        e.mesh_bvh(*m)
            .closest_hit_packet_mode(&rays, &mut packet, PacketMode::Always);
        let mut packet_any = vec![false; rays.len()];
        e.mesh_bvh(*m)
            .any_hit_packet_mode(&rays, &mut packet_any, PacketMode::Always);
        let mut packet8 = vec![None; rays.len()];
        w.bvh8
            .closest_hit_packet_mode(&rays, &mut packet8, PacketMode::Always);
        let mut packet8_any = vec![false; rays.len()];
        w.bvh8
            .any_hit_packet_mode(&rays, &mut packet8_any, PacketMode::Always);
        for (k, r) in rays.iter().enumerate() {
            let want = brute_force_closest(&mesh, r);
            let any = want.is_some();
            for (what, got, got_any) in [
                ("bvh4", w.bvh4.closest_hit(r), w.bvh4.any_hit(r)),
                ("bvh8", w.bvh8.closest_hit(r), w.bvh8.any_hit(r)),
                ("packet", packet[k], packet_any[k]),
                ("bvh8 packet", packet8[k], packet8_any[k]),
            ] {
                assert!(
                    same_hit(&mesh, r, want, got) && got_any == any,
                    "{name} frame {f} mesh {m:?} {what} ray {k} {r:?}: brute force {want:?}, \
                     got {got:?} (any {got_any})"
                );
            }
        }
    }
}

/// Runs every policy with both traversals in lockstep over `frames` frames of one animation
/// and checks each frame.
fn check_animation(scene: &Scene, anim: Option<usize>, frames: usize, tally: &mut Tally) {
    let configs: Vec<EngineConfig> = [Traversal::Binary, Traversal::Wide]
        .into_iter()
        .flat_map(|traversal| {
            policies().into_iter().map(move |policy| EngineConfig {
                policy,
                tlas: TlasPolicy::Threshold(1.2),
                traversal,
                ..EngineConfig::default()
            })
        })
        .collect();
    check_configs(scene, anim, frames, &configs, Trace::Ms(0.01), 0, tally);
}

/// The trace time each engine records after each frame.
#[derive(Clone, Copy)]
enum Trace {
    /// This many ms.
    Ms(f64),
    /// This many times what the engine's timing prices a rebuild of all its deforming meshes.
    Rebuilds(f64),
}

/// Runs engines of `configs` in lockstep over `frames` frames of one animation (the deforming
/// meshes' first trees built for `clip_poses` poses of it, 0: plainly) and checks each frame;
/// returns the mesh rebuilds and the reverts to replaced trees of each engine.
fn check_configs(
    scene: &Scene,
    anim: Option<usize>,
    frames: usize,
    configs: &[EngineConfig],
    trace: Trace,
    clip_poses: usize,
    tally: &mut Tally,
) -> Vec<(u32, u32)> {
    let mut src = GltfSource::new(scene, anim, FrameTimes::Count(frames))
        .unwrap()
        .with_clip_aware(clip_poses);
    let mut engines: Vec<Engine> = configs.iter().map(|&c| src.build(0, c)).collect();
    let mut done = vec![(0u32, 0u32); engines.len()];
    let trace_ms: Vec<f64> = engines
        .iter()
        .map(|e| match trace {
            Trace::Ms(ms) => ms,
            Trace::Rebuilds(k) => {
                k * src
                    .deforming()
                    .iter()
                    .map(|m| {
                        e.config()
                            .timing
                            .build_ms(0.0, e.indices(*m).len(), &e.config().prices)
                    })
                    .sum::<f64>()
            }
        })
        .collect();
    let deforming = src.deforming().to_vec();
    let params = EngineConfig::default().build;
    let mut wide: Vec<Wide> = deforming
        .iter()
        .map(|m| {
            let (pos, idx) = (engines[0].positions(*m), engines[0].indices(*m));
            Wide {
                bvh4: MeshBvh4::build_indexed(pos, idx, &params),
                bvh8: MeshBvh8::build_indexed(pos, idx, &params),
            }
        })
        .collect();
    let mut flat = TriMesh::default();
    for f in 1..=src.frames() {
        for (e, d) in engines.iter_mut().zip(&mut done) {
            src.advance(e, f);
            let s = e.update();
            d.0 += s.rebuilds;
            d.1 += s.reverts;
        }
        check_wide_and_packets(&src.name(), f, &engines[0], &deforming, &mut wide);
        src.flatten_into(&mut flat);
        let bounds = flat.bounds();
        if bounds.is_empty() {
            continue;
        }
        let diag = bounds.extent().length().max(1e-6);
        let mut rays = camera_rays(&bounds, 20, 20);
        // Random origins in a padded box, so that flat scenes do not start rays on a surface.
        let pad = glam::Vec3::splat(0.1 * diag);
        let padded = dynbvh::geom::Aabb::new(bounds.min - pad, bounds.max + pad);
        rays.extend(random_rays(&padded, 150, f as u64));
        let want: Vec<(Option<Hit>, bool)> = rays
            .iter()
            .map(|r| (brute_force_closest(&flat, r), brute_force_any(&flat, r)))
            .collect();
        let mut packet = vec![None; rays.len()];
        let mut packet_any = vec![false; rays.len()];
        for ((e, c), &trace_ms) in engines.iter_mut().zip(configs).zip(&trace_ms) {
            let (p, t) = (c.policy, c.traversal);
            e.closest_hit_packet_mode(&rays, &mut packet, PacketMode::Always);
            e.any_hit_packet_mode(&rays, &mut packet_any, PacketMode::Always);
            // Rays shorter than the scene test any-hit with a finite range too.
            for (k, (ray, &(w, w_any))) in rays.iter().zip(&want).enumerate() {
                let tol = 2e-4 * diag / ray.dir().length();
                let got = e.closest_hit(ray);
                assert_eq!(
                    packet[k],
                    got,
                    "{} frame {f} policy {p} {t} ray {k}: packet closest hit",
                    src.name()
                );
                assert_eq!(
                    packet_any[k],
                    e.any_hit(ray),
                    "{} frame {f} policy {p} {t} ray {k}: packet any hit",
                    src.name()
                );
                compare(&src, &flat, ray, w, got, tol, tally).unwrap_or_else(|m| {
                    panic!(
                        "{} frame {f} policy {p} {t} ray {k} {ray:?}: {m}",
                        src.name()
                    )
                });
                let any = e.any_hit(ray);
                if any != w_any {
                    let grazing = w.map_or(
                        got.is_some_and(|g| barycentric_min(g.u, g.v) < GRAZE || g.t <= tol),
                        |w| barycentric_min(w.u, w.v) < GRAZE || w.t <= tol,
                    );
                    assert!(
                        grazing,
                        "{} frame {f} policy {p} {t} ray {k}: any hit {any}, brute force {w_any}",
                        src.name()
                    );
                }
            }
            // The trees stay valid: every mesh's tree bounds its triangles.
            for m in src.deforming() {
                let mesh = TriMesh::new(e.positions(*m).to_vec(), e.indices(*m).to_vec());
                e.mesh_bvh(*m).validate(&mesh).unwrap();
                if let Some(w) = e.mesh_bvh8(*m) {
                    w.validate(&mesh).unwrap();
                }
                assert_eq!(e.mesh_bvh8(*m).is_some(), t == Traversal::Wide);
            }
            e.record_trace(trace_ms, rays.len() as u64);
        }
    }
    done
}

fn check_file(path: &Path) -> Option<Tally> {
    let (scene, _) = Scene::load(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    if scene.animations.is_empty() {
        return None;
    }
    let n = scene.animations.len();
    let per = (FRAMES_PER_FILE / n).max(4);
    let mut tally = Tally::default();
    for a in 0..n.min(FRAMES_PER_FILE / 4) {
        check_animation(&scene, Some(a), per, &mut tally);
    }
    eprintln!(
        "{}: {} animation(s), {} ray checks, {} grazing",
        path.display(),
        n,
        tally.rays,
        tally.grazing
    );
    assert!(
        tally.grazing * 100 <= tally.rays,
        "{}: too many grazing disagreements ({} of {})",
        path.display(),
        tally.grazing,
        tally.rays
    );
    Some(tally)
}

#[test]
fn shipped_animations_match_brute_force_every_frame_every_policy() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("animations");
    let mut files = Vec::new();
    gltf_files(&dir, &mut files);
    assert!(
        files.len() >= 5,
        "expected the generated animations in {}",
        dir.display()
    );
    for f in &files {
        assert!(check_file(f).is_some(), "{} has no animation", f.display());
    }
}

/// The default configuration (default policy, top-level policy and traversal) with modelled
/// costs and a recorded trace time that make the default policy rebuild on the animations that
/// deform a lot, put rebuilds on probation and go back to replaced trees (the path the 0.01 ms
/// trace above never takes): every frame still matches brute force. The 16x16 camera rays of
/// `engine_policy.rs`'s revert test only compare with an always-refitted engine.
#[test]
fn clip_aware_first_trees_match_brute_force_every_frame() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("animations");
    let configs: Vec<EngineConfig> = [Traversal::Binary, Traversal::Wide]
        .into_iter()
        .flat_map(|traversal| {
            [Policy::Refit, Policy::DEFAULT]
                .into_iter()
                .map(move |policy| EngineConfig {
                    policy,
                    traversal,
                    ..EngineConfig::default()
                })
        })
        .collect();
    for file in ["tube.glb", "swap.glb", "explode.glb"] {
        let (scene, _) = Scene::load(dir.join(file)).unwrap();
        let mut tally = Tally::default();
        check_configs(
            &scene,
            Some(0),
            20,
            &configs,
            Trace::Ms(0.01),
            4,
            &mut tally,
        );
        assert!(tally.rays > 0, "{file}: no ray checked");
    }
}

#[test]
fn default_config_matches_brute_force_through_rebuilds_and_reverts() {
    let timing = Timing::Modeled {
        refit_ns_per_tri: 17.0,
        rebuild_ns_per_tri: 200.0,
        estimate_ns_per_tri: 75.0,
    };
    // Probation (and so reverts) is the SAH measure's; the default ray-work measure runs
    // beside it on the same frames and rays, checked against brute force too.
    let config = EngineConfig {
        timing,
        cost: CostMeasure::Sah,
        ..EngineConfig::default()
    };
    let default = EngineConfig {
        timing,
        ..EngineConfig::default()
    };
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("animations");
    // (file, frames, trace time in rebuilds, least rebuilds, least reverts): on swap, five
    // rebuilds' worth of tracing a frame makes it rebuild while the grids overlap and go back
    // to the frame-0 tree (as in `engine_policy.rs`); explode degrades steadily, so its
    // rebuilds pay and stay.
    for (file, frames, k, least_rebuilds, least_reverts) in
        [("swap.glb", 60, 5.0, 1, 1), ("explode.glb", 30, 5.0, 2, 0)]
    {
        let (scene, _) = Scene::load(dir.join(file)).unwrap();
        let mut tally = Tally::default();
        let done = check_configs(
            &scene,
            Some(0),
            frames,
            &[config, default],
            Trace::Rebuilds(k),
            0,
            &mut tally,
        );
        let (rebuilds, reverts) = done[0];
        eprintln!(
            "{file}: default config, {rebuilds} rebuilds, {reverts} reverts, {} ray checks, {} \
             grazing",
            tally.rays, tally.grazing
        );
        assert!(rebuilds >= least_rebuilds, "{file}: {rebuilds} rebuilds");
        assert!(reverts >= least_reverts, "{file}: {reverts} reverts");
        assert!(
            tally.grazing * 100 <= tally.rays,
            "{file}: too many grazing"
        );
    }
}

#[test]
fn animated_samples_match_brute_force_every_frame_every_policy() {
    let Some(dir) = samples_dir() else { return };
    let mut files = Vec::new();
    gltf_files(&dir, &mut files);
    let checked = files.iter().filter_map(|f| check_file(f)).count();
    assert!(checked >= 10, "only {checked} animated sample files found");
}
