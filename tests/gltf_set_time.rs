//! `GltfSource::set_time`: posing an engine at arbitrary times gives the same trees' answers as
//! brute force over the poser's own flattened scene at that time, loops or clamps as asked,
//! and refuses bad times and engines.

use dynbvh::anim::{Scene, TimeMode};
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::{EngineConfig, FrameSource};
use dynbvh::geom::{Ray, TriMesh};
use dynbvh::glam::Vec3;

fn rays_through(bounds: dynbvh::geom::Aabb, n: usize) -> Vec<Ray> {
    let c = bounds.center();
    let r = bounds.extent().length().max(1.0);
    (0..n)
        .map(|k| {
            let a = k as f32 * 2.399_963;
            let y = 1.0 - 2.0 * (k as f32 + 0.5) / n as f32;
            let s = (1.0 - y * y).sqrt();
            let d = Vec3::new(a.cos() * s, y, a.sin() * s);
            let jitter = Vec3::new((a * 3.1).sin(), (a * 1.7).cos(), (a * 2.3).sin()) * 0.2 * r;
            Ray::new(c + d * 2.0 * r, -d * 2.0 * r + jitter)
        })
        .collect()
}

fn brute_t(mesh: &TriMesh, ray: &Ray) -> Option<f32> {
    use dynbvh::geom::{RayTriPrecomp, intersect_triangle};
    let pre = RayTriPrecomp::new(ray.dir());
    mesh.indices
        .iter()
        .filter_map(|t| {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
            intersect_triangle(ray, &pre, a, b, c, ray.tmax).map(|h| h.0)
        })
        .reduce(f32::min)
}

#[test]
fn set_time_matches_brute_force_at_arbitrary_times() {
    for (file, rigid) in [
        ("tube.glb", false),
        ("wave.glb", false),
        ("orbit.glb", true),
        ("lidar_cloth.glb", true),
    ] {
        let path = format!("{}/animations/{file}", env!("CARGO_MANIFEST_DIR"));
        let (scene, _) = Scene::load(&path).unwrap();
        let duration = scene.animations[0].duration;
        let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(1)).unwrap();
        let mut engine = src.engine(EngineConfig::default());
        let rays = rays_through(engine.bounds(), 400);
        let mut flat = TriMesh::default();
        // Off-grid times, one beyond the duration (loops) and one before the start.
        for t in [0.013, 0.77, 1.234_5, duration * 0.5, duration + 0.3, -0.4] {
            src.set_time(&mut engine, t).unwrap();
            engine.update();
            src.flatten_into(&mut flat);
            let (mut agree, mut grazing) = (0, 0);
            for r in &rays {
                let want = brute_t(&flat, r);
                let got = engine.closest_hit(r).map(|h| h.t);
                // Rigid instances are traced in their own space, the flattened scene in world
                // space: the same hits up to rounding (a ray that only one side hits grazes an
                // edge). Deforming meshes are in world space on both sides: exact.
                match (got, want) {
                    (Some(a), Some(b)) => assert!(
                        (a - b).abs() <= 1e-5 * b.abs(),
                        "{file} at t = {t}: {a} {b}"
                    ),
                    (None, None) => {}
                    _ => grazing += 1,
                }
                if !rigid {
                    assert_eq!(got, want, "{file} at t = {t}");
                }
                agree += usize::from(want.is_some());
            }
            assert!(agree > 0, "{file} at t = {t}: no ray hits");
            assert!(
                grazing <= rays.len() / 100,
                "{file} at t = {t}: {grazing} rays differ"
            );
        }
    }
}

#[test]
fn looping_and_clamping() {
    let path = format!("{}/animations/tube.glb", env!("CARGO_MANIFEST_DIR"));
    let (scene, _) = Scene::load(&path).unwrap();
    let d = scene.animations[0].duration;
    let pose_at = |mode: TimeMode, t: f32| {
        let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(1))
            .unwrap()
            .with_time_mode(mode);
        let mut e = src.engine(EngineConfig::default());
        src.set_time(&mut e, t).unwrap();
        e.update();
        let mut flat = TriMesh::default();
        src.flatten_into(&mut flat);
        flat.positions
    };
    assert_eq!(
        pose_at(TimeMode::Loop, d + 0.5),
        pose_at(TimeMode::Loop, 0.5)
    );
    assert_eq!(
        pose_at(TimeMode::Clamp, d + 0.5),
        pose_at(TimeMode::Clamp, d)
    );
    assert_ne!(
        pose_at(TimeMode::Clamp, d + 0.5),
        pose_at(TimeMode::Loop, d + 0.5)
    );
}

#[test]
fn bad_times_and_engines_are_errors() {
    let path = format!("{}/animations/tube.glb", env!("CARGO_MANIFEST_DIR"));
    let (scene, _) = Scene::load(&path).unwrap();
    let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(1)).unwrap();
    let mut empty = dynbvh::engine::Engine::new(EngineConfig::default());
    let err = src.set_time(&mut empty, 0.5).unwrap_err().to_string();
    assert!(
        err.contains("tube.glb") && err.contains("instances"),
        "{err}"
    );
    let mut e = src.engine(EngineConfig::default());
    for t in [f32::NAN, f32::INFINITY] {
        let err = src.set_time(&mut e, t).unwrap_err().to_string();
        assert!(err.contains("not finite"), "{err}");
    }
    assert!(src.set_time(&mut empty, 0.5).is_err());
}
