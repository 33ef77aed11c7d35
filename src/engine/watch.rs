//! Which frames a mesh's rays are sampled on (the ray-work measure, for the amortized rule and
//! the ladder). The sample costs a share of every frame it is taken in, and it only matters
//! while an action could become due: after each frame that brought a sample, the policy knows
//! the room left before its cheapest action is due (what the action costs, less the extra trace
//! time counted so far) and bounds how fast that extra grows; the frames that cannot make the
//! action due are traced without a sample, at most [`MAX_SAMPLE_GAP`] in a row; the mesh is
//! refitted on them, and their extra trace time is counted at the next sample, between the
//! degradations sampled on either side. A rise of the refitted tree's SAH ratio (known after
//! every refit, at no cost) ends a gap early, as does anything the policy needs a fresh sample
//! for (a new tree's reference, a rebuild being judged, routine rebuilds).

/// Most frames in a row traced without a sample.
pub const MAX_SAMPLE_GAP: u32 = 8;

/// The least degradation a gap is planned for (share of the frame's whole trace), so that a
/// mesh whose sampled ratio reads no degradation is still sampled every few frames.
pub const MIN_PLANNED_DEGRADATION: f64 = 0.05;

/// A rise of the SAH ratio (to the last build) over its value when the gap began that ends it.
pub const SAH_RISE: f32 = 0.05;

/// One mesh's sampling gap.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Watch {
    /// Frames still to be traced without a sample.
    skip: u32,
    /// The SAH ratio the gap is measured from: the last sampled frame's.
    sah_ratio: f32,
    /// The SAH ratio of the frame before (the last frame's rays were traced at that pose).
    last_sah_ratio: f32,
}

impl Watch {
    /// True when this frame's rays are to be sampled.
    #[must_use]
    pub fn due(&self) -> bool {
        self.skip == 0
    }

    /// After a frame whose decision read a fresh sample (of the last frame), its tree refitted
    /// to `sah_ratio`: `needed` when the policy needs this frame's sample whatever the room;
    /// else the gap is the frames that cannot make an action due, `room_ms` of extra trace
    /// time away, at `rate_ms` a frame (an upper bound), and no longer than the tree's `age`
    /// in frames (a young tree's degradation has shown little of how fast it grows).
    pub fn plan(&mut self, needed: bool, room_ms: f64, rate_ms: f64, age: u32, sah_ratio: f32) {
        self.sah_ratio = self.last_sah_ratio;
        // A room or rate that is not a positive number (NaN included) plans no gap.
        let plannable = room_ms > 0.0 && rate_ms > 0.0;
        self.skip = if needed || !plannable {
            0
        } else {
            // The frames before the action could be due, less the one the sample is taken in.
            let frames = (room_ms / rate_ms).floor() - 1.0;
            frames.clamp(0.0, f64::from(MAX_SAMPLE_GAP.min(age))) as u32
        };
        self.check(sah_ratio);
    }

    /// A frame without a fresh sample, its tree refitted to `sah_ratio`: one frame of the gap
    /// gone; a rise of the SAH ratio, or a `needed` sample, ends it.
    pub fn tick(&mut self, needed: bool, sah_ratio: f32) {
        self.skip = self.skip.saturating_sub(1);
        if needed {
            self.skip = 0;
        }
        self.check(sah_ratio);
    }

    /// Ends the gap when the SAH ratio has risen since the last sample.
    fn check(&mut self, sah_ratio: f32) {
        if sah_ratio > self.sah_ratio + SAH_RISE {
            self.skip = 0;
        }
        self.last_sah_ratio = sah_ratio;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Frames sampled over `frames` frames after a plan with `room` and `rate`, the SAH ratio
    /// given per frame.
    fn sampled(room: f64, rate: f64, sah: impl Fn(usize) -> f32, frames: usize) -> Vec<bool> {
        let mut w = Watch::default();
        w.tick(false, sah(0));
        w.plan(false, room, rate, 100, sah(0));
        (1..=frames)
            .map(|f| {
                let due = w.due();
                if !due {
                    w.tick(false, sah(f));
                }
                due
            })
            .collect()
    }

    /// Frames sampled after `w`'s plan, the SAH ratio flat.
    fn sampled_after(mut w: Watch, frames: usize) -> Vec<bool> {
        (0..frames)
            .map(|_| {
                let due = w.due();
                if !due {
                    w.tick(false, w.last_sah_ratio);
                }
                due
            })
            .collect()
    }

    #[test]
    fn the_gap_ends_before_the_action_can_be_due() {
        // 10 ms of room at 2 ms a frame: due at the fifth update from now at the earliest,
        // which reads the sample of the fourth frame from now: four frames without one.
        let s = sampled(10.0, 2.0, |_| 1.0, 6);
        assert_eq!(s, vec![false, false, false, false, true, true]);
        // Barely any room, or none: every frame sampled.
        assert!(sampled(1.5, 2.0, |_| 1.0, 3).iter().all(|&d| d));
        assert!(sampled(-1.0, 2.0, |_| 1.0, 3).iter().all(|&d| d));
        // Vast room: at most MAX_SAMPLE_GAP frames in a row.
        let s = sampled(1e9, 1.0, |_| 1.0, 12);
        assert_eq!(
            s.iter().take_while(|&&d| !d).count(),
            MAX_SAMPLE_GAP as usize
        );
    }

    #[test]
    fn a_rising_sah_ratio_or_a_needed_sample_ends_the_gap() {
        let s = sampled(1e9, 1.0, |f| if f >= 2 { 1.2 } else { 1.0 }, 5);
        assert_eq!(s, vec![false, false, true, true, true]);
        let mut w = Watch::default();
        w.tick(false, 1.0);
        w.plan(false, 1e9, 1.0, 100, 1.0);
        assert!(!w.due());
        w.tick(true, 1.0);
        assert!(w.due());
        w.plan(true, 1e9, 1.0, 100, 1.0);
        assert!(w.due());
        // The rise is measured from the sampled frame's pose: one between it and the frame
        // the plan is made at ends the gap at once.
        w.tick(false, 1.0);
        w.plan(false, 1e9, 1.0, 100, 1.2);
        assert!(w.due());
        // A young tree is sampled again soon.
        w.plan(false, 1e9, 1.0, 2, 1.2);
        assert_eq!(sampled_after(w, 4), vec![false, false, true, true]);
    }
}
