//! Every sample file loads with the README's triangle count, and poses without trouble.

mod anim_util;

use dynbvh::anim::{InstanceClass, Scene};

#[test]
fn every_sample_loads_with_readme_triangle_counts() {
    let Some(dir) = anim_util::samples() else {
        return;
    };
    for &(rel, tris) in anim_util::SAMPLES {
        let path = dir.join(rel);
        let (scene, warnings) = Scene::load(&path).unwrap_or_else(|e| panic!("{rel}: {e}"));
        for w in &warnings {
            eprintln!("{rel}: warning: {w}");
        }
        assert_eq!(scene.triangle_count(), tris, "{rel}");
        let flat = scene.flatten_rest();
        assert_eq!(flat.len(), tris, "{rel}");
        flat.check().unwrap();
        assert!(flat.positions.iter().all(|p| p.is_finite()), "{rel}");
        for a in 0..scene.animations.len() {
            let mut p = scene.poser(Some(a)).unwrap();
            let d = scene.animations[a].duration;
            for t in [0.0, d * 0.37, d, d * 1.5] {
                p.pose(t);
                for i in 0..scene.instances.len() {
                    assert!(
                        p.positions(i).iter().all(|v| v.is_finite()),
                        "{rel} anim {a} t {t}"
                    );
                }
            }
        }
    }
}

#[test]
fn classes_of_samples() {
    let Some(dir) = anim_util::samples() else {
        return;
    };
    let class = |rel: &str, anim: usize| {
        let (s, _) = Scene::load(dir.join(rel)).unwrap();
        s.classify(Some(anim)).unwrap()
    };
    use InstanceClass::*;
    assert_eq!(class("AnimatedCube/AnimatedCube.gltf", 0), vec![Rigid]);
    assert_eq!(class("SimpleSkin/SimpleSkin.gltf", 0), vec![Deforming]);
    assert_eq!(class("SimpleMorph/SimpleMorph.gltf", 0), vec![Deforming]);
    assert!(class("BoxAnimated/BoxAnimated.glb", 0).contains(&Rigid));
    assert!(class("Fox/Fox.glb", 2).iter().all(|&c| c == Deforming));
    let (s, _) = Scene::load(dir.join("Fox/Fox.glb")).unwrap();
    assert!(s.classify(None).unwrap().iter().all(|&c| c == Static));
}

/// MeshPrimitiveModes has points, line, line-loop and line-strip primitives besides its
/// triangles: exactly one warning says they were skipped, naming the meshes.
#[test]
fn points_and_lines_give_exactly_one_warning() {
    let Some(path) = anim_util::sample("MeshPrimitiveModes/MeshPrimitiveModes.gltf") else {
        return;
    };
    let (scene, warnings) = Scene::load(&path).unwrap();
    assert_eq!(scene.triangle_count(), 16);
    let modes: Vec<_> = warnings
        .iter()
        .filter(|w| w.0.contains("points and lines"))
        .collect();
    assert_eq!(modes.len(), 1, "{warnings:?}");
    assert!(
        modes[0].0.contains("MeshPrimitiveModes.gltf"),
        "{}",
        modes[0]
    );
    assert!(modes[0].0.contains("mesh 0"), "{}", modes[0]);
    assert_eq!(warnings.len(), 1, "{warnings:?}");
}
