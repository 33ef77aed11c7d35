//! Skinning: SimpleSkin and RiggedSimple against positions computed by hand from the file's
//! keys, and bind pose equal to the unskinned mesh.

mod anim_util;

use anim_util::{Raw, assert_near};
use dynbvh::anim::{InstanceClass, Scene, TimeMode};
use glam::{Mat4, Quat, Vec3};

/// Rotates `p` about z by `angle` around `pivot`.
fn rot_z_about(p: Vec3, angle: f32, pivot: Vec3) -> Vec3 {
    let d = p - pivot;
    let (s, c) = angle.sin_cos();
    pivot + Vec3::new(c * d.x - s * d.y, s * d.x + c * d.y, d.z)
}

#[test]
fn simple_skin_by_hand() {
    let Some(path) = anim_util::sample("SimpleSkin/SimpleSkin.gltf") else {
        return;
    };
    let (scene, _) = Scene::load(&path).unwrap();
    let rest = scene.meshes[0].positions.clone();
    // Joint 0 = node 1 (identity); joint 1 = node 2 at (0, 1, 0) with an animated z rotation;
    // its inverse bind matrix undoes the (0, 1, 0) offset, so joint 1 rotates about (0, 1, 0).
    // Weights of vertex pair k (k = 0..5) on joint 1: 0, 0.25, 0.5, 0.75, 1.
    let w1 = [0.0, 0.25, 0.5, 0.75, 1.0];
    let mut poser = scene.poser(Some(0)).unwrap();
    assert_eq!(poser.classes(), &[InstanceClass::Deforming]);
    // Key 2 at t = 1 is (0, 0, 0.707, 0.707): 90 degrees. Key 1 at t = 0.5: (0, 0, 0.383, 0.924).
    let a1 = 2.0 * 0.383f32.atan2(0.924);
    for (t, angle) in [
        (1.0f32, 90f32.to_radians()),
        (0.5, a1),
        (0.25, a1 / 2.0),
        (0.0, 0.0),
    ] {
        poser.pose(t);
        let got = poser.positions(0);
        for (v, &p) in rest.iter().enumerate() {
            let w = w1[v / 2];
            let want = (1.0 - w) * p + w * rot_z_about(p, angle, Vec3::Y);
            assert_near(got[v], want, 1e-5, &format!("t={t} vertex {v}"));
        }
    }
    // The values the brief's reader can check by eye: at t = 1, vertex 8 (-0.5, 2) -> (-1, 0.5).
    poser.pose(1.0);
    assert_near(poser.positions(0)[8], Vec3::new(-1.0, 0.5, 0.0), 1e-5, "v8");
    assert_near(
        poser.positions(0)[4],
        Vec3::new(-0.25, 0.75, 0.0),
        1e-5,
        "v4",
    );
}

#[test]
fn bind_pose_equals_unskinned() {
    let Some(path) = anim_util::sample("SimpleSkin/SimpleSkin.gltf") else {
        return;
    };
    let (scene, _) = Scene::load(&path).unwrap();
    let flat = scene.flatten_rest();
    assert_eq!(flat.positions.len(), scene.meshes[0].positions.len());
    for (a, b) in flat.positions.iter().zip(&scene.meshes[0].positions) {
        assert_near(*a, *b, 1e-6, "bind pose");
    }
}

/// Local matrix from the file's node JSON (matrix or TRS).
fn node_matrix(n: &serde_json::Value) -> Mat4 {
    let f = |k: &str| -> Option<Vec<f32>> {
        n[k].as_array()
            .map(|a| a.iter().map(|x| x.as_f64().unwrap() as f32).collect())
    };
    if let Some(m) = f("matrix") {
        return Mat4::from_cols_slice(&m);
    }
    let t = f("translation").map_or(Vec3::ZERO, |v| Vec3::from_slice(&v));
    let r = f("rotation").map_or(Quat::IDENTITY, |v| Quat::from_slice(&v));
    let s = f("scale").map_or(Vec3::ONE, |v| Vec3::from_slice(&v));
    Mat4::from_translation(t) * Mat4::from_quat(r) * Mat4::from_scale(s)
}

#[test]
fn rigged_simple_by_hand() {
    let Some(path) = anim_util::sample("RiggedSimple/RiggedSimple.glb") else {
        return;
    };
    let raw = Raw::open(&path);
    let (scene, _) = Scene::load(&path).unwrap();
    let j = &raw.json;
    let nodes = j["nodes"].as_array().unwrap();
    // Hierarchy: 0 (Z_UP) -> 1 (Armature) -> {3 (Bone) -> 4 (Bone.001), 2 (Cylinder, skinned)}.
    let parent_of_bones = node_matrix(&nodes[0]) * node_matrix(&nodes[1]);
    let bone = parent_of_bones * node_matrix(&nodes[3]);
    let ibm: Vec<Mat4> = raw
        .accessor(j["skins"][0]["inverseBindMatrices"].as_u64().unwrap() as usize)
        .iter()
        .map(|r| Mat4::from_cols_slice(&r.iter().map(|&x| x as f32).collect::<Vec<_>>()))
        .collect();
    let attrs = &j["meshes"][0]["primitives"][0]["attributes"];
    let acc = |k: &str| raw.accessor(attrs[k].as_u64().unwrap() as usize);
    let (pos, joints, weights) = (acc("POSITION"), acc("JOINTS_0"), acc("WEIGHTS_0"));
    // Channels T, R, S on node 4, all LINEAR, sharing key times.
    let anim = &j["animations"][0];
    let sampler = |path: &str| {
        let ch = anim["channels"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["target"]["path"] == path)
            .unwrap();
        let s = &anim["samplers"][ch["sampler"].as_u64().unwrap() as usize];
        (
            raw.accessor(s["input"].as_u64().unwrap() as usize),
            raw.accessor(s["output"].as_u64().unwrap() as usize),
        )
    };
    let (times, tv) = sampler("translation");
    let (_, rv) = sampler("rotation");
    let (_, sv) = sampler("scale");
    let v3 = |r: &Vec<f64>| Vec3::new(r[0] as f32, r[1] as f32, r[2] as f32);
    let q = |r: &Vec<f64>| Quat::from_xyzw(r[0] as f32, r[1] as f32, r[2] as f32, r[3] as f32);
    assert!(times[0][0] > 0.04, "keys start after 0");
    let mut poser = scene
        .poser(Some(0))
        .unwrap()
        .with_time_mode(TimeMode::Clamp);
    let inst = 0;
    assert_eq!(scene.instances[inst].node, 2);
    // At exact keys (and before the first one) LINEAR gives the key's value.
    for (t, k) in [
        (0.0f32, 0usize),
        (times[10][0] as f32, 10),
        (times[30][0] as f32, 30),
    ] {
        let local =
            Mat4::from_scale_rotation_translation(v3(&sv[k]), q(&rv[k]).normalize(), v3(&tv[k]));
        let jm = [bone * ibm[0], bone * local * ibm[1]];
        poser.pose(t);
        let got = poser.positions(inst);
        assert_eq!(got.len(), pos.len());
        for (v, p) in pos.iter().enumerate() {
            let p = v3(p);
            let mut want = Vec3::ZERO;
            for c in 0..4 {
                let w = weights[v][c] as f32;
                if w > 0.0 {
                    want += w * jm[joints[v][c] as usize].transform_point3(p);
                }
            }
            assert_near(got[v], want, 1e-4, &format!("t={t} vertex {v}"));
        }
    }
    // The mesh runs along z; Z_UP (applied once, through the joints) stands it along y. Were
    // the skinned node's parents applied again it would lie along -z.
    let m = scene.flatten_at(Some(0), 0.0).unwrap();
    let b = m.bounds();
    assert!(
        b.max.y - b.min.y > 8.0,
        "the cylinder stands along y: {b:?}"
    );
}

#[test]
fn posing_twice_reuses_buffers() {
    let Some(path) = anim_util::sample("CesiumMan/CesiumMan.glb") else {
        return;
    };
    let (scene, _) = Scene::load(&path).unwrap();
    let mut poser = scene.poser(Some(0)).unwrap();
    poser.pose(0.3);
    let ptr = poser.positions(0).as_ptr();
    let before = poser.positions(0).to_vec();
    poser.pose(1.1);
    assert_eq!(ptr, poser.positions(0).as_ptr());
    assert_ne!(before, poser.positions(0));
    poser.pose(0.3);
    assert_eq!(before, poser.positions(0));
}
