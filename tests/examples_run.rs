//! The library examples run on shipped files with small settings, and what they report holds
//! up: the lidar's clouds have returns on every frame and are valid PLY files, visibility
//! counts are bounded by the pairs and blocking more never shows more, and the proximity
//! distances agree with brute force over the posed scene.

#[allow(dead_code)]
#[path = "../examples/lidar.rs"]
mod lidar;
#[allow(dead_code)]
#[path = "../examples/proximity.rs"]
mod proximity;
#[allow(dead_code)]
#[path = "../examples/visibility.rs"]
mod visibility;

use std::path::PathBuf;

fn shipped(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("animations")
        .join(name)
}

#[test]
fn lidar_writes_a_cloud_per_frame() {
    let out = std::env::temp_dir().join(format!("dynbvh_lidar_{}", std::process::id()));
    let args = lidar::Args {
        file: shipped("lidar_cloth.glb"),
        frames: 4,
        beams: 8,
        azimuths: 90,
        out: out.clone(),
    };
    let s = lidar::run(&args).unwrap();
    assert_eq!(s.points.len(), 4);
    for (f, &n) in s.points.iter().enumerate() {
        assert!(n > 8 * 90 / 4, "frame {f}: {n} returns");
        let bytes = std::fs::read(out.join(format!("frame_{f:03}.ply"))).unwrap();
        let header_end = bytes
            .windows(11)
            .position(|w| w == b"end_header\n")
            .unwrap()
            + 11;
        let header = std::str::from_utf8(&bytes[..header_end]).unwrap();
        assert!(
            header.contains(&format!("element vertex {n}\n")),
            "{header}"
        );
        assert_eq!(bytes.len() - header_end, n * 24);
    }
    std::fs::remove_dir_all(&out).unwrap();
}

#[test]
fn visibility_counts_are_consistent() {
    let args = visibility::Args {
        file: shipped("orbit.glb"),
        frames: 4,
        agents: 12,
    };
    let s = visibility::run(&args).unwrap();
    assert_eq!(s.visible.len(), 4);
    for (v, o) in s.visible.iter().zip(&s.visible_past_agents) {
        assert!(*v <= s.pairs && *o <= s.pairs);
        assert!(v <= o, "agents blocking can only hide more: {v} > {o}");
    }
    assert!(s.visible.iter().any(|&v| v > 0) && s.visible.iter().any(|&v| v < s.pairs));
}

#[test]
fn proximity_matches_brute_force() {
    use dynbvh::anim::Scene;
    use dynbvh::engine::FrameSource;
    use dynbvh::engine::gltf::{FrameTimes, GltfSource};
    let args = proximity::Args {
        file: shipped("tube.glb"),
        steps: 6,
    };
    let s = proximity::run(&args).unwrap();
    assert_eq!(s.samples.len(), 6);
    let (scene, _) = Scene::load(&args.file).unwrap();
    let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(1)).unwrap();
    let mut e = src.engine(dynbvh::engine::EngineConfig::default());
    let mut flat = dynbvh::geom::TriMesh::default();
    for (t, p) in &s.samples {
        src.set_time(&mut e, *t).unwrap();
        src.flatten_into(&mut flat);
        let want = dynbvh::bvh::brute_force_closest_point(&flat, s.probe, f32::INFINITY).unwrap();
        assert_eq!(p.distance, want.distance, "t = {t}");
    }
    let d: Vec<f32> = s.samples.iter().map(|(_, p)| p.distance).collect();
    assert!(
        d.iter().any(|x| (x - d[0]).abs() > 1e-4),
        "the distance changes over the clip"
    );
}
