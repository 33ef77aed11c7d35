//! Clip-aware rebuilds (`GltfSource::with_clip_rebuilds`, `Engine::set_clip_ahead`): every
//! rebuild of a deforming mesh is built for the pose it is made at and the clip's sampled poses
//! after it. The oracle's tree built at frame `b` is the engine built at `b` by the source, so
//! a policy's rebuild at `b` must be that very tree, priced the same: checked bit for bit on
//! every frame of the shipped clips, with the trees valid and exact against brute force.

mod common;

use dynbvh::anim::Scene;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::source::FrameSource;
use dynbvh::engine::{EngineConfig, MeshId, Policy, Prices, Timing};
use dynbvh::geom::TriMesh;
use glam::Vec3;
use std::path::PathBuf;

/// Frames of each clip, and the poses sampled over them (frames 0, 4, 8, 12).
const FRAMES: usize = 12;
const POSES: usize = 4;

fn config() -> EngineConfig {
    EngineConfig {
        policy: Policy::Rebuild,
        timing: Timing::Priced,
        prices: Prices::default(),
        ..EngineConfig::default()
    }
}

fn mesh_of(e: &dynbvh::engine::Engine, m: MeshId) -> TriMesh {
    TriMesh {
        positions: e.positions(m).to_vec(),
        indices: e.indices(m).to_vec(),
    }
}

#[test]
fn each_rebuild_is_the_clip_aware_tree_the_source_builds_at_that_frame() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("animations");
    for file in ["explode.glb", "tube.glb", "swap.glb"] {
        let (scene, _) = Scene::load(dir.join(file)).unwrap();
        let source = || {
            GltfSource::new(&scene, Some(0), FrameTimes::Count(FRAMES))
                .unwrap()
                .with_clip_aware(POSES)
                .with_clip_rebuilds(true)
        };
        let mut src = source();
        let mut e = src.build(0, config());
        let deforming = src.deforming().to_vec();
        assert!(!deforming.is_empty(), "{file}: nothing deforms");
        for &m in &deforming {
            assert_eq!(e.mesh_build_poses(m), POSES, "{file}: first tree");
        }
        let mut at = source();
        for f in 1..=FRAMES {
            src.advance(&mut e, f);
            let s = e.update();
            assert_eq!(s.rebuilds as usize, deforming.len(), "{file} frame {f}");
            // The source's engine built at `f` stands for a rebuild there in the oracle.
            let b = at.build(f, config());
            // Poses sampled after `f`, and `f`'s own: none once the last is behind.
            let ahead = [4, 8, 12].iter().filter(|&&s| s > f).count();
            let want = if ahead == 0 { 0 } else { 1 + ahead };
            for &m in &deforming {
                let what = format!("{file} frame {f} mesh {m:?}");
                assert_eq!(e.mesh_build_poses(m), want, "{what}");
                assert_eq!(b.mesh_build_poses(m), want, "{what}: built at f");
                assert_eq!(
                    e.mesh_bvh(m).bvh().nodes(),
                    b.mesh_bvh(m).bvh().nodes(),
                    "{what}: the rebuild is not the tree built at f"
                );
                let tris = e.indices(m).len();
                let price = Prices::default().clip_rebuild_ms(tris, want);
                assert_eq!(e.mesh_stats(m).model_ms, price, "{what}: priced");
                if want > 0 {
                    assert!(price > Prices::default().rebuild_ms(tris), "{what}");
                }
                common::check_tree(&mesh_of(&e, m), e.mesh_bvh(m), &what);
            }
        }
    }
}

#[test]
fn without_clip_rebuilds_only_the_first_tree_is_clip_aware() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("animations");
    let (scene, _) = Scene::load(dir.join("explode.glb")).unwrap();
    let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(FRAMES))
        .unwrap()
        .with_clip_aware(POSES);
    let mut e = src.build(0, config());
    let m = src.deforming()[0];
    assert_eq!(e.mesh_build_poses(m), POSES);
    src.advance(&mut e, 1);
    e.update();
    assert_eq!(e.mesh_build_poses(m), 0, "a plain rebuild");
    assert_eq!(
        e.mesh_stats(m).model_ms,
        Prices::default().rebuild_ms(e.indices(m).len())
    );
    // Engines built at later frames (the oracle's rebuilds) are plain too.
    assert_eq!(src.build(3, config()).mesh_build_poses(m), 0);
}

#[test]
fn set_clip_ahead_checks_its_poses_and_an_empty_clip_makes_rebuilds_plain() {
    let mut e = dynbvh::engine::Engine::new(config());
    let quad = vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y];
    let m = e.add_mesh(quad.clone(), vec![[0, 1, 2], [0, 2, 3]]);
    e.add_instance(m, glam::Affine3A::IDENTITY);
    e.update();
    let err = e
        .set_clip_ahead(m, vec![(1, quad[..3].to_vec())])
        .unwrap_err()
        .to_string();
    assert!(err.contains("3 vertices") && err.contains("4"), "{err}");
    let err = e.set_clip_ahead(m, vec![(0, quad.clone())]).unwrap_err();
    assert!(err.to_string().contains("from 1"), "{err}");
    assert!(e.set_clip_ahead(MeshId(7), Vec::new()).is_err());
    // A pose two updates ahead: the next rebuild is for two poses, the one after is plain.
    let far: Vec<Vec3> = quad.iter().map(|p| *p * 3.0).collect();
    e.set_clip_ahead(m, vec![(2, far)]).unwrap();
    e.set_positions(m, &quad);
    e.update();
    assert_eq!(e.mesh_build_poses(m), 2);
    e.set_positions(m, &quad);
    e.update();
    assert_eq!(e.mesh_build_poses(m), 0);
    e.set_clip_ahead(m, Vec::new()).unwrap();
    e.set_positions(m, &quad);
    e.update();
    assert_eq!(e.mesh_build_poses(m), 0);
}
