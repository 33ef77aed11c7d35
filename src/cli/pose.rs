//! `dynbvh pose`: a scene's triangles at time `t`, written as OBJ or PLY.

use super::args::{self, MemoryLimit};
use anyhow::{Result, bail};
use clap::Args;
use dynbvh::geom::TriMesh;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Arguments of `dynbvh pose`.
#[derive(Args)]
pub struct PoseArgs {
    /// The .gltf or .glb file.
    pub file: PathBuf,
    /// Time in seconds (wraps beyond the animation's duration; may be negative).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true, value_parser = args::finite_time)]
    pub time: f32,
    /// Animation name or index (default: the file's first animation; the rest pose when the
    /// file has none).
    #[arg(long, short)]
    pub animation: Option<String>,
    /// Write the rest pose (nodes at their own transforms, no animation) even when the file
    /// has animations.
    #[arg(long, conflicts_with = "animation")]
    pub rest: bool,
    /// glTF scene index (default: the file's default scene).
    #[arg(long, allow_negative_numbers = true)]
    pub scene: Option<usize>,
    /// Output file: .obj (text) or .ply (binary).
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub limits: MemoryLimit,
}

/// Poses and writes.
pub fn run(a: PoseArgs) -> Result<()> {
    let scene = super::load_scene(&a.file, a.scene)?;
    a.limits.check_scene(&scene, args::POSE_MEMORY, 1)?;
    let anim = match &a.animation {
        None if a.rest => None,
        None if scene.animations.is_empty() => {
            eprintln!("{}: no animations; writing the rest pose", a.file.display());
            None
        }
        None => {
            let first = &scene.animations[0];
            eprintln!(
                "{}: posing animation 0{} of {} at {} s (--animation chooses another)",
                a.file.display(),
                first
                    .name
                    .as_deref()
                    .map(|n| format!(" \"{n}\""))
                    .unwrap_or_default(),
                scene.animations.len(),
                a.time
            );
            Some(0)
        }
        Some(key) => Some(args::choose_animation(&scene, &a.file, key)?),
    };
    let mesh = scene.flatten_at(anim, a.time)?;
    warn_nonfinite(&scene, &mesh);
    let ext = a
        .out
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let bytes = match ext.as_str() {
        "obj" => obj(&mesh),
        "ply" => ply(&mesh),
        _ => bail!("{}: output must end in .obj or .ply", a.out.display()),
    };
    write(&a.out, &bytes)?;
    eprintln!(
        "{}: {} triangles, {} vertices",
        a.out.display(),
        mesh.len(),
        mesh.positions.len()
    );
    Ok(())
}

/// Warns, per mesh instance, about posed vertices that are NaN or infinite (finite node
/// transforms can overflow when multiplied), naming the node and the mesh; they are written
/// as they are.
fn warn_nonfinite(scene: &dynbvh::anim::Scene, mesh: &TriMesh) {
    for inst in &scene.instances {
        let Some(v) = mesh.positions.get(inst.vertices.clone()) else {
            continue;
        };
        let bad = v.iter().filter(|p| !p.is_finite()).count();
        if bad > 0 {
            let m = &scene.meshes[inst.mesh];
            eprintln!(
                "warning: {}: node {}{} mesh {}{}: {bad} of {} posed vertices are not finite \
                 (NaN or infinite; the transforms overflow)",
                scene.path.display(),
                inst.node,
                scene.nodes[inst.node]
                    .name
                    .as_deref()
                    .map(|n| format!(" \"{n}\""))
                    .unwrap_or_default(),
                m.gltf_index,
                m.name
                    .as_deref()
                    .map(|n| format!(" \"{n}\""))
                    .unwrap_or_default(),
                v.len()
            );
        }
    }
}

/// Writes `bytes` to `path`.
fn write(path: &Path, bytes: &[u8]) -> Result<()> {
    std::fs::write(path, bytes).map_err(|e| dynbvh::Error::io(path, e))?;
    Ok(())
}

/// Wavefront OBJ text.
fn obj(m: &TriMesh) -> Vec<u8> {
    let mut out = Vec::with_capacity(m.positions.len() * 32 + m.indices.len() * 24);
    for p in &m.positions {
        let _ = writeln!(out, "v {} {} {}", p.x, p.y, p.z);
    }
    for [a, b, c] in &m.indices {
        let _ = writeln!(out, "f {} {} {}", a + 1, b + 1, c + 1);
    }
    out
}

/// Binary little-endian PLY.
fn ply(m: &TriMesh) -> Vec<u8> {
    let mut out = Vec::with_capacity(m.positions.len() * 12 + m.indices.len() * 13 + 256);
    let _ = write!(
        out,
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        m.positions.len(),
        m.indices.len()
    );
    for p in &m.positions {
        for c in p.to_array() {
            out.extend_from_slice(&c.to_le_bytes());
        }
    }
    for t in &m.indices {
        out.push(3);
        for i in t {
            out.extend_from_slice(&i.to_le_bytes());
        }
    }
    out
}
