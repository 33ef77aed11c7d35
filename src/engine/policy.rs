//! When to rebuild a deforming mesh's tree instead of refitting it.
//!
//! Every policy but `rebuild` refits first, then may rebuild. Two ratios measure a refitted
//! tree's degradation:
//! - the **last-build ratio**: its SAH cost over the cost right after its last (re)build
//!   (reported as `sah_ratio`; what `threshold:R` compares with R);
//! - the **fresh ratio**: its SAH cost over the cost a rebuild would reach *now*, estimated by a
//!   quick build over a subsample of the triangles calibrated at the last build
//!   ([`super::estimate::FreshSah`]); what `amortized` decides on. The two differ when a fresh
//!   tree's own cost moves: on `animations/explode.glb` a fresh build's SAH falls from 28 to 22
//!   while the refitted tree's rises to 33, so the last-build ratio peaks at 1.18 while the true
//!   degradation is 1.5 (the estimate says 1.58); on `swap.glb` the last-build ratio reaches
//!   3.2 while a fresh tree is only 1.09 better (estimate 1.2).
//!
use std::fmt;
use std::str::FromStr;

/// Why [`Policy::DEFAULT`] is the default (printed under `dynbvh bench --all`).
pub const WHY_DEFAULT: &str = "\
Why amortized is the default: see the module docs of dynbvh::engine::policy.
";

/// A refit-or-rebuild policy, selectable per run (see [`Policy::from_str`] for the syntax).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Policy {
    /// Never rebuild: refit every frame.
    Refit,
    /// Rebuild every frame (no refit).
    Rebuild,
    /// Rebuild every `N`-th frame since the last build, refit in between (`periodic:1` is
    /// `rebuild`).
    Periodic(u32),
    /// Refit, then rebuild when the SAH ratio exceeds `R`.
    Threshold(f32),
    /// Refit, then rebuild when the extra trace time accumulated since the last rebuild exceeds
    /// the measured cost of a rebuild. The extra trace time of a frame is predicted from the
    /// fresh ratio (see the module docs) and the measured trace time of the previous frame: a
    /// fresh tree would have traced it in `trace / ratio_then`, so the degraded tree costs
    /// `fresh * (ratio_now - 1)` more. With degradation growing linearly over frames this
    /// rebuilds at the optimal period (`k = sqrt(2 C / a)`); with no rays or no degradation it
    /// never rebuilds.
    Amortized,
}

impl Policy {
    /// The default policy: [`Policy::Amortized`], the one that adapts to the cost of a rebuild
    /// and to how many rays a frame casts (see the crate's bench reports for measurements).
    pub const DEFAULT: Policy = Policy::Amortized;

    /// The policies `dynbvh bench` compares when none is given.
    #[must_use]
    pub fn standard_set() -> Vec<Policy> {
        vec![
            Policy::Refit,
            Policy::Rebuild,
            Policy::Periodic(8),
            Policy::Threshold(1.3),
            Policy::Amortized,
        ]
    }

    /// True when the policy refits before deciding (so it has a SAH ratio to decide on).
    #[must_use]
    pub fn refits_first(self) -> bool {
        !matches!(self, Policy::Rebuild) && !matches!(self, Policy::Periodic(n) if n <= 1)
    }
}

impl Default for Policy {
    fn default() -> Self {
        Policy::DEFAULT
    }
}

impl fmt::Display for Policy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Policy::Refit => f.write_str("refit"),
            Policy::Rebuild => f.write_str("rebuild"),
            Policy::Periodic(n) => write!(f, "periodic:{n}"),
            Policy::Threshold(r) => write!(f, "threshold:{r}"),
            Policy::Amortized => f.write_str("amortized"),
        }
    }
}

/// Why a policy string did not parse.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ParsePolicyError(pub String);

impl fmt::Display for ParsePolicyError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ParsePolicyError {}

impl FromStr for Policy {
    type Err = ParsePolicyError;

    /// `refit`, `rebuild`, `periodic:N` (N >= 1), `threshold:R` (R >= 1) or `amortized`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = |why: &str| {
            ParsePolicyError(format!(
                "policy {s:?}: {why} (expected refit, rebuild, periodic:N, threshold:R or amortized)"
            ))
        };
        let s = s.trim();
        let (name, arg) = match s.split_once(':') {
            Some((n, a)) => (n, Some(a)),
            None => (s, None),
        };
        match (name.to_ascii_lowercase().as_str(), arg) {
            ("refit", None) => Ok(Policy::Refit),
            ("rebuild", None) => Ok(Policy::Rebuild),
            ("amortized", None) => Ok(Policy::Amortized),
            ("periodic", Some(a)) => match a.parse::<u32>() {
                Ok(n) if n >= 1 => Ok(Policy::Periodic(n)),
                _ => Err(bad("N must be a whole number >= 1")),
            },
            ("threshold", Some(a)) => match a.parse::<f32>() {
                Ok(r) if r >= 1.0 && r.is_finite() => Ok(Policy::Threshold(r)),
                _ => Err(bad("R must be a number >= 1")),
            },
            ("periodic" | "threshold", None) => Err(bad("missing argument")),
            ("refit" | "rebuild" | "amortized", Some(_)) => Err(bad("takes no argument")),
            _ => Err(bad("unknown policy")),
        }
    }
}

/// What a policy decided for one mesh in one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Action {
    /// Nothing moved: the tree was left alone.
    #[default]
    None,
    /// Refitted.
    Refit,
    /// Rebuilt (possibly after a refit that measured the degradation).
    Rebuild,
}

impl Action {
    /// Lower-case name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Action::None => "none",
            Action::Refit => "refit",
            Action::Rebuild => "rebuild",
        }
    }
}

/// Per-mesh state a policy decides on.
#[derive(Clone, Copy, Debug, Default)]
pub struct PolicyState {
    /// SAH cost right after the last (re)build.
    pub build_sah: f32,
    /// The fresh-build estimate ([`super::estimate::FreshSah::estimate`]) at the last
    /// (re)build, 0 when not computed.
    pub build_estimate: f32,
    /// Frames since the last (re)build.
    pub since_build: u32,
    /// Extra trace time (ms) predicted to have been lost to degradation since the last rebuild.
    pub extra_ms: f64,
    /// Last measured rebuild time of this mesh (ms).
    pub rebuild_ms: f64,
    /// This mesh's share of the last recorded trace time (ms).
    pub trace_share_ms: f64,
    /// Fresh ratio of the tree when that trace ran.
    pub traced_ratio: f32,
}

impl PolicyState {
    /// Decides before refitting: `Some(true)` rebuild without refitting, `Some(false)` refit
    /// only, `None` refit then ask [`PolicyState::after_refit`].
    #[must_use]
    pub fn before_refit(&self, policy: Policy) -> Option<bool> {
        match policy {
            Policy::Refit => Some(false),
            Policy::Rebuild => Some(true),
            Policy::Periodic(n) => Some(self.since_build + 1 >= n),
            Policy::Threshold(_) | Policy::Amortized => None,
        }
    }

    /// True when the policy decides on the fresh ratio (so the engine must estimate it).
    #[must_use]
    pub fn needs_fresh_ratio(policy: Policy) -> bool {
        matches!(policy, Policy::Amortized)
    }

    /// Decides after a refit that gave last-build SAH ratio `ratio` and fresh ratio `fresh`:
    /// true to rebuild. Updates the accumulated extra trace time of [`Policy::Amortized`].
    pub fn after_refit(&mut self, policy: Policy, ratio: f32, fresh: f32) -> bool {
        match policy {
            Policy::Threshold(r) => ratio > r,
            Policy::Amortized => {
                let fresh_ms = self.trace_share_ms / f64::from(self.traced_ratio.max(1e-6));
                self.extra_ms += fresh_ms * f64::from(fresh - 1.0).max(0.0);
                self.extra_ms > self.rebuild_ms
            }
            _ => false,
        }
    }

    /// Resets after a (re)build of SAH cost `sah` (fresh-build estimate `estimate`, 0 when not
    /// computed) that took `ms`.
    pub fn rebuilt(&mut self, sah: f32, estimate: f32, ms: f64) {
        self.build_sah = sah;
        self.build_estimate = estimate;
        self.since_build = 0;
        self.extra_ms = 0.0;
        self.rebuild_ms = ms;
        self.traced_ratio = 1.0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_prints_every_policy() {
        for p in [
            Policy::Refit,
            Policy::Rebuild,
            Policy::Periodic(5),
            Policy::Threshold(1.5),
            Policy::Amortized,
        ] {
            assert_eq!(p.to_string().parse::<Policy>().unwrap(), p);
        }
        assert_eq!(
            " Threshold:2 ".parse::<Policy>().unwrap(),
            Policy::Threshold(2.0)
        );
        for bad in [
            "",
            "refit:1",
            "periodic",
            "periodic:0",
            "threshold:0.5",
            "thresh:2",
            "periodic:x",
        ] {
            assert!(bad.parse::<Policy>().is_err(), "{bad:?} parsed");
        }
    }

    #[test]
    fn amortized_rebuilds_once_extra_time_passes_rebuild_cost() {
        let mut s = PolicyState::default();
        s.rebuilt(1.0, 1.0, 10.0);
        s.trace_share_ms = 4.0;
        s.traced_ratio = 1.0;
        // Ratio 1.5: 2 ms extra per frame, so the sixth frame passes 10 ms.
        let frames = (1..=10)
            .find(|_| s.after_refit(Policy::Amortized, 1.0, 1.5))
            .unwrap();
        assert_eq!(frames, 6);
        // No rays, no reason to rebuild.
        s.rebuilt(1.0, 1.0, 10.0);
        s.trace_share_ms = 0.0;
        assert!(!(0..100).any(|_| s.after_refit(Policy::Amortized, 5.0, 5.0)));
    }
}
