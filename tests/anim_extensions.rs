//! Extensions the engine does not handle: one warning per extension in `extensionsUsed` that
//! could change geometry or animation, naming it and what is ignored; primitives compressed
//! with Draco or meshopt (without uncompressed fallback data) skipped with a warning naming
//! them while the rest loads; an error naming the file when nothing is left. Small hand-made
//! `.gltf` files with data URIs.

mod anim_util;
use dynbvh::Error;
use dynbvh::anim::{LoadOptions, Scene, Warning};
use serde_json::{Value, json};
use std::path::Path;

/// One triangle's positions (36 bytes) as a data URI.
fn triangle_uri() -> String {
    let p: [f32; 9] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let bytes: Vec<u8> = p.iter().flat_map(|x| x.to_le_bytes()).collect();
    anim_util::data_uri(&bytes)
}

/// A document with buffer 0 (one triangle), buffer view 0 and accessor 0 over it, and a
/// plain mesh 0 placed by node 0; `f` adds to it.
fn doc(f: impl FnOnce(&mut Value)) -> Vec<u8> {
    let mut d = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "buffers": [{"byteLength": 36, "uri": triangle_uri()}],
        "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "accessors": [{
            "bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
            "min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 0.0]
        }]
    });
    f(&mut d);
    serde_json::to_vec(&d).unwrap()
}

fn load(bytes: &[u8]) -> dynbvh::Result<(Scene, Vec<Warning>)> {
    Scene::from_slice(Path::new("hand.gltf"), bytes, &LoadOptions::default())
}

/// Warnings that mention `needle`.
fn mentioning<'w>(w: &'w [Warning], needle: &str) -> Vec<&'w str> {
    w.iter()
        .map(|w| w.0.as_str())
        .filter(|w| w.contains(needle))
        .collect()
}

/// Adds a second node placing mesh 1, whose primitive reads accessor 1.
fn add_second_mesh(d: &mut Value, prim: Value) {
    d["nodes"].as_array_mut().unwrap().push(json!({"mesh": 1}));
    d["scenes"][0]["nodes"] = json!([0, 1]);
    d["meshes"]
        .as_array_mut()
        .unwrap()
        .push(json!({"name": "packed", "primitives": [prim]}));
}

fn used(d: &mut Value, exts: &[&str], required: &[&str]) {
    d["extensionsUsed"] = json!(exts);
    if !required.is_empty() {
        d["extensionsRequired"] = json!(required);
    }
}

#[test]
fn unhandled_extensions_are_named_once_each() {
    let bytes = doc(|d| {
        used(
            d,
            &[
                "EXT_mesh_gpu_instancing",
                "KHR_materials_emissive_strength",
                "KHR_texture_transform",
                "EXT_something_new",
                "KHR_mesh_quantization",
            ],
            &["EXT_something_new"],
        );
        // Two nodes use instancing: still one warning.
        d["nodes"][0]["extensions"] = json!({"EXT_mesh_gpu_instancing": {"attributes": {}}});
        d["nodes"]
            .as_array_mut()
            .unwrap()
            .push(json!({"mesh": 0, "translation": [3.0, 0.0, 0.0],
                "extensions": {"EXT_mesh_gpu_instancing": {"attributes": {}}}}));
        d["scenes"][0]["nodes"] = json!([0, 1]);
    });
    let (scene, w) = load(&bytes).expect("loads");
    assert_eq!(scene.triangle_count(), 2);
    let inst = mentioning(&w, "EXT_mesh_gpu_instancing");
    assert_eq!(inst.len(), 1, "{w:?}");
    assert!(inst[0].contains("instances beyond the node's own are skipped"));
    assert!(inst[0].contains("hand.gltf"));
    let new = mentioning(&w, "EXT_something_new");
    assert_eq!(new.len(), 1, "{w:?}");
    assert!(new[0].contains("ignored"));
    // Appearance extensions and the handled quantization lose nothing: no warning.
    assert!(mentioning(&w, "KHR_materials").is_empty(), "{w:?}");
    assert!(mentioning(&w, "KHR_texture").is_empty(), "{w:?}");
    assert!(mentioning(&w, "KHR_mesh_quantization").is_empty(), "{w:?}");
    assert_eq!(w.len(), 2, "{w:?}");
}

/// A Draco primitive: accessors with counts but no buffer views (the data is in the stream).
fn draco_primitive(d: &mut Value) -> Value {
    d["accessors"].as_array_mut().unwrap().push(json!({
        "componentType": 5126, "count": 3, "type": "VEC3",
        "min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 0.0]
    }));
    json!({
        "attributes": {"POSITION": 1},
        "extensions": {"KHR_draco_mesh_compression": {"bufferView": 0, "attributes": {"POSITION": 0}}}
    })
}

#[test]
fn draco_primitives_are_skipped_and_the_rest_loads() {
    let bytes = doc(|d| {
        used(
            d,
            &["KHR_draco_mesh_compression"],
            &["KHR_draco_mesh_compression"],
        );
        let p = draco_primitive(d);
        add_second_mesh(d, p);
    });
    let (scene, w) = load(&bytes).expect("the uncompressed mesh loads");
    assert_eq!(scene.triangle_count(), 1);
    let skipped = mentioning(&w, "KHR_draco_mesh_compression");
    assert_eq!(skipped.len(), 1, "{w:?}");
    assert!(
        skipped[0].contains("mesh 1 \"packed\" primitive 0 of 1") && skipped[0].contains("skipped"),
        "{}",
        skipped[0]
    );
    assert_eq!(w.len(), 1, "{w:?}");
}

#[test]
fn draco_with_uncompressed_fallback_loads_everything_silently() {
    let bytes = doc(|d| {
        used(d, &["KHR_draco_mesh_compression"], &[]);
        add_second_mesh(
            d,
            json!({
                "attributes": {"POSITION": 0},
                "extensions": {"KHR_draco_mesh_compression": {"bufferView": 0, "attributes": {"POSITION": 0}}}
            }),
        );
    });
    let (scene, w) = load(&bytes).expect("loads");
    assert_eq!(scene.triangle_count(), 2);
    assert!(w.is_empty(), "{w:?}");
}

#[test]
fn a_file_of_only_compressed_primitives_is_an_error_naming_it() {
    let bytes = doc(|d| {
        used(
            d,
            &["KHR_draco_mesh_compression"],
            &["KHR_draco_mesh_compression"],
        );
        let p = draco_primitive(d);
        d["meshes"][0]["primitives"] = json!([p]);
    });
    let e = load(&bytes).expect_err("nothing is left");
    assert!(matches!(e, Error::Unsupported { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("hand.gltf") && msg.contains("compressed") && msg.contains("1 surface"),
        "{msg}"
    );
}

/// Buffer 1 is meshopt's fallback (a length, no data); buffer view 1 lies in it, its real
/// bytes compressed in buffer 0; accessor 1 reads it.
fn meshopt_primitive(d: &mut Value) -> Value {
    d["buffers"].as_array_mut().unwrap().push(
        json!({"byteLength": 36, "extensions": {"EXT_meshopt_compression": {"fallback": true}}}),
    );
    d["bufferViews"].as_array_mut().unwrap().push(json!({
        "buffer": 1, "byteLength": 36, "byteStride": 12,
        "extensions": {"EXT_meshopt_compression": {
            "buffer": 0, "byteLength": 36, "byteStride": 12, "count": 3, "mode": "ATTRIBUTES"
        }}
    }));
    d["accessors"].as_array_mut().unwrap().push(json!({
        "bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC3",
        "min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 0.0]
    }));
    json!({"attributes": {"POSITION": 1}})
}

#[test]
fn meshopt_primitives_without_fallback_are_skipped() {
    let bytes = doc(|d| {
        used(
            d,
            &["EXT_meshopt_compression"],
            &["EXT_meshopt_compression"],
        );
        let p = meshopt_primitive(d);
        add_second_mesh(d, p);
    });
    let (scene, w) = load(&bytes).expect("the uncompressed mesh loads");
    assert_eq!(scene.triangle_count(), 1);
    let skipped = mentioning(&w, "EXT_meshopt_compression");
    assert_eq!(skipped.len(), 1, "{w:?}");
    assert!(
        skipped[0].contains("mesh 1 \"packed\" primitive 0"),
        "{}",
        skipped[0]
    );
    assert_eq!(w.len(), 1, "{w:?}");

    let only = doc(|d| {
        used(
            d,
            &["EXT_meshopt_compression"],
            &["EXT_meshopt_compression"],
        );
        let p = meshopt_primitive(d);
        d["meshes"][0]["primitives"] = json!([p]);
    });
    let msg = load(&only).expect_err("nothing is left").to_string();
    assert!(
        msg.contains("hand.gltf") && msg.contains("compressed"),
        "{msg}"
    );
}
