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
