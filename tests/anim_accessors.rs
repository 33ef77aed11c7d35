//! Accessor corner cases: sparse substitution (with and without a base buffer view),
//! strips and fans, non-indexed primitives, data URIs, and the parallel deform path.

mod anim_util;

use dynbvh::anim::generate::{Kind, generate};
use dynbvh::anim::{LoadOptions, PARALLEL_VERTICES, Scene};
use dynbvh::geom::TriMesh;
use glam::Vec3;
use serde_json::json;
use std::path::Path;

#[test]
fn sparse_positions_replace_base_values() {
    let Some(p) = anim_util::sample("SimpleSparseAccessor/SimpleSparseAccessor.gltf") else {
        return;
    };
    let (scene, _) = Scene::load(&p).unwrap();
    let pos = &scene.meshes[0].positions;
    // Base: a 7 x 2 grid (x = i % 7, y = i / 7); sparse indices 8, 10, 12 get
    // (1, 2, 0), (3, 3, 0), (5, 4, 0).
    for (i, p) in pos.iter().enumerate() {
        let want = match i {
            8 => Vec3::new(1.0, 2.0, 0.0),
            10 => Vec3::new(3.0, 3.0, 0.0),
            12 => Vec3::new(5.0, 4.0, 0.0),
            _ => Vec3::new((i % 7) as f32, (i / 7) as f32, 0.0),
        };
        assert_eq!(*p, want, "vertex {i}");
    }
}

/// A one-buffer glTF with a base64 data URI holding `bin`.
fn doc(bin: &[u8], mut root: serde_json::Value) -> Vec<u8> {
    let s = anim_util::base64(bin);
    root["asset"] = json!({"version": "2.0"});
    root["buffers"] = json!([{"byteLength": bin.len(), "uri": format!("data:application/gltf-buffer;base64,{s}")}]);
    serde_json::to_vec(&root).unwrap()
}

fn load(bytes: &[u8]) -> dynbvh::Result<Scene> {
    Scene::from_slice(Path::new("inline.gltf"), bytes, &LoadOptions::default()).map(|(s, _)| s)
}

#[test]
fn sparse_without_buffer_view_starts_from_zeros() {
    // Sparse indices u8 [1, 2] at 0; values two VEC3 at 4.
    let mut bin = vec![1u8, 2, 0, 0];
    for v in [1.0f32, 0.0, 0.0, 0.0, 1.0, 0.0] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    let root = json!({
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 2},
            {"buffer": 0, "byteOffset": 4, "byteLength": 24}
        ],
        "accessors": [{"componentType": 5126, "count": 3, "type": "VEC3",
            "sparse": {"count": 2, "indices": {"bufferView": 0, "componentType": 5121},
                       "values": {"bufferView": 1}}}]
    });
    let scene = load(&doc(&bin, root)).unwrap();
    assert_eq!(
        scene.meshes[0].positions,
        vec![Vec3::ZERO, Vec3::X, Vec3::Y]
    );
    assert_eq!(scene.triangle_count(), 1, "non-indexed triangle");
}

#[test]
fn strips_and_fans_keep_front_faces() {
    // A quad as strip 0 1 2 3 and as fan 0 1 2 3: both must face +z like the triangle list.
    let mut bin = Vec::new();
    for v in [
        0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0,
    ] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    // Fan order around the quad: 0 (0,0) 1 (1,0) 3 (1,1) 2 (0,1).
    bin.extend_from_slice(&[0u8, 1, 3, 2]);
    let root = json!({
        "scenes": [{"nodes": [0, 1]}],
        "nodes": [{"mesh": 0}, {"mesh": 1}],
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": 0}, "mode": 5}]},
            {"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "mode": 6}]}
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48},
            {"buffer": 0, "byteOffset": 48, "byteLength": 4}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"},
            {"bufferView": 1, "componentType": 5121, "count": 4, "type": "SCALAR"}
        ]
    });
    let scene = load(&doc(&bin, root)).unwrap();
    let m = scene.flatten_rest();
    assert_eq!(m.len(), 4);
    for i in 0..m.len() {
        let [a, b, c] = m.triangle(i);
        assert!((b - a).cross(c - a).z > 0.0, "triangle {i} faces -z");
    }
}

#[test]
fn index_out_of_vertex_range_is_malformed() {
    let mut bin = Vec::new();
    for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    bin.extend_from_slice(&[0u8, 1, 7, 0]);
    let root = json!({
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 3}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"},
            {"bufferView": 1, "componentType": 5121, "count": 3, "type": "SCALAR"}
        ]
    });
    let e = load(&doc(&bin, root)).unwrap_err().to_string();
    assert!(
        e.contains("inline.gltf")
            && e.contains("mesh 0 primitive 0 accessor 1 (indices)")
            && e.contains("below the vertex count 3"),
        "{e}"
    );
}

#[test]
fn big_deforming_meshes_pose_in_parallel_like_the_analytic_pose() {
    let g = generate(Kind::Tube, 80_000, 1);
    let (scene, _) =
        Scene::from_slice(Path::new("tube.glb"), &g.glb, &LoadOptions::default()).unwrap();
    assert!(scene.meshes[0].positions.len() > PARALLEL_VERTICES);
    let mut poser = scene.poser(Some(0)).unwrap();
    let mut flat = TriMesh::default();
    for (t, want) in &g.checks {
        poser.pose(*t);
        poser.flatten_into(&mut flat);
        assert_eq!(flat.positions.len(), want.len(), "t={t}");
        for (a, b) in flat.positions.iter().zip(want) {
            assert!((*a - *b).abs().max_element() < 1e-4, "t={t}: {a} vs {b}");
        }
    }
}
