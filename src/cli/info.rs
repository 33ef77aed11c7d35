//! `dynbvh info`: what a glTF file holds and how each mesh instance moves.

use anyhow::Result;
use clap::Args;
use dynbvh::anim::{InstanceClass, Interpolation, Property};
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::PathBuf;

/// Instances listed one by one; beyond this only the class counts are printed.
const LISTED: usize = 64;

/// `writeln!` into a `String` (which cannot fail).
macro_rules! out {
    ($s:expr, $($t:tt)*) => {
        let _ = writeln!($s, $($t)*);
    };
}

/// Arguments of `dynbvh info`.
#[derive(Args)]
pub struct InfoArgs {
    /// The .gltf or .glb file.
    pub file: PathBuf,
    /// glTF scene index (default: the file's default scene).
    #[arg(long, allow_negative_numbers = true)]
    pub scene: Option<usize>,
}

/// Prints the summary.
pub fn run(a: InfoArgs) -> Result<()> {
    let scene = super::load_scene(&a.file, a.scene)?;
    let mut text = String::new();
    let label = |name: &Option<String>| {
        name.as_deref()
            .map(|n| format!(" \"{n}\""))
            .unwrap_or_default()
    };
    out!(text, "file: {}", a.file.display());
    let chosen = scene
        .scene_index
        .map_or("none (all roots)".to_string(), |i| i.to_string());
    out!(text, "scenes: {} (using {chosen})", scene.scene_names.len());
    out!(
        text,
        "nodes: {} ({} roots in the scene)",
        scene.nodes.len(),
        scene.roots.len()
    );
    out!(
        text,
        "meshes placed: {}, instances: {}, triangles: {}, vertices: {}",
        scene.meshes.len(),
        scene.instances.len(),
        scene.triangle_count(),
        scene.vertex_count()
    );
    for m in &scene.meshes {
        out!(
            text,
            "  mesh {}{}: {} triangles, {} vertices, {} morph targets{}",
            m.gltf_index,
            label(&m.name),
            m.indices.len(),
            m.positions.len(),
            m.targets.len(),
            m.skin
                .as_ref()
                .map(|s| format!(", {} joint influences per vertex", s.influences))
                .unwrap_or_default()
        );
    }
    out!(text, "skins: {}", scene.skins.len());
    for (i, s) in scene.skins.iter().enumerate() {
        out!(
            text,
            "  skin {i}{}: {} joints",
            label(&s.name),
            s.joints.len()
        );
    }
    out!(text, "animations: {}", scene.animations.len());
    let classes: Vec<_> = (0..scene.animations.len())
        .map(|a| scene.classify(Some(a)))
        .collect::<dynbvh::Result<_>>()?;
    for (i, an) in scene.animations.iter().enumerate() {
        let mut modes: Vec<&str> = an
            .channels
            .iter()
            .map(|c| match an.samplers[c.sampler].interpolation {
                Interpolation::Step => "STEP",
                Interpolation::Linear => "LINEAR",
                Interpolation::CubicSpline => "CUBICSPLINE",
            })
            .collect();
        modes.sort_unstable();
        modes.dedup();
        let count = |p: Property| an.channels.iter().filter(|c| c.property == p).count();
        let n = |k: InstanceClass| classes[i].iter().filter(|&&x| x == k).count();
        out!(
            text,
            "  animation {i}{}: {:.3} s, {} channels (T {}, R {}, S {}, weights {}), {}; {} static, {} rigid, {} deforming instances",
            label(&an.name),
            an.duration,
            an.channels.len(),
            count(Property::Translation),
            count(Property::Rotation),
            count(Property::Scale),
            count(Property::Weights),
            modes.join("/"),
            n(InstanceClass::Static),
            n(InstanceClass::Rigid),
            n(InstanceClass::Deforming)
        );
    }
    out!(text, "instances (class under each animation):");
    if scene.instances.len() > LISTED {
        out!(text, "  (first {LISTED} of {})", scene.instances.len());
    }
    for (i, inst) in scene.instances.iter().enumerate().take(LISTED) {
        let node = &scene.nodes[inst.node];
        let mesh = &scene.meshes[inst.mesh];
        let cls: Vec<&str> = classes.iter().map(|c| c[i].name()).collect();
        out!(
            text,
            "  {i}: node {}{} mesh {}{}, {} triangles{}: {}",
            inst.node,
            label(&node.name),
            mesh.gltf_index,
            label(&mesh.name),
            mesh.indices.len(),
            inst.skin.map(|s| format!(", skin {s}")).unwrap_or_default(),
            if cls.is_empty() {
                "static (no animations)".to_string()
            } else {
                cls.join(", ")
            }
        );
    }
    match std::io::stdout().lock().write_all(text.as_bytes()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e.into()),
        _ => Ok(()),
    }
}
