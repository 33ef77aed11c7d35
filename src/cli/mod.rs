//! Subcommands of the `dynbvh` binary, one per file.

pub mod args;
pub mod bench;
pub mod build_bench;
pub mod default_job;
pub mod r#gen;
pub mod info;
pub mod pose;
pub mod render;

use anyhow::Result;
use std::path::Path;

/// Loads a glTF file (its default scene, or `scene`) and prints the loader's warnings.
pub fn load_scene(path: &Path, scene: Option<usize>) -> Result<dynbvh::anim::Scene> {
    let (scene, warnings) = dynbvh::anim::Scene::load_with(
        path,
        &dynbvh::anim::LoadOptions {
            scene,
            ..Default::default()
        },
    )?;
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    Ok(scene)
}

/// Loads a glTF file and flattens its default scene at rest (no animation applied), printing
/// the loader's warnings.
pub fn flatten_gltf_at_rest(path: &Path) -> Result<dynbvh::geom::TriMesh> {
    Ok(load_scene(path, None)?.flatten_rest())
}
