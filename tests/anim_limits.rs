//! Tiny malformed files that ask for huge decoded data are refused with an error naming the
//! file and the mesh or accessor, before the memory is allocated: one accessor without a
//! buffer view (zeros, up to 16M components) read by many primitives, morph targets or skins.

use dynbvh::anim::{LoadOptions, Scene};
use serde_json::{Value, json};
use std::path::Path;

fn load(d: &Value, opts: &LoadOptions) -> dynbvh::Result<Scene> {
    let bytes = serde_json::to_vec(d).unwrap();
    Scene::from_slice(Path::new("huge.gltf"), &bytes, opts).map(|(s, _)| s)
}

/// A mesh of `prims` primitives whose POSITION and `targets` morph targets all read accessor
/// 0: `count` VEC3 zeros, no buffer view.
fn many_reads(prims: usize, targets: usize, count: u64) -> Value {
    let prim = json!({
        "attributes": {"POSITION": 0},
        "targets": vec![json!({"POSITION": 0}); targets],
    });
    json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"name": "blob", "primitives": vec![prim; prims]}],
        "accessors": [{"componentType": 5126, "count": count, "type": "VEC3"}],
    })
}

#[test]
fn a_mesh_asking_for_terabytes_is_refused_before_decoding() {
    // 64 primitives × (1 + 100 targets) × 5M vertices × 12 bytes: about 390 GB from 90 KB.
    let d = many_reads(64, 100, 5_000_000);
    assert!(serde_json::to_vec(&d).unwrap().len() < 100_000);
    let e = load(&d, &LoadOptions::default()).unwrap_err().to_string();
    assert!(
        e.contains("huge.gltf")
            && e.contains("mesh 0")
            && e.contains("bytes of decoded data")
            && e.contains("100 morph targets"),
        "{e}"
    );
}

#[test]
fn vertex_count_is_checked_before_decoding() {
    // 1000 primitives of 5M vertices: 5 billion, beyond u32 indices.
    let d = many_reads(1000, 0, 5_000_000);
    let e = load(&d, &LoadOptions::default()).unwrap_err().to_string();
    assert!(
        e.contains("huge.gltf") && e.contains("mesh 0") && e.contains("fewer than 2^32 vertices"),
        "{e}"
    );
}

#[test]
fn the_bound_is_an_option_and_counts_every_accessor_read() {
    // Small enough to load under the default bound...
    let d = many_reads(4, 2, 1000);
    let s = load(&d, &LoadOptions::default()).unwrap();
    assert_eq!(s.meshes[0].positions.len(), 4000);
    // ...and refused under a tight one: 4 × 3 × 1000 × 12 bytes are needed.
    let opts = LoadOptions {
        max_decoded_bytes: Some(100_000),
        ..LoadOptions::default()
    };
    let e = load(&d, &opts).unwrap_err().to_string();
    assert!(
        e.contains("mesh 0") && e.contains("at most 100000 bytes"),
        "{e}"
    );
}

#[test]
fn skins_rereading_one_huge_accessor_hit_the_bound() {
    // 200 skins read the same 1M-matrix accessor (64 MB of zeros each, 12.8 GB in all); each
    // keeps one matrix, but the reads are counted.
    let d = json!({
        "asset": {"version": "2.0"},
        "nodes": [{}],
        "skins": vec![json!({"joints": [0], "inverseBindMatrices": 0}); 200],
        "accessors": [{"componentType": 5126, "count": 1_000_000, "type": "MAT4"}],
    });
    let e = load(&d, &LoadOptions::default()).unwrap_err().to_string();
    assert!(
        e.contains("huge.gltf")
            && e.contains("accessor 0 (inverseBindMatrices)")
            && e.contains("bytes of decoded data for the whole file"),
        "{e}"
    );
}
