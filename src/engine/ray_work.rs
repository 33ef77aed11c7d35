//! Ray-work cost: a tree's cost measured by a sample of the rays a frame really casts (nodes
//! visited and triangles tested on the trees those rays walk), beside the SAH's prediction for
//! uniformly random lines.
//!
//! The sample is systematic: every [`SAMPLE_STRIDE`]-th ray of the frame, counted over all of
//! its calls from an offset drawn from the frame number, is traced with counters (in the
//! batch's own pass, or again for rays traced outside the batch queries). Each
//! ray is sampled with probability `1 / stride`, so `stride` times the sampled work is an
//! unbiased estimate of the frame's total (Horvitz-Thompson), the same on every run.
//!
//! Work is counted per mesh: each entry of a sampled ray into an instance is kept (the ray in
//! mesh space, with its interval), so other trees of the mesh can be measured on the same rays.
//! This separates per mesh because traversal is exact: the closest hit in an instance, and
//! whether an any-hit ray is blocked, do not depend on the trees, hence neither does the
//! interval each instance is entered with; only the work inside a mesh's tree does.

use super::MeshId;
use super::prices::Prices;
use crate::bvh::TraversalStats;
use crate::geom::Ray;
use std::fmt;
use std::str::FromStr;

/// One ray in this many is taken into the sample (at most: see [`SAMPLE_MAX`]).
pub const SAMPLE_STRIDE: u64 = 128;

/// Most rays a frame's sample takes: past `SAMPLE_STRIDE * SAMPLE_MAX` rays a frame the stride
/// grows with the last sampled frame's ray count. The estimate's error there is its bias, which
/// more rays do not lower (`docs/ray_work.md`), while the sample's cost grows with them.
pub const SAMPLE_MAX: u64 = 1024;

/// The stride of a frame's sample after a sampled frame of `last_rays` rays.
#[must_use]
pub fn stride_after(last_rays: u64) -> u64 {
    last_rays.div_ceil(SAMPLE_MAX).max(SAMPLE_STRIDE)
}

/// What a policy measures a tree's degradation and a frame's trace cost by.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum CostMeasure {
    /// The SAH: expected cost for uniformly random lines, estimated fresh cost by a quick build.
    Sah,
    /// Ray work: the sampled work into each mesh over what its fresh tree would cost on the
    /// same entries ([`FreshWork`]: from the triangle boxes they pierce), scaled by what the
    /// last rebuilds' replays showed, and the frame's trace cost by the sampled work per mesh.
    #[default]
    Rays,
}

impl fmt::Display for CostMeasure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Sah => "sah",
            Self::Rays => "rays",
        })
    }
}

impl FromStr for CostMeasure {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "sah" => Ok(Self::Sah),
            "rays" => Ok(Self::Rays),
            _ => Err(format!("cost {s:?}: expected sah or rays")),
        }
    }
}

/// The query a sampled ray ran.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Query {
    /// Closest hit.
    Closest,
    /// Any hit (shadow and visibility rays).
    Any,
}

/// A sampled ray's entry into one instance: the ray in the mesh's space over the interval it
/// entered with.
#[derive(Clone, Copy, Debug)]
pub struct SampleEntry {
    /// The instance's mesh.
    pub mesh: MeshId,
    /// The query.
    pub query: Query,
    /// The ray in mesh space; `tmax` is the closest hit found before entering.
    pub ray: Ray,
    /// The work it cost in the tree it walked when it was sampled.
    pub work: TraversalStats,
    /// It hit the mesh within its interval (blocked, for an any-hit ray): like the interval,
    /// the same whatever the trees.
    pub hit: bool,
    /// Closest-hit entries: the triangle boxes its interval meets before its hit in the mesh
    /// (the same whatever the trees, see [`Pierced`]); any-hit entries: `None`.
    pub pierced: Option<u32>,
}

/// One mesh's part of a frame's sample: its entries and their work, those of the entries that
/// hit it (a fresh tree costs a hit and a miss differently, so the two are weighed apart), and
/// the boxes they pierce.
#[derive(Clone, Copy, Debug, Default)]
pub struct MeshSample {
    /// Sampled entries into the mesh's instances.
    pub entries: u32,
    /// Their work.
    pub work: TraversalStats,
    /// Those of them that hit.
    pub hits: u32,
    /// The hits' work.
    pub hit_work: TraversalStats,
    /// The closest-hit entries' box counts and their work at `p`.
    pub pierced: Pierced,
}

impl MeshSample {
    /// Adds one entry.
    pub fn add(&mut self, e: &SampleEntry) {
        self.entries += 1;
        self.work += e.work;
        if e.hit {
            self.hits += 1;
            self.hit_work += e.work;
        }
        if let Some(boxes) = e.pierced {
            self.pierced.add(boxes, e.work);
        }
    }
}

/// What a mesh's fresh tree cost per sampled entry (modelled ms): per hitting and per missing
/// entry, and as a line in the triangle boxes the entry pierces ([`Pierced`]). A fresh tree's
/// work on a later frame's entries is predicted from both ([`FreshWork::predict`]), so that a
/// change in how many rays hit the mesh, or in the geometry they cross, is not taken for
/// degradation.
#[derive(Clone, Copy, Debug)]
pub struct FreshWork {
    /// Per entry, all entries.
    all: f64,
    /// Per hitting entry; `None` with too few of them to tell.
    hit: Option<f64>,
    /// Per missing entry; `None` with too few of them to tell.
    miss: Option<f64>,
    /// Per entry as `a + b n`, `n` the boxes the entry pierces ([`Pierced`]), fitted on the
    /// fresh tree's sample; `None` without enough counted entries.
    pierced: Option<(f64, f64)>,
}

impl FreshWork {
    /// The per-entry costs of a fresh tree's sample `s`, and what they grow by with the boxes
    /// its entries pierce.
    #[must_use]
    pub fn of(s: &MeshSample, p: &Prices) -> Self {
        let total = p.trace_ms(s.work);
        let hit = p.trace_ms(s.hit_work);
        let misses = s.entries - s.hits;
        let per = |ms: f64, n: u32| (n >= MIN_STRATUM).then(|| ms / f64::from(n));
        Self {
            all: total / f64::from(s.entries.max(1)),
            hit: per(hit, s.hits),
            miss: per(total - hit, misses),
            pierced: s.pierced.fit(p),
        }
    }

    /// What a fresh tree would have cost on sample `s`'s entries (modelled ms): the mean of
    /// the predictions from their hits and misses and from the boxes they pierce when both this
    /// fit and `s` have counts, else the first alone. Each errs where
    /// the other holds: the kinds miss a change in the geometry the rays cross (the explosion's
    /// misses), the line in the count, fitted at one pose, predicts too much at a denser one
    /// (`docs/ray_work.md`).
    #[must_use]
    pub fn predict(&self, s: &MeshSample) -> f64 {
        let misses = s.entries - s.hits;
        let kinds = f64::from(s.hits) * self.hit.unwrap_or(self.all)
            + f64::from(misses) * self.miss.unwrap_or(self.all);
        if let (Some((a, b)), Some(g)) = (self.pierced, s.pierced.mean()) {
            return 0.5 * (f64::from(s.entries) * (a + b * g) + kinds);
        }
        kinds
    }
}

/// The triangle boxes a mesh's sampled closest-hit entries meet before their hit
/// ([`SampleEntry::pierced`], counted in the sample's own walk): the entries' geometry, which a
/// fresh tree's work follows where their hits and misses do not (on `animations/explode.glb`
/// a ray that misses the pieces costs a fresh tree less once they have flown apart than while
/// they are close). The work is fitted as a line in the count (`docs/ray_work.md`). Sums of
/// integers (the work priced only in the fit), so that they do not depend on the order the
/// pass's threads log their entries in.
#[derive(Clone, Copy, Debug, Default)]
pub struct Pierced {
    n: u64,
    g: u64,
    gg: u64,
    w: TraversalStats,
    /// The work weighted by each entry's count.
    gw: TraversalStats,
}

impl Pierced {
    /// Fewest counted entries a fit or a mean is made from.
    const MIN: u64 = 16;

    /// One counted entry: `boxes` met, `work` its work.
    pub fn add(&mut self, boxes: u32, work: TraversalStats) {
        let g = u64::from(boxes);
        self.n += 1;
        self.g += g;
        self.gg += g * g;
        self.w += work;
        self.gw += TraversalStats {
            nodes: g * work.nodes,
            prims: g * work.prims,
        };
    }

    /// Mean count over the counted entries.
    fn mean(&self) -> Option<f64> {
        (self.n >= Self::MIN).then(|| self.g as f64 / self.n as f64)
    }

    /// The least-squares line `work = a + b count` of the work priced at `p` (`b >= 0`,
    /// `a > 0`; else the mean work alone).
    fn fit(&self, p: &Prices) -> Option<(f64, f64)> {
        if self.n < Self::MIN {
            return None;
        }
        let (n, g, gg) = (self.n as f64, self.g as f64, self.gg as f64);
        let (w, gw) = (p.trace_ms(self.w), p.trace_ms(self.gw));
        let mean = (w / n, 0.0);
        let d = n * gg - g * g;
        if d <= 1e-12 * n * gg {
            return Some(mean);
        }
        let b = (n * gw - g * w) / d;
        let a = (w - b * g) / n;
        Some(if b >= 0.0 && a > 0.0 { (a, b) } else { mean })
    }
}

/// Entries of a kind (hits, misses) a fresh tree's sample needs for its own per-entry cost.
const MIN_STRATUM: u32 = 8;

/// A mesh's ray-work degradation since its tree was built: the sampled work into it over what
/// the fresh tree cost on entries like them ([`FreshWork`], measured on the first frame traced
/// after the build), smoothed over frames.
#[derive(Clone, Copy, Debug, Default)]
pub struct Degradation {
    base: Option<FreshWork>,
    observed: f64,
    /// Entries of the last frame observed.
    entries: u32,
    /// A frame's sample has been weighed against the reference (not only made it).
    compared: bool,
}

/// The SAH's degradation (ratio less 1) that stands in for the frame after a build, whose
/// sample only made the reference and so reads no degradation at all.
pub const EVIDENT_SAH: f64 = 0.5;

/// Entries a frame under which a mesh's sampled ratio is capped by the SAH's
/// ([`Degradation::judged`]).
pub const FEW_ENTRIES: u32 = 64;

impl Degradation {
    /// Starts over: the tree was (re)built.
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// The degradation a policy weighs: the smoothed ratio, or the SAH's ratio of the refitted
    /// tree to its build (`sah_ratio`) before the fresh tree's cost is known, and, when it is
    /// at least 1 + [`EVIDENT_SAH`], until a sample has been weighed against that cost (the
    /// frame after a build reads 1 by construction, however far an explosion has already
    /// spread the tree's boxes);
    /// capped at
    /// `sah_ratio` (at least 1) while the frames give fewer than [`FEW_ENTRIES`] entries: from
    /// a few dozen entries, against a reference of as few, the ratio can err by tens of per
    /// cent for a whole period between rebuilds, while the SAH's ratio is exact for what it
    /// measures (`docs/ray_work.md`).
    #[must_use]
    pub fn judged(&self, sah_ratio: f32) -> f32 {
        match self.ratio() {
            None => sah_ratio,
            Some(_) if !self.compared && f64::from(sah_ratio) >= 1.0 + EVIDENT_SAH => sah_ratio,
            Some(r) if self.entries < FEW_ENTRIES => (r as f32).min(sah_ratio.max(1.0)),
            Some(r) => r as f32,
        }
    }

    /// The smoothed ratio, or `None` before the fresh tree's cost is known.
    #[must_use]
    pub fn ratio(&self) -> Option<f64> {
        (self.base.is_some() && self.observed > 0.0).then_some(self.observed)
    }

    /// One more frame's sample `s` of the mesh, priced at `p`; `smoothing` is the weight of
    /// the past in the smoothed ratio.
    pub fn observe(&mut self, s: &MeshSample, p: &Prices, smoothing: f64) {
        if s.entries == 0 {
            return;
        }
        self.entries = s.entries;
        match self.base {
            None => {
                self.base = Some(FreshWork::of(s, p));
                self.observed = 1.0;
            }
            Some(base) => {
                let predicted = base.predict(s);
                if predicted > 0.0 {
                    self.compared = true;
                    let seen = p.trace_ms(s.work) / predicted;
                    self.observed = smoothing * self.observed + (1.0 - smoothing) * seen;
                }
            }
        }
    }
}

/// Which rays of a batch the frame's sample takes: the frame's rays, counted across its
/// batches, fall in blocks of [`SAMPLE_STRIDE`], and one ray of each block is taken, at a
/// position drawn for the block (stratified sampling). A fixed position in every block would
/// take one column of a camera image whose width divides the stride (a 128-wide image at one ray
/// in 128): a line that crosses a small object on one frame and misses it on the next.
#[derive(Clone, Copy, Debug)]
pub struct SamplePlan {
    /// The batch's first ray, counted in the frame.
    start: u64,
    /// Rays in the batch.
    len: u64,
    /// The frame's stride, offset and jitter seed ([`RaySample`]).
    stride: u64,
    offset: u64,
    jitter: u64,
}

impl SamplePlan {
    /// The frame's index of the ray the sample takes in block `k`.
    #[inline]
    fn pick(&self, k: u64) -> u64 {
        k * self.stride + (self.offset + splitmix(self.jitter.wrapping_add(k))) % self.stride
    }

    /// One ray in this many is taken.
    #[must_use]
    pub fn stride(&self) -> u64 {
        self.stride
    }

    /// The batch's sampled indices in `from..to`, increasing.
    #[must_use]
    pub fn picks(&self, from: usize, to: usize) -> Picks {
        let to = (to as u64).min(self.len);
        let (lo, hi) = (self.start + from as u64, self.start + to);
        Picks {
            plan: *self,
            block: lo / self.stride,
            lo,
            hi,
        }
    }

    /// True when the batch takes no ray into the sample.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.picks(0, self.len as usize).next().is_none()
    }
}

/// The sampled indices of a batch within a range ([`SamplePlan::picks`]).
#[derive(Clone, Debug)]
pub struct Picks {
    plan: SamplePlan,
    block: u64,
    lo: u64,
    hi: u64,
}

impl Iterator for Picks {
    type Item = usize;

    #[inline]
    fn next(&mut self) -> Option<usize> {
        while self.block * self.plan.stride < self.hi {
            let p = self.plan.pick(self.block);
            self.block += 1;
            if p >= self.lo && p < self.hi {
                return Some((p - self.plan.start) as usize);
            }
        }
        None
    }
}

/// Work of some sampled rays, to be merged into the frame's [`RaySample`] (sums of integers, so
/// the merged sample is the same in whatever order the parts come).
#[derive(Clone, Copy, Debug, Default)]
pub struct SampleSums {
    sampled: u64,
    work: TraversalStats,
    top: TraversalStats,
    sum: f64,
    sum_sq: f64,
}

impl SampleSums {
    /// Adds one sampled ray's work (`top` of it in the top-level tree).
    pub fn add(&mut self, work: TraversalStats, top: TraversalStats) {
        self.sampled += 1;
        self.work += work;
        self.top += top;
        let w = (work.nodes + work.prims) as f64;
        self.sum += w;
        self.sum_sq += w * w;
    }

    /// Rays in this part.
    #[must_use]
    pub fn sampled(&self) -> u64 {
        self.sampled
    }

    /// Their work, both levels.
    #[must_use]
    pub fn work(&self) -> TraversalStats {
        self.work
    }

    /// Adds another part.
    pub fn merge(&mut self, o: &Self) {
        self.sampled += o.sampled;
        self.work += o.work;
        self.top += o.top;
        self.sum += o.sum;
        self.sum_sq += o.sum_sq;
    }
}

/// The frame's sample so far: which rays it takes and the work they cost.
#[derive(Clone, Copy, Debug)]
pub struct RaySample {
    /// The frame the sample belongs to.
    pub frame: u64,
    /// Rays the frame has cast so far (sampled or not).
    pub rays: u64,
    /// Rays sampled.
    pub sampled: u64,
    /// Work of the sampled rays, both levels, every mesh.
    pub work: TraversalStats,
    /// Work of the sampled rays in the top-level tree.
    pub top: TraversalStats,
    /// Sum and sum of squares of each sampled ray's work (nodes plus triangles).
    sum: f64,
    sum_sq: f64,
    /// One ray in this many is taken ([`stride_after`]).
    stride: u64,
    /// Added to every block's drawn position (mod the stride): over the frames' offsets
    /// every ray is taken equally often, whatever the draws.
    offset: u64,
    /// Seed of the blocks' positions.
    jitter: u64,
}

/// Mixed with the frame number into the seed of its blocks' positions.
const JITTER_SEED: u64 = 0x005e_ed0f_b10c;

/// The sample's estimate of the frame's mean work per ray.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct WorkEstimate {
    /// Rays cast in the frame.
    pub rays: u64,
    /// Rays sampled.
    pub sampled: u64,
    /// Estimated mean work per ray (nodes visited plus triangles tested).
    pub mean: f64,
    /// Half width of the 95% confidence interval of `mean` (normal approximation, sample
    /// variance with the finite-population correction; 0 when fewer than two rays were
    /// sampled).
    pub ci95: f64,
}

impl Default for RaySample {
    fn default() -> Self {
        Self::new(u64::MAX)
    }
}

impl RaySample {
    /// An empty sample of `frame`, one ray in [`SAMPLE_STRIDE`].
    #[must_use]
    pub fn new(frame: u64) -> Self {
        Self::after(frame, 0)
    }

    /// An empty sample of `frame` after a sampled frame of `last_rays` rays
    /// ([`stride_after`]).
    #[must_use]
    pub fn after(frame: u64, last_rays: u64) -> Self {
        let stride = stride_after(last_rays);
        Self {
            frame,
            rays: 0,
            sampled: 0,
            work: TraversalStats::default(),
            top: TraversalStats::default(),
            sum: 0.0,
            sum_sq: 0.0,
            stride,
            offset: splitmix(frame) % stride,
            jitter: splitmix(frame ^ JITTER_SEED),
        }
    }

    /// Which rays of a batch of `n` (cast after the frame's earlier ones) the sample takes;
    /// counts the batch's rays.
    pub fn plan(&mut self, n: usize) -> SamplePlan {
        let start = self.rays;
        self.rays += n as u64;
        SamplePlan {
            start,
            len: n as u64,
            stride: self.stride,
            offset: self.offset,
            jitter: self.jitter,
        }
    }

    /// Indices within a batch of `n` rays that the sample takes ([`RaySample::plan`]).
    pub fn take(&mut self, n: usize) -> Picks {
        self.plan(n).picks(0, n)
    }

    /// Adds one sampled ray's work (`top` of it in the top-level tree).
    pub fn add(&mut self, work: TraversalStats, top: TraversalStats) {
        let mut s = SampleSums::default();
        s.add(work, top);
        self.merge(&s);
    }

    /// Adds the work of sampled rays.
    pub fn merge(&mut self, s: &SampleSums) {
        self.sampled += s.sampled;
        self.work += s.work;
        self.top += s.top;
        self.sum += s.sum;
        self.sum_sq += s.sum_sq;
    }

    /// Scale from sampled work to the frame's estimated total: the stride.
    #[must_use]
    pub fn scale(&self) -> f64 {
        self.stride as f64
    }

    /// Estimated mean work per ray and its confidence interval.
    #[must_use]
    pub fn estimate(&self) -> WorkEstimate {
        let n = self.sampled as f64;
        if self.sampled == 0 {
            return WorkEstimate {
                rays: self.rays,
                ..WorkEstimate::default()
            };
        }
        let mean = self.sum / n;
        let ci95 = if self.sampled > 1 {
            let var = ((self.sum_sq - n * mean * mean) / (n - 1.0)).max(0.0);
            let fpc = (1.0 - n / self.rays.max(1) as f64).max(0.0);
            1.96 * (var * fpc / n).sqrt()
        } else {
            0.0
        };
        WorkEstimate {
            rays: self.rays,
            sampled: self.sampled,
            mean,
            ci95,
        }
    }
}

/// splitmix64: the frame's sampling offset, and the replays' choice of entries.
pub(crate) fn splitmix(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entries(hits: u32, hit_nodes: u64, misses: u32, miss_nodes: u64) -> MeshSample {
        let mut s = MeshSample::default();
        for (n, nodes, hit) in [(hits, hit_nodes, true), (misses, miss_nodes, false)] {
            for _ in 0..n {
                s.add(&SampleEntry {
                    mesh: MeshId(0),
                    query: Query::Closest,
                    ray: Ray::new(glam::Vec3::ZERO, glam::Vec3::X),
                    work: TraversalStats { nodes, prims: 0 },
                    hit,
                    pierced: None,
                });
            }
        }
        s
    }

    #[test]
    fn without_box_counts_a_fresh_trees_work_is_predicted_for_as_many_hits_and_misses() {
        // Entries without box counts (any-hit ones).
        let p = Prices::default();
        let node = p.trace_ms_f(1.0, 0.0);
        // Fresh: 20 hits of 30 nodes, 20 misses of 10.
        let fresh = FreshWork::of(&entries(20, 30, 20, 10), &p);
        // Later, 5 hits and 35 misses on the same (undegraded) tree: 50 + 350 nodes, which
        // the prediction matches, where the work per entry alone (20) would read 0.5.
        let later = entries(5, 30, 35, 10);
        let predicted = fresh.predict(&later) / node;
        assert!((predicted - 500.0).abs() < 1e-6, "{predicted}");
        // Too few of a kind at the fresh tree: its cost per entry of any kind stands in.
        let few = FreshWork::of(&entries(3, 30, 37, 10), &p);
        let all = (3.0 * 30.0 + 37.0 * 10.0) / 40.0;
        let predicted = few.predict(&entries(10, 30, 0, 10)) / node;
        assert!((predicted - 10.0 * all).abs() < 1e-6, "{predicted}");
    }

    #[test]
    fn degradation_is_the_work_over_the_fresh_trees_smoothed_and_starts_over_at_a_rebuild() {
        let p = Prices::default();
        let mut d = Degradation::default();
        assert_eq!(d.ratio(), None, "nothing traced yet");
        d.observe(&MeshSample::default(), &p, 0.5);
        assert_eq!(d.ratio(), None, "a frame without entries says nothing");
        // The first traced frame is the fresh tree's: the reference, ratio 1.
        d.observe(&entries(20, 30, 20, 10), &p, 0.5);
        assert_eq!(d.ratio(), Some(1.0));
        // The same entries at twice the work: 2, smoothed with the past at weight 0.5.
        d.observe(&entries(20, 60, 20, 20), &p, 0.5);
        let r = d.ratio().unwrap();
        assert!((r - 1.5).abs() < 1e-9, "{r}");
        d.observe(&entries(20, 60, 20, 20), &p, 0.5);
        let r = d.ratio().unwrap();
        assert!((r - 1.75).abs() < 1e-9, "{r}");
        d.reset();
        assert_eq!(d.ratio(), None, "rebuilt: the reference is taken again");
        d.observe(&entries(20, 60, 20, 20), &p, 0.5);
        assert_eq!(d.ratio(), Some(1.0));
    }

    #[test]
    fn a_few_entries_ratio_is_capped_by_the_sah_ratio() {
        let p = Prices::default();
        let mut d = Degradation::default();
        // Before any reference: the SAH's ratio stands in.
        assert_eq!(d.judged(1.3), 1.3);
        let n = FEW_ENTRIES / 2;
        d.observe(&entries(n / 2, 30, n / 2, 10), &p, 0.0);
        // Three times the reference's work on as many entries.
        d.observe(&entries(n / 2, 90, n / 2, 30), &p, 0.0);
        assert!((d.ratio().unwrap() - 3.0).abs() < 1e-9);
        assert_eq!(d.judged(1.2), 1.2, "capped at the SAH's ratio");
        assert_eq!(d.judged(0.9), 1.0, "a cap below 1 is 1");
        assert!((d.judged(4.0) - 3.0).abs() < 1e-6, "a cap, not a floor");
        // With enough entries the sampled ratio stands.
        let mut d = Degradation::default();
        let n = FEW_ENTRIES;
        d.observe(&entries(n / 2, 30, n / 2, 10), &p, 0.0);
        d.observe(&entries(n / 2, 90, n / 2, 30), &p, 0.0);
        assert!((d.judged(1.2) - 3.0).abs() < 1e-6);
    }

    #[test]
    fn an_evident_sah_ratio_stands_in_until_a_sample_is_weighed_against_the_reference() {
        let p = Prices::default();
        let mut d = Degradation::default();
        let n = FEW_ENTRIES;
        // The frame after a build: its sample only made the reference (ratio 1).
        d.observe(&entries(n / 2, 30, n / 2, 10), &p, 0.0);
        assert_eq!(d.ratio(), Some(1.0));
        assert_eq!(d.judged(2.5), 2.5, "an evident SAH ratio stands in");
        assert_eq!(
            d.judged(1.3),
            1.0,
            "below the bound the reference's 1 stands"
        );
        // Once a sample is weighed against the reference, it decides.
        d.observe(&entries(n / 2, 60, n / 2, 20), &p, 0.0);
        assert!((d.judged(2.5) - 2.0).abs() < 1e-6);
        d.reset();
        d.observe(&entries(n / 2, 30, n / 2, 10), &p, 0.0);
        assert_eq!(d.judged(2.5), 2.5, "rebuilt: again until the next sample");
    }

    #[test]
    fn one_ray_of_each_block_is_sampled_whatever_the_batches() {
        let stride = SAMPLE_STRIDE as usize;
        for frame in 0..20 {
            let mut whole = RaySample::new(frame);
            let all: Vec<usize> = whole.take(1000).collect();
            let mut split = RaySample::new(frame);
            let mut parts = Vec::new();
            let mut base = 0;
            for n in [1, 63, 64, 65, 7, 800] {
                parts.extend(split.take(n).map(|i| i + base));
                base += n;
            }
            assert_eq!(all, parts, "frame {frame}");
            assert_eq!(split.rays, 1000);
            // One ray in each block of the stride, the last block's if it falls in the batch.
            for (k, &i) in all.iter().enumerate() {
                assert_eq!(i / stride, k, "frame {frame}");
            }
            assert!(all.len() == 1000 / stride || all.len() == 1000 / stride + 1);
        }
        // The positions vary from block to block (not one column of a 128-wide image) and
        // from frame to frame: over many frames every position comes up in a block.
        let rows: Vec<usize> = RaySample::new(3)
            .take(16 * stride)
            .map(|i| i % stride)
            .collect();
        assert!(rows.windows(2).any(|w| w[0] != w[1]), "{rows:?}");
        let mut seen = vec![false; stride];
        for frame in 0..2000 {
            seen[RaySample::new(frame).take(stride).next().unwrap()] = true;
        }
        assert!(seen.iter().all(|&s| s));
    }

    #[test]
    fn chunks_walked_with_picks_take_the_plans_rays() {
        for frame in 0..20 {
            let mut s = RaySample::new(frame);
            let _ = s.take(37);
            let mut again = s;
            let want: Vec<usize> = s.take(1000).collect();
            let plan = again.plan(1000);
            for size in [1, 63, 64, 256, 1000, 1024] {
                let mut got = Vec::new();
                for base in (0..1000).step_by(size) {
                    got.extend(plan.picks(base, base + size));
                }
                assert_eq!(got, want, "frame {frame}, chunks of {size}");
            }
        }
    }

    #[test]
    fn the_estimate_is_unbiased_over_offsets_and_its_interval_covers() {
        // Work of ray i: a pattern with a strong trend, so a fixed offset would be biased. With
        // the blocks' draws fixed, the frames' offsets take every ray once. The stride of a
        // frame after a large one ([`stride_after`]) is unbiased alike.
        let work = |i: usize| ((i * 37) % 101 + i / 50) as u64;
        for (n, stride) in [(5000, SAMPLE_STRIDE), (300_000, stride_after(1_000_000))] {
            let truth = (0..n).map(|i| work(i) as f64).sum::<f64>() / n as f64;
            let mut mean_of_means = 0.0;
            let mut covered = 0;
            for offset in 0..stride {
                let mut s = RaySample {
                    stride,
                    offset,
                    jitter: 7,
                    ..RaySample::default()
                };
                for i in s.take(n).collect::<Vec<_>>() {
                    let w = TraversalStats {
                        nodes: work(i),
                        prims: 0,
                    };
                    s.add(w, TraversalStats::default());
                }
                let e = s.estimate();
                // Totals: stride times the sample, the estimate of the frame's total.
                mean_of_means += s.scale() * e.mean * e.sampled as f64 / n as f64;
                if (e.mean - truth).abs() <= e.ci95 {
                    covered += 1;
                }
            }
            mean_of_means /= stride as f64;
            assert!(
                (mean_of_means - truth).abs() < 1e-9 * truth,
                "stride {stride}: {mean_of_means} vs {truth}"
            );
            assert!(
                covered * 8 >= stride * 7,
                "stride {stride}: interval covered {covered} offsets"
            );
        }
    }

    #[test]
    fn past_sample_max_rays_a_frame_the_stride_keeps_the_sample_at_sample_max() {
        assert_eq!(stride_after(0), SAMPLE_STRIDE);
        assert_eq!(stride_after(SAMPLE_STRIDE * SAMPLE_MAX), SAMPLE_STRIDE);
        assert!(stride_after(SAMPLE_STRIDE * SAMPLE_MAX + 1) > SAMPLE_STRIDE);
        for rays in [10_000, 131_072, 131_073, 1_000_000, 3_000_001] {
            for frame in 0..5 {
                let mut s = RaySample::after(frame, rays);
                let taken = s.take(rays as usize).count() as u64;
                let want = rays.div_ceil(s.stride);
                assert!(taken.abs_diff(want) <= 1, "{rays}: {taken} of {want}");
                assert!(
                    taken <= SAMPLE_MAX.max(rays / SAMPLE_STRIDE) + 1,
                    "{rays}: {taken}"
                );
                assert_eq!(s.scale(), s.stride as f64);
            }
        }
    }

    #[test]
    fn cost_names_round_trip() {
        for c in [CostMeasure::Sah, CostMeasure::Rays] {
            assert_eq!(c.to_string().parse::<CostMeasure>().unwrap(), c);
        }
        assert!("ray".parse::<CostMeasure>().is_err());
    }

    #[test]
    fn the_fresh_work_is_predicted_from_the_boxes_the_entries_pierce_and_their_kinds() {
        let p = Prices::default();
        // A fresh tree's work per entry is 10 + 3 per box pierced.
        let work = |boxes: u32| {
            p.trace_ms(TraversalStats {
                nodes: 10 + 3 * u64::from(boxes),
                prims: 0,
            })
        };
        // Entries with box counts `counts`, and the same without them.
        let sample = |counts: &[u32], with: bool| {
            let mut s = MeshSample::default();
            for &n in counts {
                s.add(&SampleEntry {
                    mesh: MeshId(0),
                    query: Query::Closest,
                    ray: Ray::new(glam::Vec3::ZERO, glam::Vec3::X),
                    work: TraversalStats {
                        nodes: 10 + 3 * u64::from(n),
                        prims: 0,
                    },
                    hit: n % 2 == 0,
                    pierced: with.then_some(n),
                });
            }
            s
        };
        let counts: Vec<u32> = (0..40).map(|i| i % 9).collect();
        let fresh = FreshWork::of(&sample(&counts, true), &p);
        // Later entries that pierce fewer boxes: predicted from their counts, not from their
        // hits and misses.
        let later: Vec<u32> = (0..40).map(|i| i % 3).collect();
        let by_boxes: f64 = later.iter().map(|&n| work(n)).sum();
        // Without counts, per hit and per miss: here far off.
        let by_kind = fresh.predict(&sample(&later, false));
        assert!(
            (by_kind - by_boxes).abs() > 0.05 * by_boxes,
            "{by_kind} {by_boxes}"
        );
        // With them, the mean of the line in the counts (exact here) and of that.
        let want = 0.5 * (by_boxes + by_kind);
        assert!((fresh.predict(&sample(&later, true)) - want).abs() < 1e-9 * want);
    }
}
