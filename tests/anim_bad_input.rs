//! Bad input never panics: every sample file truncated at many offsets, with random bytes
//! flipped, and with random digits of its JSON changed (which keeps the JSON valid but sends
//! indices, counts and offsets out of range). Loading gives Ok or an error naming the file;
//! what loads also poses and flattens.

mod anim_util;

use dynbvh::anim::{LoadOptions, Scene};
use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};
use std::path::{Path, PathBuf};

/// The file's bytes, with external buffers of `.gltf` files inlined as data URIs so that
/// mutations reach binary data too.
fn self_contained(path: &Path) -> Vec<u8> {
    let bytes = std::fs::read(path).unwrap();
    if bytes.starts_with(b"glTF") {
        return bytes;
    }
    let mut json: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
    for b in json["buffers"].as_array_mut().unwrap() {
        let uri = b["uri"].as_str().unwrap().to_string();
        if !uri.starts_with("data:") {
            let data = std::fs::read(path.parent().unwrap().join(&uri)).unwrap();
            b["uri"] = anim_util::data_uri(&data).into();
        }
    }
    serde_json::to_vec(&json).unwrap()
}

/// Loads mutated bytes: Ok, or an error that names the file. Posing what loads must not panic.
fn check(path: &Path, bytes: &[u8]) {
    match Scene::from_slice(path, bytes, &LoadOptions::default()) {
        Ok((scene, _)) => {
            let _ = scene.flatten_rest();
            for a in 0..scene.animations.len().min(3) {
                let mut p = scene.poser(Some(a)).unwrap();
                let d = scene.animations[a].duration;
                p.pose(d * 0.3);
                p.pose(d * 1.7);
                let mut out = Default::default();
                p.flatten_into(&mut out);
            }
        }
        // A file the document refers to (a buffer URI) is named by itself, beside the file.
        Err(dynbvh::Error::Io { path: p, .. }) if p.parent() == path.parent() => {}
        Err(e) => {
            let msg = e.to_string();
            let name = path.file_name().unwrap().to_string_lossy();
            assert!(msg.contains(&*name), "error does not name the file: {msg}");
        }
    }
}

/// Sample files small enough to mutate many times (the 1M-triangle file gets fewer cases).
fn files() -> Vec<(PathBuf, u32)> {
    let Some(dir) = anim_util::samples() else {
        return Vec::new();
    };
    anim_util::SAMPLES
        .iter()
        .map(|&(rel, tris)| (dir.join(rel), if tris > 100_000 { 6 } else { 160 }))
        .collect()
}

#[test]
fn truncations_never_panic() {
    for (path, cases) in files() {
        let bytes = self_contained(&path);
        let n = bytes.len();
        let steps = (cases as usize).max(8);
        for k in 0..steps {
            let cut = n * k / steps;
            check(&path, &bytes[..cut]);
        }
        // Near the ends too: headers and the last few bytes.
        for cut in [
            1,
            4,
            11,
            12,
            19,
            20,
            21,
            n.saturating_sub(1),
            n.saturating_sub(4),
        ] {
            check(&path, &bytes[..cut.min(n)]);
        }
    }
}

#[test]
fn byte_flips_never_panic() {
    for (path, cases) in files() {
        let bytes = self_contained(&path);
        let n = bytes.len();
        let mut runner = TestRunner::new(Config {
            cases,
            failure_persistence: None,
            ..Config::default()
        });
        let strategy = prop::collection::vec((0..n, 1u8..=255), 1..6);
        runner
            .run(&strategy, |flips| {
                let mut b = bytes.clone();
                for (at, x) in flips {
                    b[at] ^= x;
                }
                check(&path, &b);
                Ok(())
            })
            .unwrap();
    }
}

#[test]
fn json_digit_changes_never_panic() {
    for (path, cases) in files() {
        let bytes = self_contained(&path);
        // Positions of ASCII digits in the JSON part (all of a .gltf; the first chunk of a .glb).
        let json_end = if bytes.starts_with(b"glTF") {
            20 + u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize
        } else {
            bytes.iter().position(|&c| c == b';').unwrap_or(bytes.len())
        };
        let digits: Vec<usize> = (0..json_end.min(bytes.len()))
            .filter(|&i| bytes[i].is_ascii_digit())
            .collect();
        if digits.is_empty() {
            continue;
        }
        let mut runner = TestRunner::new(Config {
            cases: cases * 2,
            failure_persistence: None,
            ..Config::default()
        });
        let strategy = prop::collection::vec((0..digits.len(), 0u8..10), 1..4);
        runner
            .run(&strategy, |changes| {
                let mut b = bytes.clone();
                for (k, d) in changes {
                    b[digits[k]] = b'0' + d;
                }
                check(&path, &b);
                Ok(())
            })
            .unwrap();
    }
}

/// A missing file is an I/O error naming it; a missing external buffer is an error about the
/// `.gltf` file that names the buffer, the missing file and the system's reason.
#[test]
fn missing_file_is_an_io_error_and_missing_buffer_names_gltf_buffer_and_file() {
    let e = Scene::load("/nonexistent/dir/x.glb").unwrap_err();
    match &e {
        dynbvh::Error::Io { path, err } => {
            assert_eq!(path, Path::new("/nonexistent/dir/x.glb"));
            assert_eq!(err.kind(), std::io::ErrorKind::NotFound);
        }
        other => panic!("not an I/O error: {other:?}"),
    }
    assert!(e.to_string().contains("x.glb"));
    let Some(p) = anim_util::sample("SimpleSkin/SimpleSkin.gltf") else {
        return;
    };
    let text = std::fs::read_to_string(&p)
        .unwrap()
        .replace("skinGeometry.bin", "nope.bin");
    let e = Scene::from_slice(&p, text.as_bytes(), &LoadOptions::default()).unwrap_err();
    match &e {
        dynbvh::Error::Malformed { path, object, what } => {
            assert_eq!(path, &p);
            assert_eq!(object, "buffer 0");
            assert!(what.contains("nope.bin"), "{what}");
            let reason = std::io::Error::from(std::io::ErrorKind::NotFound).to_string();
            assert!(
                what.contains("No such file") || what.contains(&reason),
                "{what}"
            );
        }
        other => panic!("not a Malformed error: {other:?}"),
    }
    assert!(e.to_string().contains("SimpleSkin.gltf"), "{e}");
}

#[test]
fn malformed_messages_name_file_object_and_expectation() {
    let Some(p) = anim_util::sample("SimpleMorph/SimpleMorph.gltf") else {
        return;
    };
    let json: serde_json::Value = serde_json::from_slice(&self_contained(&p)).unwrap();
    let load = |j: &serde_json::Value| {
        Scene::from_slice(&p, &serde_json::to_vec(j).unwrap(), &LoadOptions::default())
            .map(|_| ())
            .unwrap_err()
            .to_string()
    };
    let mut j = json.clone();
    j["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = 42.into();
    let e = load(&j);
    assert!(
        e.contains("SimpleMorph.gltf") && e.contains("mesh 0 primitive 0 accessor 42 (POSITION)"),
        "{e}"
    );
    let mut j = json.clone();
    j["accessors"][1]["type"] = "VEC2".into();
    let e = load(&j);
    assert!(
        e.contains("accessor 1 (POSITION)") && e.contains("VEC3"),
        "{e}"
    );
    let mut j = json.clone();
    j["accessors"][1]["count"] = 4000.into();
    let e = load(&j);
    assert!(
        e.contains("accessor 1 (POSITION)") && e.contains("inside buffer view"),
        "{e}"
    );
    let mut j = json.clone();
    j["animations"][0]["samplers"][0]["input"] = 5.into(); // the weights: not increasing
    let e = load(&j);
    assert!(
        e.contains("animation 0 sampler 0") && e.contains("increasing"),
        "{e}"
    );
    let mut j = json.clone();
    j["nodes"][0]["children"] = serde_json::json!([0]);
    let e = load(&j);
    assert!(e.contains("node 0"), "{e}");
}
