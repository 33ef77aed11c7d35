//! Morphing: SimpleMorph and AnimatedMorphCube against positions computed by hand, and the
//! KHR_mesh_quantization copy of AnimatedMorphCube posing like the float one.

mod anim_util;

use anim_util::{Raw, assert_near};
use dynbvh::anim::{InstanceClass, Scene};
use glam::{Mat4, Quat, Vec3};

#[test]
fn simple_morph_by_hand() {
    let Some(path) = anim_util::sample("SimpleMorph/SimpleMorph.gltf") else {
        return;
    };
    let (scene, _) = Scene::load(&path).unwrap();
    // Base (0,0,0) (1,0,0) (0.5,0.5,0); target deltas only on vertex 2: (-1,1,0) and (1,1,0).
    // Mesh default weights (0.5, 0.5); keys at t = 0..4: (0,0) (0,1) (1,1) (1,0) (0,0).
    let v2 = |w0: f32, w1: f32| {
        Vec3::new(0.5, 0.5, 0.0) + w0 * Vec3::new(-1.0, 1.0, 0.0) + w1 * Vec3::new(1.0, 1.0, 0.0)
    };
    let rest = scene.flatten_rest();
    assert_near(rest.positions[2], v2(0.5, 0.5), 1e-6, "default weights");
    assert_eq!(scene.classify(None).unwrap(), vec![InstanceClass::Static]);
    let mut p = scene.poser(Some(0)).unwrap();
    assert_eq!(p.classes(), &[InstanceClass::Deforming]);
    for (t, w0, w1) in [
        (0.0, 0.0, 0.0),
        (1.5, 0.5, 1.0),
        (2.25, 1.0, 0.75),
        (3.0, 1.0, 0.0),
        (4.0, 0.0, 0.0),
    ] {
        p.pose(t);
        assert_eq!(p.morph_weights(0), &[w0, w1], "t={t}");
        assert_near(p.positions(0)[2], v2(w0, w1), 1e-6, &format!("t={t}"));
        assert_near(p.positions(0)[1], Vec3::X, 0.0, "vertex 1 has no deltas");
    }
}

/// AnimatedMorphCube by hand: one node with rotation and scale, LINEAR weight keys.
#[test]
fn animated_morph_cube_by_hand() {
    let Some(path) = anim_util::sample("AnimatedMorphCube/AnimatedMorphCube.glb") else {
        return;
    };
    let raw = Raw::open(&path);
    let (scene, _) = Scene::load(&path).unwrap();
    let j = &raw.json;
    let prim = &j["meshes"][0]["primitives"][0];
    let acc = |v: &serde_json::Value| raw.accessor(v.as_u64().unwrap() as usize);
    let pos = acc(&prim["attributes"]["POSITION"]);
    let d0 = acc(&prim["targets"][0]["POSITION"]);
    let d1 = acc(&prim["targets"][1]["POSITION"]);
    let s = &j["animations"][0]["samplers"][0];
    let times = acc(&s["input"]);
    let w = acc(&s["output"]);
    assert_eq!(
        j["nodes"][0]["scale"],
        serde_json::json!([100.0, 100.0, 100.0])
    );
    let node = Mat4::from_scale_rotation_translation(
        Vec3::splat(100.0),
        Quat::from_slice(
            &j["nodes"][0]["rotation"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap() as f32)
                .collect::<Vec<_>>(),
        )
        .normalize(),
        Vec3::ZERO,
    );
    let mut p = scene.poser(Some(0)).unwrap();
    for k in [0usize, 20, 45, 90] {
        // Midway between keys k and k + 1.
        let (t0, t1) = (times[k][0], times[k + 1][0]);
        let t = ((t0 + t1) / 2.0) as f32;
        let wk = |i: usize| ((w[2 * k + i][0] + w[2 * k + 2 + i][0]) / 2.0) as f32;
        let (w0, w1) = (wk(0), wk(1));
        p.pose(t);
        for v in 0..pos.len() {
            let f = |r: &Vec<f64>| Vec3::new(r[0] as f32, r[1] as f32, r[2] as f32);
            let local = f(&pos[v]) + w0 * f(&d0[v]) + w1 * f(&d1[v]);
            let want = node.transform_point3(local);
            assert_near(
                p.positions(0)[v],
                want,
                1e-4,
                &format!("key {k} vertex {v}"),
            );
        }
    }
}

#[test]
fn quantized_morph_cube_matches_float() {
    let (Some(fp), Some(qp)) = (
        anim_util::sample("AnimatedMorphCube/AnimatedMorphCube.glb"),
        anim_util::sample("AnimatedMorphCube/glTF-Quantized/AnimatedMorphCube.gltf"),
    ) else {
        return;
    };
    let (fs, _) = Scene::load(&fp).unwrap();
    let (qs, _) = Scene::load(&qp).unwrap();
    assert!((fs.animations[0].duration - qs.animations[0].duration).abs() < 1e-4);
    let (mut pf, mut pq) = (fs.poser(Some(0)).unwrap(), qs.poser(Some(0)).unwrap());
    let mut moved = 0.0f32;
    let first = fs.flatten_at(Some(0), 0.0).unwrap();
    for t in [0.0, 0.5, 1.1, 1.9, 2.6, 3.3, 4.0, 4.2] {
        pf.pose(t);
        pq.pose(t);
        let mut a = Default::default();
        let mut b = Default::default();
        pf.flatten_into(&mut a);
        pq.flatten_into(&mut b);
        let a: &dynbvh::geom::TriMesh = &a;
        let b: &dynbvh::geom::TriMesh = &b;
        assert_eq!(a.len(), b.len());
        // Same triangles in the same order: compare corner by corner. Quantization: positions
        // step 3.6e-4, weights step 1/255 of deltas up to ~2 units in world space.
        for i in 0..a.len() {
            for (x, y) in a.triangle(i).iter().zip(b.triangle(i)) {
                assert_near(*x, y, 0.01, &format!("t={t} triangle {i}"));
            }
        }
        for (x, y) in a.positions.iter().zip(&first.positions) {
            moved = moved.max((*x - *y).length());
        }
    }
    assert!(moved > 0.5, "the cube must actually morph ({moved})");
}
