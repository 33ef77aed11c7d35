//! Subcommands of the `dynbvh` binary, one per file.

pub mod accel_bench;
pub mod args;
pub mod bench;
pub mod build_bench;
pub mod clip;
pub mod default_job;
pub mod r#gen;
pub mod info;
pub mod pose;
pub mod progress;
pub mod render;
pub mod rungs;

use anyhow::Result;
use std::path::Path;

/// Whether glTF files may name buffers outside their folder (`--allow-outside-files`), set
/// once by `main` before any command runs.
static ALLOW_OUTSIDE_FILES: std::sync::OnceLock<bool> = std::sync::OnceLock::new();

/// Sets what `--allow-outside-files` said, for every file the command loads.
pub fn set_allow_outside_files(allow: bool) {
    let _ = ALLOW_OUTSIDE_FILES.set(allow);
}

/// Loads a glTF file (its default scene, or `scene`) and prints the loader's warnings.
pub fn load_scene(path: &Path, scene: Option<usize>) -> Result<dynbvh::anim::Scene> {
    let (scene, warnings) = dynbvh::anim::Scene::load_with(
        path,
        &dynbvh::anim::LoadOptions {
            scene,
            allow_outside_files: ALLOW_OUTSIDE_FILES.get().copied().unwrap_or(false),
            ..Default::default()
        },
    )?;
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    Ok(scene)
}

/// Loads a glTF file and flattens its default scene at rest (no animation applied), printing
/// the loader's warnings; refused when the flattened scene and `per`'s allocations for it
/// would pass `limit`.
pub fn flatten_gltf_at_rest(
    path: &Path,
    limit: &args::MemoryLimit,
    per: args::PerElement,
) -> Result<dynbvh::geom::TriMesh> {
    let scene = load_scene(path, None)?;
    limit.check_scene(&scene, per, 1)?;
    Ok(scene.flatten_rest())
}
