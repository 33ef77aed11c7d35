//! Skin weights the loader repairs or refuses: weights not summing to 1 are renormalized (one
//! warning), vertices whose weights are all zero are counted apart (they are not renormalized
//! but left to the mesh node's transform), and a joint index of 65536 or more, which no skin
//! can have, is an error naming the mesh. Hand-made `.gltf` files with one data URI.

mod anim_util;

use dynbvh::anim::{LoadOptions, Scene};
use glam::Vec3;
use serde_json::json;
use std::path::Path;

/// One skinned triangle: joints given as u32 (`JOINTS_0` of componentType 5125, which the
/// loader reads although the spec allows only u8 and u16), weights as floats; nodes 0 and 1
/// are the skin's two joints, node 2 (translated by (5, 0, 0)) places the mesh.
fn skinned_triangle(joints: [[u32; 4]; 3], weights: [[f32; 4]; 3]) -> Vec<u8> {
    let pos: [f32; 9] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let mut bin: Vec<u8> = pos.iter().flat_map(|x| x.to_le_bytes()).collect();
    bin.extend(joints.iter().flatten().flat_map(|j| j.to_le_bytes()));
    bin.extend(weights.iter().flatten().flat_map(|w| w.to_le_bytes()));
    let d = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0, 2]}],
        "nodes": [
            {"children": [1]},
            {"translation": [0.0, 2.0, 0.0]},
            {"mesh": 0, "skin": 0, "translation": [5.0, 0.0, 0.0]},
        ],
        "skins": [{"joints": [0, 1]}],
        "meshes": [{"name": "tri", "primitives": [{"attributes": {"POSITION": 0, "JOINTS_0": 1, "WEIGHTS_0": 2}}]}],
        "buffers": [{"byteLength": bin.len(), "uri": anim_util::data_uri(&bin)}],
        "bufferViews": [
            {"buffer": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 48},
            {"buffer": 0, "byteOffset": 84, "byteLength": 48},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"},
            {"bufferView": 1, "componentType": 5125, "count": 3, "type": "VEC4"},
            {"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC4"},
        ],
    });
    serde_json::to_vec(&d).unwrap()
}

fn load(bytes: &[u8]) -> dynbvh::Result<(Scene, Vec<dynbvh::anim::Warning>)> {
    Scene::from_slice(Path::new("skin.gltf"), bytes, &LoadOptions::default())
}

#[test]
fn renormalized_and_all_zero_weights_are_told_apart() {
    let bytes = skinned_triangle(
        [[0, 0, 0, 0], [1, 0, 0, 0], [0, 1, 0, 0]],
        // Vertex 0: sums to 2 (renormalized); vertex 1: all zero; vertex 2: sums to 1.
        [
            [2.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, 0.0],
            [0.5, 0.5, 0.0, 0.0],
        ],
    );
    let (scene, warnings) = load(&bytes).unwrap();
    assert_eq!(warnings.len(), 2, "{warnings:?}");
    assert!(
        warnings[0]
            .0
            .contains("renormalized in mesh 0 (1 vertices)"),
        "{warnings:?}"
    );
    assert!(
        warnings[1].0.contains("all zero are not skinned")
            && warnings[1].0.contains("mesh 0 (1 vertices)"),
        "{warnings:?}"
    );
    // Posed at rest: vertex 0 follows joint 0 (identity), vertex 2 half joint 1 (+2 in y),
    // vertex 1 (no weights) the mesh node's own transform (+5 in x).
    let flat = scene.flatten_rest();
    let want = [
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(6.0, 0.0, 0.0),
        Vec3::new(0.0, 2.0, 0.0),
    ];
    for (p, w) in flat.positions.iter().zip(want) {
        assert!((*p - w).abs().max_element() < 1e-6, "{p} vs {w}");
    }
}

#[test]
fn joint_indices_beyond_u16_are_an_error_naming_the_mesh() {
    let bytes = skinned_triangle(
        [[0, 0, 0, 0], [70_000, 0, 0, 0], [1, 0, 0, 0]],
        [[1.0, 0.0, 0.0, 0.0]; 3],
    );
    let e = load(&bytes).unwrap_err().to_string();
    assert!(
        e.contains("skin.gltf")
            && e.contains("mesh 0 primitive 0 JOINTS_0")
            && e.contains("below 65536")
            && e.contains("found 70000")
            && e.contains("vertex 1"),
        "{e}"
    );
    // With zero weight the index never matters: no error.
    let bytes = skinned_triangle(
        [[0, 70_000, 0, 0], [1, 0, 0, 0], [1, 0, 0, 0]],
        [[1.0, 0.0, 0.0, 0.0]; 3],
    );
    let (_, warnings) = load(&bytes).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
}
