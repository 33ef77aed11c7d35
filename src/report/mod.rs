//! Measurements and reports: what the CLI's benchmark commands compute and print.

pub mod accel_bench;
pub mod all_pairs;
pub mod build_bench;
pub mod charts;
pub mod clip;
pub mod font;
pub mod frame_bench;
pub mod ray_sweep;
pub mod rays;
pub mod rungs;
pub mod wide_bench;

/// What the text tables print for a value that was not computed.
pub const NOT_COMPUTED: &str = "\u{2013}";

/// `v` with `decimals` decimals, or [`NOT_COMPUTED`] when it is `None` or not finite.
#[must_use]
pub fn or_dash(v: Option<f64>, decimals: usize) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.decimals$}"),
        _ => NOT_COMPUTED.to_string(),
    }
}

/// `v`, where 0 stands for "not computed" (as in the reports' ratios to the oracle), with
/// `decimals` decimals, or [`NOT_COMPUTED`].
#[must_use]
pub fn nonzero_or_dash(v: f64, decimals: usize) -> String {
    or_dash((v != 0.0).then_some(v), decimals)
}

/// An always-refit engine built at frame 0 of `src`, and its largest deforming mesh: what the
/// rung and clip reports follow through the frames.
///
/// # Errors
/// When the source has no deforming mesh.
pub(crate) fn refit_engine_on_largest_mesh(
    src: &mut dyn crate::engine::source::FrameSource,
) -> anyhow::Result<(crate::engine::Engine, crate::engine::MeshId)> {
    let config = crate::engine::EngineConfig {
        policy: crate::engine::Policy::Refit,
        ..crate::engine::EngineConfig::default()
    };
    let e = src.build(0, config);
    let Some(&mesh) = src.deforming().iter().max_by_key(|&&m| e.indices(m).len()) else {
        anyhow::bail!("{}: no deforming mesh to refit", src.name());
    };
    Ok((e, mesh))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dashes_for_missing_values() {
        assert_eq!(or_dash(Some(1.23456), 3), "1.235");
        assert_eq!(or_dash(None, 3), NOT_COMPUTED);
        assert_eq!(or_dash(Some(f64::NAN), 2), NOT_COMPUTED);
        assert_eq!(nonzero_or_dash(0.0, 3), NOT_COMPUTED);
        assert_eq!(nonzero_or_dash(1.5, 1), "1.5");
    }
}
