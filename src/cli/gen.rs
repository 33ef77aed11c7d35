//! `dynbvh gen`: writes a deterministic animated test scene as `.glb`.

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
    #[arg(long, default_value_t = 10_000)]
    pub triangles: usize,
    /// Seed of the random parts (orbit radii and hops, explode speeds, lidar-cloth box sizes,
    /// radii, heights and phases).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// For `tube`: give every vertex 4 non-zero skin weights over a chain of this many joints
    /// (cubic B-spline falloff; at least 4), as the posing benchmark does, instead of 2.
    #[arg(long, value_name = "JOINTS")]
    pub four_weights: Option<usize>,
}

/// Generates and writes the file.
pub fn run(a: GenArgs) -> Result<()> {
    let Some(kind) = Kind::parse(&a.kind) else {
        let names: Vec<_> = Kind::ALL.iter().map(|k| k.name()).collect();
        bail!("unknown kind {:?}; one of {}", a.kind, names.join(", "));
    };
    let g = match (kind, a.four_weights) {
        (Kind::Tube, Some(j)) if j >= 4 => skinned_tube(a.triangles, j, TubeWeights::Cubic),
        (Kind::Tube, Some(j)) => bail!("--four-weights needs at least 4 joints, got {j}"),
        (_, Some(_)) => bail!("--four-weights applies to the tube only"),
        (_, None) => generate(kind, a.triangles, a.seed),
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
