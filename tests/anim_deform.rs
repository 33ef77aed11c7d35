//! The posing fast path against the definition, on a hand-built file: morph first (animated
//! weights on two targets), then linear blend skinning over two JOINTS/WEIGHTS sets (u8 and
//! u16 joints), joints with translation, rotation and non-uniform scale, weights that need
//! renormalizing, and vertices whose weights are all zero (they follow the skinned node). One
//! instance is big enough for the parallel path, one is small.

use dynbvh::anim::{InstanceClass, LoadOptions, PARALLEL_VERTICES, Scene};
use glam::{Mat4, Quat, Vec3};
use serde_json::json;
use std::path::Path;

/// Vertices of the big mesh (parallel path); the small mesh uses the first `SMALL`.
const BIG: usize = PARALLEL_VERTICES + 4321;
const SMALL: usize = 777;
const JOINTS: usize = 5;

/// Deterministic pseudo-random numbers in [0, 1).
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// A GLB with `root` as JSON (its one buffer's length filled in) and `bin` as BIN chunk.
fn glb(mut root: serde_json::Value, bin: &[u8]) -> Vec<u8> {
    root["buffers"] = json!([{"byteLength": bin.len()}]);
    let mut js = serde_json::to_vec(&root).unwrap();
    while !js.len().is_multiple_of(4) {
        js.push(b' ');
    }
    let mut b = bin.to_vec();
    while !b.len().is_multiple_of(4) {
        b.push(0);
    }
    let total = 12 + 8 + js.len() + 8 + b.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(js.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&js);
    out.extend_from_slice(&(b.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&b);
    out
}

/// Appends `bytes` to `bin` as a new buffer view (4-byte aligned) and returns its index.
fn view(bin: &mut Vec<u8>, views: &mut Vec<serde_json::Value>, bytes: &[u8]) -> usize {
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    views.push(json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": bytes.len()}));
    bin.extend_from_slice(bytes);
    views.len() - 1
}

fn f32s(v: impl IntoIterator<Item = f32>) -> Vec<u8> {
    v.into_iter().flat_map(f32::to_le_bytes).collect()
}

/// The test file.
fn scene_bytes() -> Vec<u8> {
    let mut rng = Lcg(42);
    let mut bin = Vec::new();
    let mut views = Vec::new();
    let pos = f32s((0..3 * BIG).map(|_| 4.0 * rng.next() - 2.0));
    let t0 = f32s((0..3 * BIG).map(|_| rng.next() - 0.5));
    let t1 = f32s((0..3 * BIG).map(|_| 0.3 * rng.next()));
    let mut j0 = Vec::new();
    let mut j1 = Vec::new();
    let mut w0 = Vec::new();
    let mut w1 = Vec::new();
    for v in 0..BIG {
        for c in 0..4 {
            j0.push((rng.next() * JOINTS as f32) as u8);
            j1.extend_from_slice(&((rng.next() * JOINTS as f32) as u16).to_le_bytes());
            // Every 97th vertex has no weight at all; every 13th has a zero in each set;
            // every 7th sums to about 1.5 (renormalized at load).
            let zero = v % 97 == 0 || (v % 13 == 0 && c == 1);
            let scale = if v % 7 == 0 { 0.375 } else { 0.125 };
            let w = if zero { 0.0 } else { scale * 2.0 * rng.next() };
            w0.extend_from_slice(&w.to_le_bytes());
            let w = if zero { 0.0 } else { scale * 2.0 * rng.next() };
            w1.extend_from_slice(&w.to_le_bytes());
        }
    }
    let ibm = f32s((0..JOINTS).flat_map(|j| {
        let m = Mat4::from_scale_rotation_translation(
            Vec3::new(1.0, 1.0 + 0.1 * j as f32, 1.0),
            Quat::from_rotation_x(0.2 * j as f32),
            Vec3::new(0.0, -(j as f32), 0.3),
        );
        m.to_cols_array()
    }));
    let times = f32s([0.0, 1.0, 2.0]);
    let rot = f32s(
        [0.0f32, 0.7, -0.4]
            .iter()
            .flat_map(|&a| Quat::from_rotation_z(a).to_array()),
    );
    let scale = f32s([1.0, 1.0, 1.0, 1.5, 0.5, 1.0, 0.8, 1.2, 2.0]);
    let trans = f32s([0.0, 0.0, 0.0, 0.5, 0.0, -1.0, 0.0, 2.0, 0.0]);
    let morph = f32s([0.0, 0.0, 1.0, 0.5, -0.5, 2.0]);
    let mut v = |b: &[u8]| view(&mut bin, &mut views, b);
    let (pv, t0v, t1v) = (v(&pos), v(&t0), v(&t1));
    let (j0v, j1v, w0v, w1v) = (v(&j0), v(&j1), v(&w0), v(&w1));
    let (ibmv, tv, rv, sv, trv, mv) =
        (v(&ibm), v(&times), v(&rot), v(&scale), v(&trans), v(&morph));
    let mut accessors = Vec::new();
    let mut acc = |view: usize, comp: u32, count: usize, ty: &str| {
        accessors
            .push(json!({"bufferView": view, "componentType": comp, "count": count, "type": ty}));
        accessors.len() - 1
    };
    let prim = |n: usize, acc: &mut dyn FnMut(usize, u32, usize, &str) -> usize| {
        let p = acc(pv, 5126, n, "VEC3");
        let (a, b) = (acc(t0v, 5126, n, "VEC3"), acc(t1v, 5126, n, "VEC3"));
        json!({
            "attributes": {
                "POSITION": p,
                "JOINTS_0": acc(j0v, 5121, n, "VEC4"),
                "JOINTS_1": acc(j1v, 5123, n, "VEC4"),
                "WEIGHTS_0": acc(w0v, 5126, n, "VEC4"),
                "WEIGHTS_1": acc(w1v, 5126, n, "VEC4"),
            },
            "targets": [{"POSITION": a}, {"POSITION": b}],
        })
    };
    let big = prim(BIG, &mut acc);
    let small = prim(SMALL, &mut acc);
    let ibma = acc(ibmv, 5126, JOINTS, "MAT4");
    let ta = acc(tv, 5126, 3, "SCALAR");
    let ra = acc(rv, 5126, 3, "VEC4");
    let sa = acc(sv, 5126, 3, "VEC3");
    let tra = acc(trv, 5126, 3, "VEC3");
    let ma = acc(mv, 5126, 6, "SCALAR");
    let lin = |o: usize| json!({"input": ta, "output": o, "interpolation": "LINEAR"});
    let root = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0, 5, 6]}],
        "nodes": [
            {"translation": [0.5, 0.0, 0.0], "children": [1]},
            {"translation": [0.0, 1.0, 0.0], "children": [2]},
            {"translation": [0.0, 1.0, 0.0], "children": [3]},
            {"translation": [0.0, 1.0, 0.0], "rotation": Quat::from_rotation_y(0.5).to_array(), "children": [4]},
            {"translation": [0.0, 1.0, 0.0], "scale": [1.0, 2.0, 0.5]},
            {"mesh": 0, "skin": 0, "translation": [9.0, 1.0, 2.0], "scale": [2.0, 2.0, 2.0]},
            {"mesh": 1, "skin": 0, "translation": [-3.0, 0.0, 0.0]},
        ],
        "meshes": [
            {"primitives": [big], "weights": [0.25, 0.0]},
            {"primitives": [small], "weights": [0.0, 1.0]},
        ],
        "skins": [{"joints": [0, 1, 2, 3, 4], "inverseBindMatrices": ibma}],
        "animations": [{
            "channels": [
                {"sampler": 0, "target": {"node": 2, "path": "rotation"}},
                {"sampler": 1, "target": {"node": 4, "path": "scale"}},
                {"sampler": 2, "target": {"node": 0, "path": "translation"}},
                {"sampler": 3, "target": {"node": 5, "path": "weights"}},
                {"sampler": 3, "target": {"node": 6, "path": "weights"}},
            ],
            "samplers": [lin(ra), lin(sa), lin(tra), lin(ma)],
        }],
        "accessors": accessors,
        "bufferViews": views,
    });
    glb(root, &bin)
}

/// Morph then skin vertex by vertex, straight from the definition, in f64.
fn reference(scene: &Scene, world: &[Mat4], inst: usize, morph: &[f32]) -> Vec<Vec3> {
    let i = &scene.instances[inst];
    let mesh = &scene.meshes[i.mesh];
    let skin = &scene.skins[i.skin.unwrap()];
    let attrs = mesh.skin.as_ref().unwrap();
    let k = attrs.influences;
    let dm = |m: Mat4| m.to_cols_array().map(f64::from);
    let apply = |m: &[f64; 16], p: [f64; 3]| -> [f64; 3] {
        std::array::from_fn(|r| m[r] * p[0] + m[4 + r] * p[1] + m[8 + r] * p[2] + m[12 + r])
    };
    let joints: Vec<[f64; 16]> = skin
        .joints
        .iter()
        .zip(&skin.inverse_bind)
        .map(|(&j, b)| dm(world[j] * *b))
        .collect();
    (0..mesh.positions.len())
        .map(|v| {
            let mut p = mesh.positions[v].to_array().map(f64::from);
            for (w, t) in morph.iter().zip(&mesh.targets) {
                for c in 0..3 {
                    p[c] += f64::from(*w) * f64::from(t[v][c]);
                }
            }
            let ws = &attrs.weights[v * k..v * k + k];
            let js = &attrs.joints[v * k..v * k + k];
            let out = if ws.iter().all(|&w| w == 0.0) {
                apply(&dm(world[i.node]), p)
            } else {
                let mut acc = [0.0; 3];
                for (&j, &w) in js.iter().zip(ws) {
                    let q = apply(&joints[usize::from(j)], p);
                    for c in 0..3 {
                        acc[c] += f64::from(w) * q[c];
                    }
                }
                acc
            };
            Vec3::from_array(out.map(|x| x as f32))
        })
        .collect()
}

#[test]
fn posing_matches_morph_then_blend_skinning_by_definition() {
    let bytes = scene_bytes();
    let (scene, warnings) =
        Scene::from_slice(Path::new("deform.glb"), &bytes, &LoadOptions::default()).unwrap();
    // One warning for renormalized weights, one for all-zero weights (not renormalized,
    // counted apart: the vertices the loaded skin still has with all weights zero).
    assert_eq!(warnings.len(), 2, "{warnings:?}");
    assert!(warnings[0].0.contains("renormalized"), "{warnings:?}");
    let zero = |m: usize| {
        let a = scene.meshes[m].skin.as_ref().unwrap();
        a.weights
            .chunks_exact(a.influences)
            .filter(|w| w.iter().all(|&w| w == 0.0))
            .count()
    };
    assert!(zero(0) > 0 && zero(1) > 0);
    let w = &warnings[1].0;
    assert!(
        w.contains("all zero are not skinned")
            && w.contains(&format!("mesh 0 ({} vertices)", zero(0)))
            && w.contains(&format!("mesh 1 ({} vertices)", zero(1))),
        "{w}"
    );
    assert_eq!(scene.instances.len(), 2);
    assert_eq!(scene.meshes[0].positions.len(), BIG);
    assert_eq!(scene.meshes[1].positions.len(), SMALL);
    assert_eq!(scene.meshes[0].skin.as_ref().unwrap().influences, 8);
    let mut poser = scene.poser(Some(0)).unwrap();
    assert_eq!(poser.classes(), &[InstanceClass::Deforming; 2]);
    for t in [0.0, 0.4, 1.0, 1.7, 2.0, 2.9] {
        poser.pose(t);
        for inst in 0..2 {
            let want = reference(
                &scene,
                poser.world_matrices(),
                inst,
                poser.morph_weights(inst),
            );
            let got = poser.positions(inst);
            assert_eq!(got.len(), want.len());
            for (v, (a, b)) in got.iter().zip(&want).enumerate() {
                let tol = 2e-5 * b.abs().max_element().max(1.0);
                assert!(
                    (*a - *b).abs().max_element() <= tol,
                    "t={t} instance {inst} vertex {v}: posed {a}, by definition {b}"
                );
            }
        }
    }
}
