//! `dynbvh gen`: writes a deterministic animated test scene as `.glb`.

use super::args::MemoryLimit;
use anyhow::{Result, bail};
use clap::Args;
use dynbvh::anim::generate::{Kind, TubeWeights, generate, skinned_tube};
use std::path::PathBuf;

/// Arguments of `dynbvh gen`.
#[derive(Args)]
pub struct GenArgs {
    /// Scene kind: tube (skinned bend), wave (morph, cubic weights), orbit (rigid objects,
    /// STEP and LINEAR), explode (triangles fly apart), swap (two halves trade places),
    /// lidar-cloth (a sensor scene: a cloth sheet that ripples, billows and folds over, with
    /// rigid boxes moving above and around it).
    pub kind: String,
    /// Output .glb file.
    #[arg(long)]
    pub out: PathBuf,
    /// Approximate triangle count.
    #[arg(long, allow_negative_numbers = true, default_value_t = 10_000, value_parser = clap::value_parser!(u64).range(1..=1 << 32))]
    pub triangles: u64,
    /// Seed of the random parts (orbit radii and hops, explode speeds, lidar-cloth box sizes,
    /// radii, heights and phases).
    #[arg(long, allow_negative_numbers = true, default_value_t = 1)]
    pub seed: u64,
    /// For `tube`: give every vertex 4 non-zero skin weights over a chain of this many joints
    /// (cubic B-spline falloff; at least 4), as the posing benchmark does, instead of 2.
    #[arg(long, allow_negative_numbers = true, value_name = "JOINTS", value_parser = clap::value_parser!(u64).range(4..=MAX_JOINTS))]
    pub four_weights: Option<u64>,
    #[command(flatten)]
    pub limits: MemoryLimit,
}

/// Most joints of `--four-weights`: a glTF skin holds at most 65536.
const MAX_JOINTS: u64 = 1 << 16;

/// Peak bytes per triangle of generating `kind` (the scene, its animation and the GLB), with
/// a margin over what was measured.
pub(super) fn bytes_per_triangle(kind: Kind) -> u64 {
    match kind {
        Kind::Orbit => 1000,
        Kind::Explode => 600,
        _ => 200,
    }
}

/// Generates and writes the file.
pub fn run(a: GenArgs) -> Result<()> {
    let Some(kind) = Kind::parse(&a.kind) else {
        let names: Vec<_> = Kind::ALL.iter().map(|k| k.name()).collect();
        bail!("unknown kind {:?}; one of {}", a.kind, names.join(", "));
    };
    a.limits.check_memory(
        &format!("--triangles {}", a.triangles),
        a.triangles.saturating_mul(bytes_per_triangle(kind)),
    )?;
    let glb = a
        .out
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("glb"));
    if !glb {
        anyhow::bail!(
            "{}: gen writes binary glTF; give the file the .glb extension",
            a.out.display()
        );
    }
    let triangles = a.triangles as usize;
    let g = match (kind, a.four_weights) {
        (Kind::Tube, Some(j)) => skinned_tube(triangles, j as usize, TubeWeights::Cubic),
        (_, Some(_)) => bail!("--four-weights applies to the tube only"),
        (_, None) => generate(kind, triangles, a.seed),
    };
    std::fs::write(&a.out, &g.glb).map_err(|e| dynbvh::Error::io(&a.out, e))?;
    eprintln!(
        "{}: {} triangles, {:.2} s animation, {} bytes",
        a.out.display(),
        g.triangles,
        g.duration,
        g.glb.len()
    );
    Ok(())
}
