//! Rebuilds made every frame because a rebuild costs under [`ROUTINE_REBUILD_SHARE`] of the
//! mesh's trace (under the ray-work measure, for `amortized` and the ladder): against refitting
//! such a rebuild can lose little more than that share a frame, where any degradation above it
//! pays, and the sampled ratio does not resolve degradations that small.
//!
//! Whether a fresh tree does better at all is checked by trials (the last frame's sampled rays
//! replayed on both trees, the new one dropped if worse), spaced out while they keep finding
//! it better (a check after 1, 2, 4, ... routine rebuilds, up to [`MAX_ROUTINE_GAP`]); the
//! unchecked ones pay no replay. Two checks in a row that find it no better hold routine
//! rebuilds off for 2, 4, ... frames: a builder can do worse at every pose than the first tree
//! refitted, while a single check can misjudge (it replays the last frame's rays, not this
//! frame's). The cases and sweeps behind these rules: `docs/ray_work.md`.

/// The share of a mesh's trace a frame under which its rebuild is made every frame.
pub const ROUTINE_REBUILD_SHARE: f64 = 0.05;

/// Most routine rebuilds between two checks, and the longest hold after failed ones.
pub const MAX_ROUTINE_GAP: u32 = 16;

/// One mesh's routine rebuilds: when they are made, and which of them are checked.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Routine {
    /// This frame's rebuild is routine.
    pub now: bool,
    /// It is a check: made as a trial.
    pub checked: bool,
    /// Routine rebuilds from one check to the next.
    gap: u32,
    /// Routine rebuilds since the last check.
    since_check: u32,
    /// Frames left without routine rebuilds.
    hold: u32,
    /// The next hold's length.
    backoff: u32,
    /// Checks in a row that found the fresh tree no better.
    failed: u32,
}

impl Default for Routine {
    fn default() -> Self {
        Self {
            now: false,
            checked: false,
            gap: 1,
            since_check: 0,
            hold: 0,
            backoff: 2,
            failed: 0,
        }
    }
}

impl Routine {
    /// A new frame: nothing decided yet (a decision made before the refit never asks
    /// [`Routine::decide`], and must not read the last frame's).
    pub fn new_frame(&mut self) {
        self.now = false;
        self.checked = false;
    }

    /// One frame: true to rebuild routinely, when a rebuild is `cheap` and none is held off.
    pub fn decide(&mut self, cheap: bool) -> bool {
        self.new_frame();
        if self.hold > 0 {
            self.hold -= 1;
            return false;
        }
        if cheap {
            self.now = true;
            self.since_check += 1;
            self.checked = self.since_check >= self.gap;
        }
        self.now
    }

    /// The outcome of a check: the fresh tree did better on the replay (`gained`), or not.
    pub fn record_check(&mut self, gained: bool) {
        self.since_check = 0;
        if gained {
            self.failed = 0;
            self.gap = (self.gap * 2).min(MAX_ROUTINE_GAP);
        } else {
            self.failed += 1;
            self.gap = 1;
            if self.failed >= 2 {
                self.hold = self.backoff;
                self.backoff = (self.backoff * 2).min(MAX_ROUTINE_GAP);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs `frames` frames with rebuilds always cheap; `gains(k)` is what the `k`-th check
    /// finds. Returns, per frame, `None` (no routine rebuild), `Some(false)` (unchecked) or
    /// `Some(true)` (checked).
    fn run(frames: usize, gains: impl Fn(usize) -> bool) -> Vec<Option<bool>> {
        let mut r = Routine::default();
        let mut checks = 0;
        (0..frames)
            .map(|_| {
                if !r.decide(true) {
                    return None;
                }
                if r.checked {
                    r.record_check(gains(checks));
                    checks += 1;
                }
                Some(r.checked)
            })
            .collect()
    }

    #[test]
    fn checks_space_out_while_fresh_trees_keep_doing_better() {
        let seen = run(40, |_| true);
        assert!(seen.iter().all(Option::is_some), "never held off: {seen:?}");
        let checked: Vec<usize> = (0..40).filter(|&f| seen[f] == Some(true)).collect();
        // After 1, 2, 4, 8, 16, 16 routine rebuilds.
        assert_eq!(checked, vec![0, 2, 6, 14, 30]);
    }

    #[test]
    fn fresh_trees_no_better_hold_routine_rebuilds_off_ever_longer() {
        let seen = run(40, |_| false);
        let rebuilt: Vec<usize> = (0..40).filter(|&f| seen[f].is_some()).collect();
        // Every routine rebuild is checked; from the second failure on, holds of 2, 4, 8, 16.
        assert!(rebuilt.iter().all(|&f| seen[f] == Some(true)));
        assert_eq!(rebuilt, vec![0, 1, 4, 9, 18, 35]);
        // One failure alone holds nothing off, and a gain clears the count.
        let seen = run(12, |k| k % 2 == 1);
        assert!(seen.iter().all(Option::is_some), "{seen:?}");
    }

    #[test]
    fn nothing_is_routine_while_rebuilds_are_dear() {
        let mut r = Routine::default();
        for _ in 0..5 {
            assert!(!r.decide(false));
            assert!(!r.now && !r.checked);
        }
        // The first cheap one is checked.
        assert!(r.decide(true) && r.checked);
    }
}
