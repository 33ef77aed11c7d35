//! When to rebuild a deforming mesh's tree instead of refitting it.
//!
//! Every policy but `rebuild` and `periodic` refits first, then may rebuild. What it weighs
//! depends on the engine's [`super::CostMeasure`]:
//! - **ray work** (the default): the frame's sampled rays ([`super::ray_work`]) give each
//!   mesh's share of the trace cost, and the degradation is the sampled work into the mesh over
//!   what its fresh tree would cost on the same entries, predicted from the triangle boxes
//!   they pierce ([`super::ray_work::FreshWork`]), corrected by each rebuild's replay of the rays on both
//!   trees; a rebuild whose tree the replay finds worse is dropped in the same frame (a trial),
//!   and each kept one is judged by what it saved ([`Payback`]); a rebuild that costs under a
//!   small share of the mesh's trace is made every frame, checked by a trial now and then
//!   ([`super::routine`]); frames that cannot make an action due go unsampled
//!   ([`super::watch`]);
//! - **SAH**: the degradation is the refitted tree's SAH over a fresh build's, estimated by
//!   [`super::estimate::FreshSah`]; rebuilds are probed (the mesh goes back to the replaced
//!   tree if it is better again before the rebuild has paid).
//!
//! `amortized` rebuilds when the trace time its degradation has cost since the last build
//! passes a rebuild's cost: the optimal period for linearly growing degradation, and no rebuild
//! without rays or degradation. Under the ray-work measure, a sampled degradation of at least
//! half a fresh tree's work is also projected forward (`PolicyState::forward_ms`), so that
//! one growing faster than that (an explosion) is not rebuilt late. `amortized-plain` is that
//! rule without estimate, calibration or probation. The sweeps behind the default:
//! `docs/policy_sweep.md`, `docs/ray_work.md`.
use super::routine::{ROUTINE_REBUILD_SHARE, Routine};
use super::watch::{MIN_PLANNED_DEGRADATION, Watch};
use std::fmt;
use std::str::FromStr;

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
    ///
    /// A rebuild is then on probation: the tree it replaced is refitted alongside until the new
    /// tree has saved the rebuild's cost in trace time (by the two trees' SAH costs), or the old
    /// tree is the better one again, in which case the mesh goes back to it and the next rebuild
    /// must be expected to save twice as much ([`PolicyState::rebuild_scale`]), or refitting
    /// the old tree has cost half a rebuild.
    Amortized,
    /// The plain amortized rule, without [`Policy::Amortized`]'s refinements (fresh-build
    /// estimate and its calibration, rebuild scaling, probation and reverts): after each
    /// refit, add `(SAH ratio - 1) * trace` to the extra trace time accumulated since the last
    /// (re)build, where the SAH ratio is the last-build ratio (the refitted tree's SAH over its
    /// SAH right after the last (re)build) and `trace` the mesh's share of the last measured
    /// trace time ([`super::Engine::record_trace`]; the whole frame's when the scene has one
    /// mesh); rebuild when the sum exceeds the last (re)build's measured cost
    /// ([`super::Timing`]); a rebuild resets the sum. Selectable as `amortized-plain`, for
    /// comparison with the default.
    AmortizedPlain,
    /// [`Policy::Amortized`]'s rule with insertion-based optimisation of this share of the
    /// interior nodes ([`crate::bvh::optimize`]) as the only action besides refit: it acts when
    /// the extra trace time it is expected to win back passes its cost.
    Optimize(f32),
    /// The same with a partial rebuild of at most this share of the triangles
    /// ([`crate::bvh::partial`]).
    Partial(f32),
    /// The ladder: refit, optimise ([`LADDER_OPTIMIZE`]), partial rebuild ([`LADDER_PARTIAL`])
    /// or full rebuild, whichever is expected to win back the most extra trace time over its
    /// cost once one of them has paid; each rung's cost and share of the degradation it
    /// recovers are learnt per mesh from what it did (see [`RungModel`]).
    Ladder,
    /// [`Policy::Amortized`]'s rule with its rebuilds run in the background
    /// ([`Decision::Background`]): the old tree is refitted until the new one is built, then
    /// the new one is refitted to the current pose and swapped in. A rebuild is made in the
    /// frame instead when waiting for the build would cost more trace time than the rebuild
    /// ([`PolicyState::expect_background`]).
    Async,
}

/// The optimisation budget of [`Policy::Ladder`]: a share of the interior nodes.
pub const LADDER_OPTIMIZE: f32 = 0.01;
/// The partial rebuild of [`Policy::Ladder`]: at most this share of the triangles.
pub const LADDER_PARTIAL: f32 = 0.25;

/// What a policy decided for one mesh in one frame, before it is done.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Decision {
    /// Refit only.
    Refit,
    /// Refit, then optimise this share of the interior nodes.
    Optimize(f32),
    /// Refit, then rebuild the top and at most this share of the triangles.
    Partial(f32),
    /// Rebuild (possibly after a refit that measured the degradation).
    Rebuild,
    /// Refit, and rebuild from this frame's positions on the background worker (refit only
    /// while it is busy).
    Background,
}

impl Decision {
    /// The rung's index among [`PolicyState::rungs`] (optimise 0, partial 1), if it is one.
    #[must_use]
    pub fn rung(self) -> Option<usize> {
        match self {
            Decision::Optimize(_) => Some(0),
            Decision::Partial(_) => Some(1),
            _ => None,
        }
    }
}

/// What a policy knows of one intermediate rung on one mesh: its cost and the share of the
/// degradation it wins back, as measured the last times it ran.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RungModel {
    /// Predicted cost, ms (the last run's; before any, a prior the engine sets).
    pub cost_ms: f64,
    /// Share of the degradation (`ratio - 1`) it removes (0 ..= 1), learnt as the rays or the
    /// SAH showed it.
    pub recovery: f32,
    /// Runs it was learnt from.
    pub runs: u32,
}

impl RungModel {
    /// Learns from one run that cost `ms` and took the degradation from `before` to `after`
    /// (ratios to a fresh tree, or the measured ratio of the old tree's cost to the new one's
    /// with `after` 1).
    pub fn learn(&mut self, ms: f64, before: f32, after: f32) {
        self.cost_ms = ms;
        if before > 1.0 + MIN_RAY_SIGNAL && after.is_finite() {
            let seen = ((before - after) / (before - 1.0)).clamp(0.0, 1.0);
            let w = (1.0 / (self.runs as f32 + 1.0)).max(0.3);
            self.recovery += w * (seen - self.recovery);
            self.runs += 1;
        }
    }
}

impl Policy {
    /// The default policy: [`Policy::Amortized`], the one that adapts to the cost of a rebuild
    /// and to how many rays a frame casts (`docs/policy_sweep.md` compares it with the others).
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
            Policy::AmortizedPlain,
        ]
    }

    /// True when the policy may optimise or rebuild partly: actions outside the
    /// refit-or-rebuild oracle's, which such a policy may therefore beat.
    #[must_use]
    pub fn uses_rungs(self) -> bool {
        matches!(
            self,
            Policy::Optimize(_) | Policy::Partial(_) | Policy::Ladder
        )
    }

    /// True when the policy's moves are not all the oracle's (rungs, or rebuilds that take
    /// effect frames later), so that it may come out below it.
    #[must_use]
    pub fn beyond_oracle(self) -> bool {
        self.uses_rungs() || self == Policy::Async
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
            Policy::AmortizedPlain => f.write_str("amortized-plain"),
            Policy::Optimize(b) => write!(f, "optimize:{b}"),
            Policy::Partial(b) => write!(f, "partial:{b}"),
            Policy::Ladder => f.write_str("ladder"),
            Policy::Async => f.write_str("async"),
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

    /// `refit`, `rebuild`, `periodic:N` (N >= 1), `threshold:R` (R >= 1), `amortized`,
    /// `amortized-plain`, `optimize:B` and `partial:F` (shares in (0, 1]), `ladder` or `async`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = |why: &str| {
            ParsePolicyError(format!(
                "policy {s:?}: {why} (expected refit, rebuild, periodic:N, threshold:R, amortized, \
                 amortized-plain, optimize:B, partial:F, ladder or async)"
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
            ("amortized-plain", None) => Ok(Policy::AmortizedPlain),
            ("ladder", None) => Ok(Policy::Ladder),
            ("async", None) => Ok(Policy::Async),
            ("optimize" | "partial", Some(a)) => match a.parse::<f32>() {
                Ok(b) if b > 0.0 && b <= 1.0 => Ok(if name.eq_ignore_ascii_case("optimize") {
                    Policy::Optimize(b)
                } else {
                    Policy::Partial(b)
                }),
                _ => Err(bad("the share must be a number in (0, 1]")),
            },
            ("periodic", Some(a)) => match a.parse::<u32>() {
                Ok(n) if n >= 1 => Ok(Policy::Periodic(n)),
                _ => Err(bad("N must be a whole number >= 1")),
            },
            ("threshold", Some(a)) => match a.parse::<f32>() {
                Ok(r) if r >= 1.0 && r.is_finite() => Ok(Policy::Threshold(r)),
                _ => Err(bad("R must be a number >= 1")),
            },
            ("periodic" | "threshold" | "optimize" | "partial", None) => {
                Err(bad("missing argument"))
            }
            (
                "refit" | "rebuild" | "amortized" | "amortized-plain" | "ladder" | "async",
                Some(_),
            ) => Err(bad("takes no argument")),
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
    /// Refitted, then optimised.
    Optimize,
    /// Refitted, then partly rebuilt.
    Partial,
    /// Rebuilt (possibly after a refit that measured the degradation).
    Rebuild,
    /// Refitted, and a rebuild started in the background.
    #[serde(rename = "async-start")]
    AsyncStart,
    /// The background rebuild's tree swapped in and refitted.
    #[serde(rename = "async-swap")]
    AsyncSwap,
    /// Back to the tree the last rebuild replaced, refitted (a rebuild on probation that did
    /// not pay).
    Back,
}

impl From<Decision> for Action {
    fn from(d: Decision) -> Self {
        match d {
            Decision::Refit => Action::Refit,
            Decision::Optimize(_) => Action::Optimize,
            Decision::Partial(_) => Action::Partial,
            Decision::Rebuild => Action::Rebuild,
            Decision::Background => Action::AsyncStart,
        }
    }
}

impl Action {
    /// Lower-case name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Action::None => "none",
            Action::Refit => "refit",
            Action::Optimize => "optimize",
            Action::Partial => "partial",
            Action::Rebuild => "rebuild",
            Action::AsyncStart => "async-start",
            Action::AsyncSwap => "async-swap",
            Action::Back => "back",
        }
    }
}

/// Per-mesh state a policy decides on.
#[derive(Clone, Copy, Debug)]
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
    /// How much of the estimated degradation (`fresh ratio - 1`) a rebuild actually recovered,
    /// learnt at every rebuild that followed a refit (the refitted tree's cost over the new
    /// tree's is the true fresh ratio at that frame); starts at 1.
    pub estimate_gain: f32,
    /// Factor on the rebuild cost the extra trace time must pass: doubled by each rebuild that
    /// did not pay for itself (the tree it replaced, refitted alongside, turned out better
    /// before the new one had saved its cost), halved towards 1 by each that did.
    pub rebuild_scale: f64,
    /// Rebuilds the ray-work measure has learnt `estimate_gain` from.
    pub ray_calibrations: u32,
    /// The intermediate rungs: optimise, partial rebuild.
    pub rungs: [RungModel; 2],
    /// The extra trace time the last frame's degradation added (ms): what an action that
    /// removes it saves each frame from now on.
    pub frame_extra_ms: f64,
    /// The last sampled frame's degradation (ray-work measure): its ratio less 1, times
    /// `estimate_gain`.
    pub frame_degradation: f64,
    /// How fast the sampled frames' extra trace time grows, ms a frame per frame: the lesser
    /// of its growth since the last sampled frame and its mean growth since the build (0 when
    /// it does not grow).
    pub frame_growth_ms: f64,
    /// Frames `extra_ms` has been counted over (since the last build, or since a rejected
    /// trial or a rung restarted the count).
    pub extra_frames: u32,
    /// Frames the run still traces, this one included (`None`: open-ended; see
    /// [`super::Engine::plan_frames`]). An action is taken only if it pays for itself within
    /// them.
    pub frames_left: Option<u64>,
    /// The last rebuild while it is being judged (ray-work measure): whether the trace time
    /// it saves against the replaced tree's degradation pays for it.
    pub payback: Option<Payback>,
    /// Rebuilds made every frame because they cost next to nothing against the mesh's trace
    /// ([`PolicyState::after_refit_sampled`]), and the trials that check them.
    pub routine: Routine,
    /// What the last rebuild's replays cost (ms, part of `rebuild_ms`).
    pub replay_ms: f64,
    /// The frames the mesh's rays are sampled on.
    pub watch: Watch,
    /// Frames traced without a sample since the last sampled one.
    pub unsampled: u32,
    /// Under [`Policy::Async`]: what waiting for a background build would cost
    /// ([`PolicyState::expect_background`]).
    pub background: Outlook,
}

/// A rebuild being judged by what it saved: each frame the new tree's extra trace time is
/// compared with the replaced tree's just before the rebuild (assumed to stay at that level).
/// It paid once the savings reach its cost; it failed if the new tree is as degraded as the
/// old one was before they do (a tree built at an unusual pose can refit worse over the rest
/// of a clip than the one it replaced).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Payback {
    /// The replaced tree's extra trace time per frame when it was replaced, ms.
    pub level_ms: f64,
    /// What the rebuild cost, ms.
    pub cost_ms: f64,
    /// Savings so far, ms.
    pub saved_ms: f64,
    /// Frames judged.
    pub frames: u32,
}

/// Under [`Policy::Async`], this frame: how many frames a background build started now would
/// take to arrive, whether one is already on its way, and the frame's extra trace time by the
/// SAH's ratio to the last build (ms), beside the chosen measure's.
#[derive(Clone, Copy, Debug, Default)]
pub struct Outlook {
    /// Frames until a build started now is swapped in.
    pub lag: f64,
    /// A build of this mesh is running.
    pub running: bool,
    /// The frame's extra trace time by the SAH's ratio to the last build, ms.
    pub sah_extra_ms: f64,
}

impl Default for PolicyState {
    fn default() -> Self {
        Self {
            build_sah: 0.0,
            build_estimate: 0.0,
            since_build: 0,
            extra_ms: 0.0,
            rebuild_ms: 0.0,
            trace_share_ms: 0.0,
            traced_ratio: 1.0,
            estimate_gain: 1.0,
            rebuild_scale: 1.0,
            ray_calibrations: 0,
            rungs: [
                RungModel {
                    cost_ms: f64::INFINITY,
                    recovery: 0.3,
                    runs: 0,
                },
                RungModel {
                    cost_ms: f64::INFINITY,
                    recovery: 0.6,
                    runs: 0,
                },
            ],
            frame_extra_ms: 0.0,
            frame_degradation: 0.0,
            frame_growth_ms: 0.0,
            extra_frames: 0,
            frames_left: None,
            payback: None,
            routine: Routine::default(),
            replay_ms: 0.0,
            watch: Watch::default(),
            unsampled: 0,
            background: Outlook::default(),
        }
    }
}

impl PolicyState {
    /// Decides before refitting: [`Decision::Rebuild`] without refitting,
    /// [`Decision::Refit`] only, `None` refit then ask [`PolicyState::after_refit`].
    #[must_use]
    pub fn before_refit(&self, policy: Policy) -> Option<Decision> {
        let rebuild = |yes| {
            Some(if yes {
                Decision::Rebuild
            } else {
                Decision::Refit
            })
        };
        match policy {
            Policy::Refit => rebuild(false),
            Policy::Rebuild => rebuild(true),
            Policy::Periodic(n) => rebuild(self.since_build + 1 >= n),
            Policy::Threshold(_)
            | Policy::Amortized
            | Policy::AmortizedPlain
            | Policy::Optimize(_)
            | Policy::Partial(_)
            | Policy::Ladder
            | Policy::Async => None,
        }
    }

    /// True when the policy decides on the fresh ratio (so the engine must estimate it).
    #[must_use]
    pub fn needs_fresh_ratio(policy: Policy) -> bool {
        matches!(
            policy,
            Policy::Amortized
                | Policy::Optimize(_)
                | Policy::Partial(_)
                | Policy::Ladder
                | Policy::Async
        )
    }

    /// True when the policy reads the ray-work sample (its ratios, or the meshes' shares of the
    /// trace it weighs an action's cost against); the fixed schedules do not.
    #[must_use]
    pub fn reads_sample(policy: Policy) -> bool {
        !matches!(
            policy,
            Policy::Refit | Policy::Rebuild | Policy::Periodic(_)
        )
    }

    /// True when the policy keeps the tree a rebuild replaced and refits it alongside until
    /// the rebuild has paid for itself, going back to it if it turns out better (and learning
    /// from it: [`PolicyState::rebuild_failed`]).
    #[must_use]
    pub fn probes_rebuilds(policy: Policy) -> bool {
        matches!(policy, Policy::Amortized)
    }

    /// Decides after a refit that gave last-build SAH ratio `ratio` and fresh ratio `fresh`:
    /// true to rebuild. Updates the accumulated extra trace time of [`Policy::Amortized`] and
    /// [`Policy::AmortizedPlain`].
    pub fn after_refit(&mut self, policy: Policy, ratio: f32, fresh: f32) -> Decision {
        match policy {
            Policy::Threshold(r) => rebuild_if(ratio > r),
            Policy::AmortizedPlain => {
                self.extra_ms += self.trace_share_ms * f64::from(ratio - 1.0).max(0.0);
                rebuild_if(self.extra_ms > self.rebuild_ms)
            }
            Policy::Amortized
            | Policy::Optimize(_)
            | Policy::Partial(_)
            | Policy::Ladder
            | Policy::Async => {
                let fresh_ms = self.trace_share_ms / f64::from(self.traced_ratio.max(1e-6));
                let degradation = f64::from(self.estimate_gain) * f64::from(fresh - 1.0).max(0.0);
                self.frame_extra_ms = fresh_ms * degradation;
                self.extra_ms += self.frame_extra_ms;
                self.choose(policy)
            }
            _ => Decision::Refit,
        }
    }

    /// The amortized rule over the policy's actions: each action `a` wins back a share
    /// `recovery(a)` of the extra trace time degradation costs (1 for a rebuild) at a cost
    /// `cost(a)`; once `recovery(a) * extra > cost(a)` for some action, take the one with the
    /// largest `recovery * extra - cost`. `extra` is the time lost since the last build, or,
    /// under an evident degradation, what the present frame's loss comes to over as many
    /// frames again ([`PolicyState::forward_ms`]). With a known end of the run, an action must
    /// also pay for itself before it: `recovery(a) * frame_extra * frames_left > cost(a)`
    /// (what it saves each frame, were the degradation to stay as it is, over the frames left).
    fn choose(&self, policy: Policy) -> Decision {
        let (options, n) = self.options(policy);
        let mut best = (Decision::Refit, 0.0);
        let basis = self.extra_ms.max(self.forward_ms());
        for &(d, recovery, cost) in &options[..n] {
            let won = match self.frames_left {
                Some(left) => basis.min(self.frame_extra_ms * left as f64),
                None => basis,
            };
            let net = recovery * won - cost;
            if net > best.1 {
                best = (d, net);
            }
        }
        match (policy, best.0) {
            (Policy::Async, Decision::Rebuild) if self.background.running => Decision::Refit,
            (Policy::Async, Decision::Rebuild) if self.waiting_pays() => Decision::Background,
            (_, d) => d,
        }
    }

    /// Under a sampled degradation of at least [`FORWARD_DEGRADATION`] (the ray-work measure),
    /// what the tree is taken to lose over as many frames again as the loss has been counted
    /// over (the tree's age, unless a rejected trial restarted the count): the frame's extra
    /// trace time each frame, growing as fast as it has been growing (`frame_growth_ms`).
    /// The sum of the past losses, the amortized rule's measure, is as large only while the
    /// degradation holds steady; while it grows, as an explosion's does, the sum lags its
    /// present level and the rule rebuilds late (in the limit the classic rule's factor of two
    /// against the best schedule). Below the bound a sampled ratio is mostly noise, and noise
    /// times the age would pass for degradation; 0 there.
    fn forward_ms(&self) -> f64 {
        if self.frame_degradation >= FORWARD_DEGRADATION {
            let n = f64::from(self.extra_frames.max(1));
            self.frame_extra_ms * n + self.frame_growth_ms * n * (n + 1.0) * 0.5
        } else {
            0.0
        }
    }

    /// A background rebuild keeps the degraded tree for [`Outlook::lag`] more frames: worth
    /// it unless those frames' extra trace time, at the present degradation by the lesser of
    /// the two measures, passes a synchronous rebuild's cost. Both must agree, so that one
    /// measure's overestimate does not bring the spike back; what they agree on is the
    /// evident case, a tree that degrades many times over within the lag (an explosion's
    /// first tree, `docs/ladder.md`).
    fn waiting_pays(&self) -> bool {
        let per_frame = self.frame_extra_ms.min(self.background.sah_extra_ms);
        self.background.lag * per_frame <= self.rebuild_ms
    }

    /// Before deciding under [`Policy::Async`]: a build started now arrives `lag` frames
    /// later, one is `running` already, and the tree's SAH ratio to its build is `sah_ratio`.
    pub fn expect_background(&mut self, lag: f64, running: bool, sah_ratio: f32) {
        let fresh_ms = self.trace_share_ms / f64::from(self.traced_ratio.max(1e-6));
        self.background = Outlook {
            lag,
            running,
            sah_extra_ms: fresh_ms * f64::from(sah_ratio - 1.0).max(0.0),
        };
    }

    /// The actions the amortized rule weighs under `policy`, each with its recovery and cost
    /// (the first `n` of the array).
    fn options(&self, policy: Policy) -> ([(Decision, f64, f64); 3], usize) {
        let rebuild = (Decision::Rebuild, 1.0, self.rebuild_ms * self.rebuild_scale);
        let rung = |d: Decision| {
            let m = self.rungs[d.rung().unwrap_or(0)];
            (d, f64::from(m.recovery), m.cost_ms)
        };
        match policy {
            Policy::Optimize(b) => ([rung(Decision::Optimize(b)), rebuild, rebuild], 1),
            Policy::Partial(b) => ([rung(Decision::Partial(b)), rebuild, rebuild], 1),
            Policy::Ladder => (
                [
                    rung(Decision::Optimize(LADDER_OPTIMIZE)),
                    rung(Decision::Partial(LADDER_PARTIAL)),
                    rebuild,
                ],
                3,
            ),
            _ => ([rebuild, rebuild, rebuild], 1),
        }
    }

    /// After a decision that read a fresh sample (ray-work measure): plans the frames the
    /// mesh's rays can go without one ([`Watch`]): the room is the extra trace time still
    /// missing before the cheapest action is due (a rebuild at its own cost, not the bar failed
    /// rebuilds have raised: the next rebuild that pays lowers it again), the rate twice the
    /// last frame's extra and at least [`MIN_PLANNED_DEGRADATION`] of the frame's whole trace
    /// `frame_ms` (the mesh's own share, from the entries of a few sampled rays, can read
    /// next to nothing on one frame and most of the trace on the next). `needed`, a rebuild
    /// being judged and rebuilds within twice the routine share of the frame's trace sample
    /// this frame whatever the room.
    pub fn plan_sample(&mut self, policy: Policy, needed: bool, frame_ms: f64, sah_ratio: f32) {
        let (options, n) = self.options(policy);
        let due = options[..n]
            .iter()
            .map(|&(d, recovery, cost)| match d {
                Decision::Rebuild => self.rebuild_ms,
                _ => cost / recovery.max(1e-6),
            })
            .fold(f64::INFINITY, f64::min);
        let rate = (2.0 * self.frame_extra_ms).max(MIN_PLANNED_DEGRADATION * frame_ms);
        let near_routine =
            self.rebuild_ms - self.replay_ms < 2.0 * ROUTINE_REBUILD_SHARE * frame_ms;
        self.watch.plan(
            needed || near_routine || self.payback.is_some(),
            due - self.extra_ms.max(self.forward_ms()),
            rate,
            self.since_build,
            sah_ratio,
        );
    }

    /// [`PolicyState::after_refit`] under the ray-work measure, whose degradation `raw` is a
    /// sampled ratio with noise either side of the truth: `amortized` sums the extra trace time
    /// with its sign (kept at or above zero), so that noise cancels instead of adding up as if
    /// it were degradation. `judged` is what `threshold` compares.
    pub fn after_refit_sampled(&mut self, policy: Policy, judged: f32, raw: f32) -> Decision {
        match policy {
            Policy::Amortized
            | Policy::Optimize(_)
            | Policy::Partial(_)
            | Policy::Ladder
            | Policy::Async => {
                let fresh_ms = self.trace_share_ms / f64::from(self.traced_ratio.max(1e-6));
                let degradation = f64::from(self.estimate_gain) * f64::from(raw - 1.0);
                let last = self.frame_extra_ms;
                let before = self.frame_degradation;
                self.frame_degradation = degradation;
                self.frame_extra_ms = fresh_ms * degradation;
                // The frames traced without a sample since the last one: between the two
                // sampled frames' extra times.
                let gap = f64::from(std::mem::take(&mut self.unsampled));
                // The lesser of the two growths: a noisy sample's jump alone does not make a
                // tree that has degraded slowly since its build look like an explosion.
                let recent = (degradation - before) / (gap + 1.0);
                let mean = degradation / f64::from(self.since_build.max(1));
                self.frame_growth_ms = fresh_ms * recent.min(mean).max(0.0);
                let filled = gap * 0.5 * (last + self.frame_extra_ms);
                self.extra_ms = (self.extra_ms + filled + self.frame_extra_ms).max(0.0);
                self.extra_frames += gap as u32 + 1;
                self.judge_payback();
                let cheap = matches!(policy, Policy::Amortized | Policy::Ladder)
                    && self.rebuild_ms - self.replay_ms < ROUTINE_REBUILD_SHARE * fresh_ms;
                if self.routine.decide(cheap) {
                    return Decision::Rebuild;
                }
                self.choose(policy)
            }
            _ => self.after_refit(policy, judged, raw),
        }
    }

    /// A frame in a sampling gap ([`Watch`]; ray-work measure): nothing new to weigh, so the
    /// last sampled frame's decision to refit stands (the gap was planned so that no action
    /// can become due in it; an action is only ever taken on a fresh sample, which its trial
    /// replays). The frame's extra trace time is counted at the next sampled frame, between
    /// the ratios on either side: carrying the last one forward would count a passing
    /// degradation for every frame of the gap.
    pub fn after_refit_unsampled(&mut self) -> Decision {
        self.unsampled += 1;
        Decision::Refit
    }

    /// Starts judging the rebuild just made (cost `cost_ms`) against the degradation the
    /// replaced tree had, `level_ms` of extra trace time a frame.
    pub fn judge_rebuild(&mut self, level_ms: f64, cost_ms: f64) {
        self.payback = (level_ms > 0.0 && cost_ms > 0.0).then_some(Payback {
            level_ms,
            cost_ms,
            saved_ms: 0.0,
            frames: 0,
        });
    }

    /// One more frame of the rebuild being judged: paid once its savings reach its cost,
    /// failed once the new tree is as degraded as the old one was.
    fn judge_payback(&mut self) {
        let Some(p) = &mut self.payback else { return };
        p.frames += 1;
        p.saved_ms += p.level_ms - self.frame_extra_ms;
        if p.saved_ms >= p.cost_ms {
            self.payback = None;
            self.rebuild_paid();
        } else if p.frames >= PAYBACK_MIN_FRAMES && self.frame_extra_ms >= p.level_ms {
            self.payback = None;
            self.rebuild_failed();
        }
    }

    /// After an intermediate rung ran: the extra trace time counts afresh (from a tree that
    /// is as degraded as the rung left it).
    pub fn restructured(&mut self) {
        self.extra_ms = 0.0;
        self.extra_frames = 0;
    }

    /// Learns from a rebuild that followed a refit: the fresh ratio was estimated at
    /// `estimated`, and the refitted tree's cost over the rebuilt one's is `measured`. The
    /// estimate's gain factor moves halfway towards what this rebuild showed (within 0 ..= 2).
    pub fn calibrate(&mut self, estimated: f32, measured: f32) {
        if estimated > 1.0 + 1e-3 && measured.is_finite() {
            let seen = ((measured - 1.0) / (estimated - 1.0)).clamp(0.0, 2.0);
            self.estimate_gain = 0.5 * (self.estimate_gain + seen);
        }
    }

    /// Learns from a rebuild under the ray-work measure: the fresh SAH ratio was estimated at
    /// `estimated`, and the replaced tree's sampled work over the new tree's, on the same rays,
    /// is `measured`. The gain becomes the share of the SAH's estimated degradation the rays
    /// felt: the first measurement replaces the prior of 1, later ones are averaged in with
    /// weight `max(1 / (n + 1), 0.3)` (so it follows a change within a few rebuilds).
    pub fn calibrate_rays(&mut self, estimated: f32, measured: f32) {
        // A small estimated degradation says nothing about the gain (the replay's ratio is
        // then mostly the sample's noise): learn only from clear ones, or from a replay that
        // itself shows a clear degradation the estimate missed (a small mesh's few entries,
        // whose ratio was held near the SAH's), taking the estimate's as at least the signal.
        let clear = estimated > 1.0 + MIN_RAY_SIGNAL || measured > 1.0 + MIN_RAY_SHOWN;
        if clear && measured.is_finite() {
            let seen = ((measured - 1.0) / (estimated - 1.0).max(MIN_RAY_SIGNAL))
                .clamp(MIN_RAY_GAIN, MAX_RAY_GAIN);
            let w = (1.0 / (self.ray_calibrations as f32 + 1.0)).max(0.3);
            self.estimate_gain += w * (seen - self.estimate_gain);
            self.ray_calibrations += 1;
        }
    }

    /// Learns that a rebuild did not pay for itself: the next must be expected to save twice as
    /// much.
    pub fn rebuild_failed(&mut self) {
        self.rebuild_scale = (self.rebuild_scale * 2.0).min(MAX_REBUILD_SCALE);
    }

    /// Learns from a trial rebuild undone because its tree did worse on the replayed rays than
    /// the refitted one (`cost_ms` spent for nothing): the extra trace time counts afresh, and
    /// the next rebuild must be expected to save twice as much ([`PolicyState::rebuild_failed`]),
    /// unless it was a routine rebuild's check: those hold their own rebuilds off
    /// ([`Routine::record_check`]), and a fresh tree no better than the refitted one at one
    /// frame says nothing of what a rebuild for a later degradation would save (raising the
    /// bar for it kept such rebuilds from being made: `docs/ray_work.md`).
    pub fn rebuild_rejected(&mut self, cost_ms: f64) {
        self.rebuild_ms = cost_ms;
        self.extra_ms = 0.0;
        self.extra_frames = 0;
        if !self.routine.now {
            self.rebuild_failed();
        }
    }

    /// Learns that a rebuild paid for itself.
    pub fn rebuild_paid(&mut self) {
        self.rebuild_scale = (self.rebuild_scale * 0.5).max(1.0);
    }

    /// Resets after a (re)build of SAH cost `sah` (fresh-build estimate `estimate`, 0 when not
    /// computed) that took `ms`.
    pub fn rebuilt(&mut self, sah: f32, estimate: f32, ms: f64) {
        self.replay_ms = 0.0;
        self.build_sah = sah;
        self.build_estimate = estimate;
        self.since_build = 0;
        self.extra_ms = 0.0;
        self.extra_frames = 0;
        self.frame_degradation = 0.0;
        self.frame_growth_ms = 0.0;
        self.rebuild_ms = ms;
        self.traced_ratio = 1.0;
        self.payback = None;
        self.unsampled = 0;
    }
}

fn rebuild_if(yes: bool) -> Decision {
    if yes {
        Decision::Rebuild
    } else {
        Decision::Refit
    }
}

/// Bound of the ray-work measure's gain: how much more the replays may show than the sampled
/// ratio said (the fresh tree's own work per entry moves while the refitted one degrades).
const MAX_RAY_GAIN: f32 = 8.0;
/// Lower bound of that gain: the sampled ratio is the rays' own measure, so it is never
/// believed to be mostly noise.
const MIN_RAY_GAIN: f32 = 0.25;
/// Estimated degradation below which a replay teaches nothing...
const MIN_RAY_SIGNAL: f32 = 0.05;
/// ...unless the replay itself shows at least this much.
const MIN_RAY_SHOWN: f32 = 0.2;

/// Sampled degradation (ratio less 1) from which [`PolicyState::forward_ms`] projects the
/// frame's loss: half again a fresh tree's work, well clear of a sample's noise (the sweep of
/// this bound is in `docs/ray_work.md`).
const FORWARD_DEGRADATION: f64 = 0.5;

/// Frames a rebuild is judged before it can be found to have failed (the first frames'
/// samples are the noisiest part of the smoothed ratio).
const PAYBACK_MIN_FRAMES: u32 = 2;

/// Bound of [`PolicyState::rebuild_scale`].
const MAX_REBUILD_SCALE: f64 = 64.0;

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
            Policy::AmortizedPlain,
            Policy::Ladder,
            Policy::Async,
        ] {
            assert_eq!(p.to_string().parse::<Policy>().unwrap(), p);
        }
        assert_eq!(
            "Amortized-Plain".parse::<Policy>().unwrap(),
            Policy::AmortizedPlain
        );
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
            "amortized-plain:2",
            "amortized_plain",
            "async:1",
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
            .find(|_| s.after_refit(Policy::Amortized, 1.0, 1.5) == Decision::Rebuild)
            .unwrap();
        assert_eq!(frames, 6);
        // No rays, no reason to rebuild.
        s.rebuilt(1.0, 1.0, 10.0);
        s.trace_share_ms = 0.0;
        assert!(!(0..100).any(|_| s.after_refit(Policy::Amortized, 5.0, 5.0) == Decision::Rebuild));
    }

    /// Feeds `fresh(k)` (the fresh ratio `k` frames after the last build) to the amortized
    /// policy with `trace` ms of tracing per frame and rebuilds of `rebuild` ms; returns the
    /// frames (1-based) it rebuilt at.
    fn amortized_schedule(
        frames: usize,
        trace: f64,
        rebuild: f64,
        fresh: impl Fn(usize) -> f32,
    ) -> Vec<usize> {
        let mut s = PolicyState::default();
        s.rebuilt(1.0, 1.0, rebuild);
        let mut since = 0;
        let mut out = Vec::new();
        for f in 1..=frames {
            since += 1;
            let r = fresh(since);
            // The trace of the previous frame ran at the previous ratio.
            s.trace_share_ms = trace * f64::from(fresh(since - 1));
            s.traced_ratio = fresh(since - 1);
            if s.after_refit(Policy::Amortized, r, r) == Decision::Rebuild {
                s.rebuilt(1.0, 1.0, rebuild);
                since = 0;
                out.push(f);
            }
        }
        out
    }

    #[test]
    fn amortized_rebuilds_when_degradation_times_trace_passes_rebuild_cost() {
        // Degradation 0.1 per frame, 4 ms of fresh tracing: the extra time after k frames is
        // 0.4 k (k + 1) / 2, which first passes 10 ms at k = 7.
        let at = amortized_schedule(21, 4.0, 10.0, |k| 1.0 + 0.1 * k as f32);
        assert_eq!(at, vec![7, 14, 21]);
        // Rebuilds four times as expensive: twice the period (k (k + 1) > 200 at k = 14).
        let at = amortized_schedule(28, 4.0, 40.0, |k| 1.0 + 0.1 * k as f32);
        assert_eq!(at, vec![14, 28]);
        // No degradation: never, however many rays.
        assert!(amortized_schedule(1000, 1e6, 0.001, |_| 1.0).is_empty());
        // A tree that got better than a fresh one (estimate noise): no extra time either.
        assert!(amortized_schedule(1000, 1e6, 0.001, |_| 0.9).is_empty());
    }

    #[test]
    fn amortized_is_near_the_oracle_on_linear_degradation() {
        use crate::engine::oracle::{MeshCosts, best_schedule};
        let n = 60;
        let slope = 0.02f32;
        let c = MeshCosts {
            refit_ms: vec![0.1; n + 1],
            rebuild_ms: vec![5.0; n + 1],
            fresh_trace_ms: vec![8.0; n + 1],
            sah: (0..=n)
                .map(|b| {
                    (b..=n)
                        .map(|f| 10.0 * (1.0 + slope * (f - b) as f32))
                        .collect()
                })
                .collect(),
        };
        let at = amortized_schedule(n, 8.0, 5.0, |k| 1.0 + slope * k as f32);
        let mut rebuild = vec![false; n + 1];
        for f in at {
            rebuild[f] = true;
        }
        let best = best_schedule(&c).cost_ms;
        let ours = c.cost_of(&rebuild);
        assert!(ours <= best * 1.1, "amortized {ours} against oracle {best}");
    }

    #[test]
    fn a_known_end_rules_out_rebuilds_that_cannot_pay_before_it() {
        // Ratio 1.5 from the first frame: 2 ms extra a frame; a 10 ms rebuild passes the
        // amortized bar at the sixth frame, open-ended.
        let run = |left: Option<u64>| {
            let mut s = PolicyState::default();
            s.rebuilt(1.0, 1.0, 10.0);
            s.trace_share_ms = 4.0;
            (1..=10u64).find(|f| {
                s.frames_left = left.map(|n| n.saturating_sub(f - 1));
                s.after_refit_sampled(Policy::Amortized, 1.5, 1.5) == Decision::Rebuild
            })
        };
        assert_eq!(run(None), Some(6));
        // Plenty of frames left: the same frame.
        assert_eq!(run(Some(100)), Some(6));
        // Ten frames in all: at the sixth, 5 frames are left, 2 ms each saves exactly the
        // 10 ms the rebuild costs, which does not pay; nor does any later frame.
        assert_eq!(run(Some(10)), None);
        // Eleven: at the sixth frame six are left (12 ms saved): it pays.
        assert_eq!(run(Some(11)), Some(6));
    }

    /// The first frame (1-based) the sampled amortized rule rebuilds at, with 4 ms of fresh
    /// tracing a frame, rebuilds of `cost` ms and the sampled ratio `ratio(k)` at frame `k`.
    fn sampled_rebuild_at(cost: f64, ratio: impl Fn(u32) -> f32) -> Option<u32> {
        let mut s = PolicyState::default();
        s.rebuilt(1.0, 1.0, cost);
        s.trace_share_ms = 4.0;
        (1..=40).find(|&k| {
            let r = ratio(k);
            s.since_build += 1;
            s.after_refit_sampled(Policy::Amortized, r, r) == Decision::Rebuild
        })
    }

    #[test]
    fn an_evident_growing_degradation_is_rebuilt_before_its_past_loss_reaches_the_cost() {
        // Ratio 1 + k / 2 over a fresh trace of 4: a loss of 2k at frame k, k (k + 1) in all,
        // past the cost of 40 at frame 6; at frame 4 the loss, growing by 2 a frame, comes to
        // 10 + 12 + 14 + 16 = 52 over as many frames again (held flat, 32: frame 5).
        assert_eq!(sampled_rebuild_at(40.0, |k| 1.0 + 0.5 * k as f32), Some(4));
        // A steady degradation: the projection is the past sum, the same frame as before
        // (2 ms a frame passes 10 ms at the sixth).
        assert_eq!(sampled_rebuild_at(10.0, |_| 1.5), Some(6));
        // Below half a fresh tree's work the sum alone decides: 0.16k ms at frame k,
        // 0.08 k (k + 1) in all, past 10 ms at frame 11 (the ratio is then 1.44).
        assert_eq!(
            sampled_rebuild_at(10.0, |k| 1.0 + 0.04 * k as f32),
            Some(11)
        );
    }

    #[test]
    fn a_rebuild_is_judged_by_what_it_saves_against_the_tree_it_replaced() {
        let fresh = |s: &mut PolicyState, ratio: f32| {
            s.trace_share_ms = 4.0;
            s.traced_ratio = 1.0;
            s.after_refit_sampled(Policy::Amortized, ratio, ratio);
        };
        // The replaced tree cost 2 ms extra a frame; the new one none: 2 ms saved a frame, so
        // a 5 ms rebuild has paid after the third frame and lowers the bar.
        let mut s = PolicyState {
            rebuild_scale: 4.0,
            ..PolicyState::default()
        };
        s.rebuilt(1.0, 1.0, 5.0);
        s.judge_rebuild(2.0, 5.0);
        fresh(&mut s, 1.0);
        fresh(&mut s, 1.0);
        assert!(s.payback.is_some());
        fresh(&mut s, 1.0);
        assert!(s.payback.is_none());
        assert_eq!(s.rebuild_scale, 2.0);
        // A new tree as degraded as the old one within two frames: failed, the bar doubles.
        let mut s = PolicyState::default();
        s.rebuilt(1.0, 1.0, 5.0);
        s.judge_rebuild(2.0, 5.0);
        fresh(&mut s, 1.3);
        assert!(s.payback.is_some(), "one frame is not enough to judge");
        fresh(&mut s, 1.6);
        assert!(s.payback.is_none());
        assert_eq!(s.rebuild_scale, 2.0);
        // Nothing to judge without a degraded tree replaced.
        s.judge_rebuild(0.0, 5.0);
        assert!(s.payback.is_none());
    }

    #[test]
    fn a_rebuild_that_costs_next_to_nothing_against_the_trace_is_made_every_frame() {
        let frame = |s: &mut PolicyState, policy: Policy| {
            s.routine.new_frame();
            s.trace_share_ms = 100.0;
            s.traced_ratio = 1.0;
            // The sample sees no degradation at all.
            s.after_refit_sampled(policy, 1.0, 1.0)
        };
        // 1.5 ms against 100 ms of trace: rebuilt every frame, checked after one routine
        // rebuild, then after two while the checks find the fresh trees better.
        let mut s = PolicyState::default();
        for checked in [true, false, true] {
            s.rebuilt(1.0, 1.0, 1.5);
            assert_eq!(frame(&mut s, Policy::Amortized), Decision::Rebuild);
            assert!(s.routine.now);
            assert_eq!(s.routine.checked, checked);
            if checked {
                s.routine.record_check(true);
            }
        }
        assert_eq!(frame(&mut s, Policy::Ladder), Decision::Rebuild);
        // Not under the policies without trials, and not at 6 ms.
        for p in [Policy::Refit, Policy::Async, Policy::Partial(0.25)] {
            s.rebuilt(1.0, 1.0, 1.5);
            assert_ne!(frame(&mut s, p), Decision::Rebuild, "{p}");
            assert!(!s.routine.now);
        }
        s.rebuilt(1.0, 1.0, 6.0);
        assert_eq!(frame(&mut s, Policy::Amortized), Decision::Refit);
        assert!(!s.routine.now);
        // The replays that judged the last rebuild are not part of a routine one's price.
        s.rebuilt(1.0, 1.0, 6.0);
        s.replay_ms = 2.0;
        assert_eq!(frame(&mut s, Policy::Amortized), Decision::Rebuild);
        assert!(s.routine.now);
    }

    #[test]
    fn frames_that_cannot_make_a_rebuild_due_go_unsampled_and_count_between_the_samples() {
        // A 50 ms rebuild against 100 ms of trace a frame; the tree 2% degraded, 20 frames old.
        let mut s = PolicyState::default();
        s.rebuilt(1.0, 1.0, 50.0);
        s.since_build = 20;
        s.trace_share_ms = 100.0;
        s.traced_ratio = 1.02;
        assert_eq!(
            s.after_refit_sampled(Policy::Amortized, 1.02, 1.02),
            Decision::Refit
        );
        let extra = s.extra_ms;
        // The rate planned for is 5% of the frame's trace (above twice the 2% seen): 5 ms a
        // frame against about 48 ms of room: 8 frames before the next sample (the cap too;
        // 9.6 frames of room, less the sampled one). (The SAH ratio was 1.1 on
        // the sampled frame too.)
        s.watch.tick(false, 1.1);
        s.plan_sample(Policy::Amortized, false, 100.0, 1.1);
        let gap: Vec<bool> = (0..10)
            .map(|_| {
                let due = s.watch.due();
                if !due {
                    s.watch.tick(false, 1.1);
                }
                due
            })
            .collect();
        assert_eq!(gap.iter().take_while(|&&d| !d).count(), 8, "{gap:?}");
        // Eight frames without a sample add nothing; the next sampled frame (4% now) adds
        // them at the mean of the extra times on either side, and its own.
        for _ in 0..8 {
            assert_eq!(s.after_refit_unsampled(), Decision::Refit);
        }
        assert_eq!(s.extra_ms, extra);
        let before = s.frame_extra_ms;
        s.after_refit_sampled(Policy::Amortized, 1.04, 1.04);
        let filled = 8.0 * 0.5 * (before + s.frame_extra_ms) + s.frame_extra_ms;
        assert!(
            (s.extra_ms - (extra + filled)).abs() < 1e-9,
            "{}",
            s.extra_ms
        );
        // Near the rebuild's cost, every frame is sampled; so it is for a young tree's first
        // frames, a rebuild being judged, and a rebuild near the routine share.
        s.extra_ms = 48.0;
        s.plan_sample(Policy::Amortized, false, 100.0, 1.1);
        assert!(s.watch.due());
        s.extra_ms = 0.0;
        s.since_build = 1;
        s.plan_sample(Policy::Amortized, false, 100.0, 1.1);
        s.watch.tick(false, 1.1);
        assert!(s.watch.due(), "a tree one frame old: one frame at most");
        s.since_build = 20;
        s.rebuild_ms = 8.0;
        s.plan_sample(Policy::Amortized, false, 100.0, 1.1);
        assert!(s.watch.due(), "within twice the routine share");
    }

    #[test]
    fn failed_rebuilds_raise_the_bar_and_paid_ones_lower_it() {
        let mut s = PolicyState::default();
        s.rebuilt(1.0, 1.0, 10.0);
        s.trace_share_ms = 4.0;
        s.failed_then(2);
        // Four times the rebuild cost: 2 ms extra a frame passes 40 ms at the 21st frame.
        let frames = (1..=40)
            .find(|_| s.after_refit(Policy::Amortized, 1.0, 1.5) == Decision::Rebuild)
            .unwrap();
        assert_eq!(frames, 21);
        s.rebuild_paid();
        assert_eq!(s.rebuild_scale, 2.0);
        s.rebuild_paid();
        s.rebuild_paid();
        assert_eq!(s.rebuild_scale, 1.0);
        s.failed_then(100);
        assert_eq!(s.rebuild_scale, MAX_REBUILD_SCALE);
        // Rebuilding does not forget it.
        s.rebuilt(1.0, 1.0, 10.0);
        assert_eq!(s.rebuild_scale, MAX_REBUILD_SCALE);
    }

    #[test]
    fn a_routine_check_that_finds_no_gain_leaves_the_bar_where_it_was() {
        let mut s = PolicyState::default();
        s.rebuilt(1.0, 1.0, 10.0);
        // A trial the amortized rule made, undone: the next must save twice as much.
        s.extra_ms = 30.0;
        s.rebuild_rejected(12.0);
        assert_eq!(
            (s.rebuild_scale, s.rebuild_ms, s.extra_ms),
            (2.0, 12.0, 0.0)
        );
        // A routine rebuild's check, undone: the routine holds its rebuilds off by its own
        // rule, and the amortized rule's bar stays.
        assert!(s.routine.decide(true) && s.routine.checked);
        s.extra_ms = 5.0;
        s.rebuild_rejected(11.0);
        assert_eq!(
            (s.rebuild_scale, s.rebuild_ms, s.extra_ms),
            (2.0, 11.0, 0.0)
        );
    }

    impl PolicyState {
        fn failed_then(&mut self, n: usize) {
            for _ in 0..n {
                self.rebuild_failed();
            }
        }
    }

    /// Runs the plain rule over `ratios` (the last-build SAH ratio after each frame's refit,
    /// counted from the last build; a rebuild restarts the list), with `trace(k)` the trace
    /// time recorded before frame `k` (1-based) and rebuilds costing `rebuild` ms; returns the
    /// frames it rebuilt at.
    fn plain_schedule(
        frames: usize,
        rebuild: f64,
        trace: impl Fn(usize) -> f64,
        ratio: impl Fn(usize) -> f32,
    ) -> Vec<usize> {
        let mut s = PolicyState::default();
        s.rebuilt(1.0, 0.0, rebuild);
        let mut since = 0;
        let mut out = Vec::new();
        for f in 1..=frames {
            assert_eq!(s.before_refit(Policy::AmortizedPlain), None);
            since += 1;
            s.trace_share_ms = trace(f);
            if s.after_refit(Policy::AmortizedPlain, ratio(since), 0.0) == Decision::Rebuild {
                s.rebuilt(1.0, 0.0, rebuild);
                since = 0;
                out.push(f);
            }
        }
        out
    }

    #[test]
    fn amortized_plain_is_the_issues_rule() {
        // SAH ratio 1 + 0.1 k after k refits, 4 ms of tracing: the extra time after k frames is
        // 0.4 k (k + 1) / 2 ms, which first exceeds a 10 ms rebuild at k = 7 (11.2 ms; 8.4 ms
        // at k = 6), and the sum restarts after each rebuild.
        let linear = |k: usize| 1.0 + 0.1 * k as f32;
        assert_eq!(plain_schedule(21, 10.0, |_| 4.0, linear), vec![7, 14, 21]);
        // Exceeds, not reaches: a constant ratio of 1.5 with 4 ms adds 2 ms a frame, so 10 ms
        // is reached at frame 5 and exceeded at frame 6.
        assert_eq!(plain_schedule(12, 10.0, |_| 4.0, |_| 1.5), vec![6, 12]);
        // Four times dearer rebuilds: twice the period (0.2 k (k + 1) > 40 at k = 14).
        assert_eq!(plain_schedule(28, 40.0, |_| 4.0, linear), vec![14, 28]);
        // Twice the rays: twice the extra time a frame, so rebuilds come sooner (k = 5: 12 ms).
        assert_eq!(plain_schedule(10, 10.0, |_| 8.0, linear), vec![5, 10]);
        // Adapts to the rays frame by frame: no tracing for 10 frames, then 4 ms. The first
        // frames add nothing however degraded the tree.
        let at = plain_schedule(20, 10.0, |f| if f <= 10 { 0.0 } else { 4.0 }, linear);
        // From frame 11 on: ratio 1 + 0.1 k at k = 11, 12, 13 adds 4.4, 4.8, 5.2 ms; then
        // from the rebuild on as above, 7 frames.
        assert_eq!(at, vec![13, 20]);
        // No degradation, or a tree better than at its build: never.
        assert!(plain_schedule(1000, 0.001, |_| 1e6, |_| 1.0).is_empty());
        assert!(plain_schedule(1000, 0.001, |_| 1e6, |_| 0.9).is_empty());
        // No rays: never.
        assert!(plain_schedule(1000, 0.001, |_| 0.0, |_| 5.0).is_empty());
    }

    #[test]
    fn amortized_plain_ignores_the_defaults_refinements() {
        // The fresh ratio, the estimate's gain and the rebuild scale play no part, it refits
        // first, and it neither estimates nor probes.
        let mut s = PolicyState::default();
        s.rebuilt(1.0, 1.0, 10.0);
        s.trace_share_ms = 4.0;
        s.estimate_gain = 0.1;
        s.rebuild_scale = 64.0;
        s.traced_ratio = 3.0;
        let frames = (1..=40)
            .find(|_| s.after_refit(Policy::AmortizedPlain, 1.5, 9.0) == Decision::Rebuild)
            .unwrap();
        assert_eq!(frames, 6);
        assert!(Policy::AmortizedPlain.refits_first());
        assert!(!PolicyState::needs_fresh_ratio(Policy::AmortizedPlain));
        assert!(!PolicyState::probes_rebuilds(Policy::AmortizedPlain));
        // The same frames with the default policy: its estimate (fresh ratio 9) and the scale
        // decide instead.
        let mut d = PolicyState::default();
        d.rebuilt(1.0, 1.0, 10.0);
        d.trace_share_ms = 4.0;
        assert_eq!(
            d.after_refit(Policy::Amortized, 1.5, 9.0),
            Decision::Rebuild
        );
    }

    #[test]
    fn calibration_scales_the_estimated_degradation() {
        let mut s = PolicyState::default();
        assert_eq!(s.estimate_gain, 1.0);
        // Estimated 1.2, a rebuild recovered only 1.1: half as much as estimated.
        s.calibrate(1.2, 1.1);
        assert!((s.estimate_gain - 0.75).abs() < 1e-6);
        // Rebuilding survives: the gain is not reset.
        s.rebuilt(1.0, 1.0, 10.0);
        assert!((s.estimate_gain - 0.75).abs() < 1e-6);
        // No estimated degradation: nothing learnt.
        s.calibrate(1.0, 1.5);
        assert!((s.estimate_gain - 0.75).abs() < 1e-6);
        // Bounded.
        for _ in 0..20 {
            s.calibrate(1.01, 9.0);
        }
        assert!(s.estimate_gain <= 2.0);
    }

    #[test]
    fn a_replay_teaches_the_rays_gain_when_it_or_the_estimate_is_clear() {
        // Estimated 1.1, the replay showed 1.2: the rays felt twice the estimate.
        let mut s = PolicyState::default();
        s.calibrate_rays(1.1, 1.2);
        assert!((s.estimate_gain - 2.0).abs() < 1e-5, "{}", s.estimate_gain);
        // An estimate within the noise and a replay within it too: nothing learnt.
        let mut s = PolicyState::default();
        s.calibrate_rays(1.02, 1.1);
        assert_eq!(s.estimate_gain, 1.0);
        // An estimate within the noise (a small mesh's few entries reading 1), but a replay
        // of 1.4, a clear degradation: learnt, the estimate's degradation taken as the
        // signal's floor (0.4 / 0.05 = 8, the bound).
        s.calibrate_rays(1.0, 1.4);
        assert!(
            (s.estimate_gain - MAX_RAY_GAIN).abs() < 1e-5,
            "{}",
            s.estimate_gain
        );
        // A later clear estimate pulls it back by its weight.
        s.calibrate_rays(1.2, 1.2);
        assert!(s.estimate_gain < MAX_RAY_GAIN && s.estimate_gain > 1.0);
    }

    #[test]
    fn a_background_rebuild_gives_way_when_both_measures_say_waiting_costs_more() {
        // The rule has made a rebuild due (the extra trace time twice the rebuild's cost); a
        // build started now arrives after as many frames as a rebuild costs fresh frames.
        let decide = |fresh: f32, sah: f32, running: bool| {
            let mut s = PolicyState {
                rebuild_ms: 100.0,
                trace_share_ms: 10.0,
                extra_ms: 200.0,
                ..PolicyState::default()
            };
            s.expect_background(10.0, running, sah);
            s.after_refit(Policy::Async, sah, fresh)
        };
        // Slow degradation: the lag's extra trace time by the lesser measure is half a rebuild.
        assert_eq!(decide(2.0, 1.5, false), Decision::Background);
        // Both measures read the tree 29 times worse: waiting would cost 29 rebuilds.
        assert_eq!(decide(30.0, 30.0, false), Decision::Rebuild);
        // One measure alone reading it so does not bring the spike back.
        assert_eq!(decide(2.0, 30.0, false), Decision::Background);
        assert_eq!(decide(30.0, 1.5, false), Decision::Background);
        // A build already on its way is waited for, not doubled by a synchronous one.
        assert_eq!(decide(30.0, 30.0, true), Decision::Refit);
        assert_eq!(decide(2.0, 1.5, true), Decision::Refit);
        // The amortized rule itself is unchanged: not due, no action.
        let mut s = PolicyState {
            rebuild_ms: 100.0,
            trace_share_ms: 10.0,
            ..PolicyState::default()
        };
        s.expect_background(10.0, false, 30.0);
        assert_eq!(s.after_refit(Policy::Async, 30.0, 1.01), Decision::Refit);
    }
}
