//! Shared helpers of the `anim_*` tests: locating the sample files.
#![allow(dead_code)]

use std::path::PathBuf;

/// The shared glTF samples folder, or `None` (with a loud message; a panic under `CI`).
pub fn samples() -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/gltf-samples");
    if dir.is_dir() {
        return Some(dir);
    }
    let msg = format!(
        "!!!!! glTF samples folder {} is missing: sample-file tests SKIPPED !!!!!",
        dir.display()
    );
    if std::env::var_os("CI").is_some() {
        panic!("{msg} (CI is set, so this is a failure)");
    }
    eprintln!("{msg}");
    None
}

/// A sample file path, or `None` when the folder is absent.
pub fn sample(rel: &str) -> Option<PathBuf> {
    samples().map(|d| d.join(rel))
}

/// Every sample file with its triangle count from the samples README.
pub const SAMPLES: &[(&str, usize)] = &[
    ("AnimatedTriangle/AnimatedTriangle.gltf", 1),
    ("AnimatedCube/AnimatedCube.gltf", 12),
    ("BoxAnimated/BoxAnimated.glb", 254),
    ("InterpolationTest/InterpolationTest.glb", 110),
    ("SimpleMorph/SimpleMorph.gltf", 1),
    ("AnimatedMorphCube/AnimatedMorphCube.glb", 12),
    (
        "AnimatedMorphCube/glTF-Quantized/AnimatedMorphCube.gltf",
        12,
    ),
    ("AnimatedMorphSphere/AnimatedMorphSphere.glb", 960),
    ("MorphStressTest/MorphStressTest.glb", 2412),
    ("SimpleSkin/SimpleSkin.gltf", 8),
    ("RiggedSimple/RiggedSimple.glb", 188),
    ("RiggedFigure/RiggedFigure.glb", 256),
    ("CesiumMan/CesiumMan.glb", 4672),
    ("Fox/Fox.glb", 576),
    ("SimpleSparseAccessor/SimpleSparseAccessor.gltf", 12),
    ("MeshPrimitiveModes/MeshPrimitiveModes.gltf", 16),
    ("TransmissionTest/TransmissionTest.glb", 128_775),
    (
        "MetalRoughSpheresNoTextures/MetalRoughSpheresNoTextures.glb",
        1_040_409,
    ),
];

/// A tiny independent glTF reader for tests: JSON as `serde_json::Value` and raw buffers
/// (GLB BIN chunk or external files; no data URIs, no sparse accessors).
pub struct Raw {
    /// The JSON document.
    pub json: serde_json::Value,
    /// Buffer bytes.
    pub buffers: Vec<Vec<u8>>,
}

impl Raw {
    /// Reads `path`.
    pub fn open(path: &std::path::Path) -> Raw {
        let bytes = std::fs::read(path).unwrap();
        let u32_at = |b: &[u8], o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap());
        if bytes.starts_with(b"glTF") {
            let jl = u32_at(&bytes, 12) as usize;
            let json = serde_json::from_slice(&bytes[20..20 + jl]).unwrap();
            let off = (20 + jl).div_ceil(4) * 4;
            let bl = u32_at(&bytes, off) as usize;
            let bin = bytes[off + 8..off + 8 + bl].to_vec();
            Raw {
                json,
                buffers: vec![bin],
            }
        } else {
            let json: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
            let dir = path.parent().unwrap();
            let buffers = json["buffers"]
                .as_array()
                .unwrap()
                .iter()
                .map(|b| std::fs::read(dir.join(b["uri"].as_str().unwrap())).unwrap())
                .collect();
            Raw { json, buffers }
        }
    }

    /// Accessor `i` as rows of f64 (floats, or integers as their value, normalized if flagged).
    pub fn accessor(&self, i: usize) -> Vec<Vec<f64>> {
        let a = &self.json["accessors"][i];
        let v = &self.json["bufferViews"][a["bufferView"].as_u64().unwrap() as usize];
        let n = match a["type"].as_str().unwrap() {
            "SCALAR" => 1,
            "VEC2" => 2,
            "VEC3" => 3,
            "VEC4" => 4,
            "MAT4" => 16,
            t => panic!("{t}"),
        };
        let ct = a["componentType"].as_u64().unwrap();
        let size = match ct {
            5120 | 5121 => 1,
            5122 | 5123 => 2,
            _ => 4,
        };
        let norm = a["normalized"].as_bool().unwrap_or(false);
        let stride = v["byteStride"].as_u64().unwrap_or((n * size) as u64) as usize;
        let base = v["byteOffset"].as_u64().unwrap_or(0) as usize
            + a["byteOffset"].as_u64().unwrap_or(0) as usize;
        let buf = &self.buffers[v["buffer"].as_u64().unwrap() as usize];
        (0..a["count"].as_u64().unwrap() as usize)
            .map(|k| {
                (0..n)
                    .map(|c| {
                        let o = base + k * stride + c * size;
                        let b = &buf[o..o + size];
                        match ct {
                            5120 => {
                                let x = b[0] as i8 as f64;
                                if norm { (x / 127.0).max(-1.0) } else { x }
                            }
                            5121 => {
                                let x = b[0] as f64;
                                if norm { x / 255.0 } else { x }
                            }
                            5122 => {
                                let x = i16::from_le_bytes([b[0], b[1]]) as f64;
                                if norm { (x / 32767.0).max(-1.0) } else { x }
                            }
                            5123 => {
                                let x = u16::from_le_bytes([b[0], b[1]]) as f64;
                                if norm { x / 65535.0 } else { x }
                            }
                            5125 => u32::from_le_bytes(b.try_into().unwrap()) as f64,
                            _ => f32::from_le_bytes(b.try_into().unwrap()) as f64,
                        }
                    })
                    .collect()
            })
            .collect()
    }
}

/// Asserts two points agree within `tol`.
#[track_caller]
pub fn assert_near(a: glam::Vec3, b: glam::Vec3, tol: f32, what: &str) {
    assert!(
        (a - b).abs().max_element() <= tol,
        "{what}: got {a}, want {b} (tol {tol})"
    );
}

/// `bytes` as a base64 data URI (standard alphabet, padded).
pub fn data_uri(bytes: &[u8]) -> String {
    format!("data:application/octet-stream;base64,{}", base64(bytes))
}

/// Standard base64 with padding (for `data:` URIs in hand-made glTF files).
pub fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for c in bytes.chunks(3) {
        let n = (u32::from(c[0]) << 16)
            | (u32::from(*c.get(1).unwrap_or(&0)) << 8)
            | u32::from(*c.get(2).unwrap_or(&0));
        for k in 0..4 {
            if k <= c.len() {
                out.push(char::from(A[(n >> (18 - 6 * k) & 63) as usize]));
            } else {
                out.push('=');
            }
        }
    }
    out
}
