//! Unit prices of the engine's work, so that a frame's cost can be *modelled* from work counts
//! (triangles refitted and rebuilt, nodes visited and triangles tested by rays) instead of
//! timed: the same frames then cost the same on every run, whatever else the machine does.
//!
//! The prices come from one calibration pass ([`Prices::calibrate`]: a generated mesh refitted,
//! rebuilt and traced, each timed in CPU time as the median of a few passes) and can be saved
//! and loaded as JSON, so that several runs share one set.

use crate::bvh::{BuildParams, BuildWorkspace, MeshBvh, MeshBvh8, TraversalStats};
use crate::geom::{Ray, shapes};
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Nanoseconds per unit of each kind of work.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Prices {
    /// Refitting one triangle (the binary tree and the wide tree rays walk), ns.
    pub refit_ns_per_tri: f64,
    /// Rebuilding, per `n log2 n` of a mesh of `n` triangles (binned build and collapse), ns.
    pub rebuild_ns_per_tri_log: f64,
    /// The fresh-build estimate, per triangle of its subsample, ns.
    pub estimate_ns_per_tri: f64,
    /// A ray visiting one node (either tree level), ns.
    pub trace_ns_per_node: f64,
    /// A ray testing one triangle, ns.
    pub trace_ns_per_tri: f64,
    /// Writing a restructured tree back (optimisation, partial rebuild), with the wide tree's
    /// collapse, per triangle, ns.
    #[serde(default = "default_restructure")]
    pub restructure_ns_per_tri: f64,
    /// One candidate position an optimisation's insertion search looks at, ns.
    #[serde(default = "default_visit")]
    pub optimize_ns_per_visit: f64,
    /// What taking one ray into the ray-work sample adds to its trace in the batch's own pass
    /// (the counters and its entries kept), ns.
    #[serde(default = "default_sample")]
    pub sample_ns_per_ray: f64,
    /// What a clip-aware rebuild for `k` sampled poses costs beyond a plain one, in plain
    /// rebuilds per `k^2` (each reference's box grows into every pose's bins for every pose it
    /// is binned in): a share of the rebuild's price, so that it holds with the prices of
    /// another machine.
    #[serde(default = "default_clip")]
    pub clip_rebuild_share_per_pose2: f64,
}

fn default_clip() -> f64 {
    Prices::default().clip_rebuild_share_per_pose2
}

fn default_sample() -> f64 {
    Prices::default().sample_ns_per_ray
}

fn default_restructure() -> f64 {
    Prices::default().restructure_ns_per_tri
}

fn default_visit() -> f64 {
    Prices::default().optimize_ns_per_visit
}

impl Default for Prices {
    /// Placeholder figures of a plausible order, not a measurement: what an engine never given
    /// calibrated prices models with (tests, library users); use [`Prices::calibrate`] for the
    /// machine at hand.
    fn default() -> Self {
        Self {
            refit_ns_per_tri: 6.0,
            rebuild_ns_per_tri_log: 6.0,
            estimate_ns_per_tri: 60.0,
            trace_ns_per_node: 12.0,
            trace_ns_per_tri: 4.0,
            restructure_ns_per_tri: 40.0,
            optimize_ns_per_visit: 30.0,
            sample_ns_per_ray: 40.0,
            clip_rebuild_share_per_pose2: 1.0,
        }
    }
}

/// `n log2 n` of a mesh of `n` triangles: the units a rebuild is priced in.
#[must_use]
pub fn rebuild_units(tris: usize) -> f64 {
    let n = tris as f64;
    n * n.max(2.0).log2()
}

impl Prices {
    /// Modelled refit of `tris` triangles, ms.
    #[must_use]
    pub fn refit_ms(&self, tris: usize) -> f64 {
        self.refit_ns_per_tri * tris as f64 * 1e-6
    }

    /// Modelled rebuild of a mesh of `tris` triangles, ms.
    #[must_use]
    pub fn rebuild_ms(&self, tris: usize) -> f64 {
        self.rebuild_ns_per_tri_log * rebuild_units(tris) * 1e-6
    }

    /// Modelled clip-aware rebuild of a mesh of `tris` triangles for `poses` sampled poses
    /// ([`crate::bvh::MeshBvh::rebuild_clip_aware`]; a plain rebuild with fewer than one), ms.
    #[must_use]
    pub fn clip_rebuild_ms(&self, tris: usize, poses: usize) -> f64 {
        let k = poses as f64;
        self.rebuild_ms(tris) * (1.0 + self.clip_rebuild_share_per_pose2 * k * k)
    }

    /// Modelled optimisation of a mesh of `tris` triangles whose searches looked at `visits`
    /// candidate positions, ms.
    #[must_use]
    pub fn optimize_ms(&self, tris: usize, visits: u64) -> f64 {
        (self.restructure_ns_per_tri * tris as f64 + self.optimize_ns_per_visit * visits as f64)
            * 1e-6
    }

    /// Modelled partial rebuild of a mesh of `tris` triangles over a cut of `cut` subtrees,
    /// `rebuilt` of its triangles rebuilt from scratch, ms.
    #[must_use]
    pub fn partial_ms(&self, tris: usize, cut: usize, rebuilt: usize) -> f64 {
        let per_subtree = (tris / cut.max(1)).max(2) as f64;
        self.restructure_ns_per_tri * tris as f64 * 1e-6
            + self.rebuild_ms(cut)
            + self.rebuild_ns_per_tri_log * rebuilt as f64 * per_subtree.log2() * 1e-6
    }

    /// Modelled fresh-build estimate over a subsample of `tris` triangles, ms.
    #[must_use]
    pub fn estimate_ms(&self, tris: usize) -> f64 {
        self.estimate_ns_per_tri * tris as f64 * 1e-6
    }

    /// Modelled cost of taking `rays` into the ray-work sample in their own pass, ms.
    #[must_use]
    pub fn sample_ms(&self, rays: u64) -> f64 {
        self.sample_ns_per_ray * rays as f64 * 1e-6
    }

    /// Modelled trace time of `work`, ms.
    #[must_use]
    pub fn trace_ms(&self, work: TraversalStats) -> f64 {
        self.trace_ms_f(work.nodes as f64, work.prims as f64)
    }

    /// Modelled trace time of `nodes` node visits and `tris` triangle tests, ms.
    #[must_use]
    pub fn trace_ms_f(&self, nodes: f64, tris: f64) -> f64 {
        (self.trace_ns_per_node * nodes + self.trace_ns_per_tri * tris) * 1e-6
    }

    /// Reads prices saved as JSON.
    ///
    /// # Errors
    /// When the file cannot be read or is not a prices object with positive, finite prices.
    pub fn load(path: &Path) -> crate::Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| crate::Error::io(path, e))?;
        let p: Prices = serde_json::from_str(&text).map_err(|e| {
            crate::Error::malformed(path, "prices", format!("not a prices file: {e}"))
        })?;
        let all = [
            p.refit_ns_per_tri,
            p.rebuild_ns_per_tri_log,
            p.estimate_ns_per_tri,
            p.trace_ns_per_node,
            p.trace_ns_per_tri,
            p.restructure_ns_per_tri,
            p.optimize_ns_per_visit,
            p.clip_rebuild_share_per_pose2,
        ];
        if all.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
            return Err(crate::Error::malformed(
                path,
                "prices",
                format!("every price must be positive and finite, found {all:?}"),
            ));
        }
        Ok(p)
    }

    /// What [`Prices::calibrate`] with these arguments measures on, for reports.
    #[must_use]
    pub fn calibration_source(triangles: usize, passes: usize) -> String {
        format!(
            "calibrated: bumpy sphere of about {triangles} triangles, {} thread(s), median of {passes} \
             passes in CPU time",
            rayon::current_num_threads()
        )
    }

    /// Measures the prices on this machine in the current rayon pool: a bumpy sphere of about
    /// `triangles` triangles is refitted, rebuilt, estimated and traced (camera rays, the wide
    /// tree), each the median of `passes` passes in CPU time of the whole process (so time
    /// other processes take is not counted). The two trace prices come from two trees over the
    /// same rays whose mix of node visits and triangle tests differs (leaves of at most 2 and
    /// of at most 16 triangles): two equations, two unknowns.
    #[must_use]
    pub fn calibrate(triangles: usize, passes: usize) -> Self {
        let mesh = shapes::bumpy_sphere(triangles.max(1000));
        let (pos, idx) = (&mesh.positions, &mesh.indices);
        let n = idx.len();
        let passes = passes.max(1);
        let build = BuildParams::BINNED;
        let mut ws = BuildWorkspace::default();
        let mut bvh = MeshBvh::build_indexed(pos, idx, &build);
        let mut wide = MeshBvh8::from_mesh_bvh(&bvh);
        let refit = median_cpu_ms(passes, || {
            bvh.refit_indexed(pos, idx);
            wide.refit_indexed(pos, idx);
        });
        let rebuild = median_cpu_ms(passes, || {
            bvh.rebuild_indexed(pos, idx, &build, &mut ws);
            wide.collapse_from(&bvh);
        });
        // A clip-aware rebuild for four poses (the sphere squashed along each axis in turn),
        // beyond the plain one.
        let squashed: Vec<Vec<Vec3>> = (0..CLIP_POSES)
            .map(|k| {
                let s = Vec3::ONE + 0.5 * Vec3::AXES[k % 3] * (1.0 + k as f32);
                pos.iter().map(|&p| p * s).collect()
            })
            .collect();
        let views: Vec<&[Vec3]> = squashed.iter().map(Vec::as_slice).collect();
        let mut clip = crate::bvh::build::clip::ClipPoses::default();
        let clip_ms = median_cpu_ms(passes, || {
            bvh.rebuild_clip_aware(pos, idx, &views, &build, &mut ws, &mut clip);
            wide.collapse_from(&bvh);
        });
        let k2 = (CLIP_POSES * CLIP_POSES) as f64;
        let clip_share = ((clip_ms - rebuild) / (k2 * rebuild)).max(1e-3);
        let mut fresh = super::estimate::FreshSah::new(n, build.max_leaf_size);
        let estimate = median_cpu_ms(passes, || {
            std::hint::black_box(fresh.estimate(pos, idx));
        });
        let rays = view_rays(&bvh.bvh().bounds(), 256);
        let trace_with = |leaf: u32| {
            let params = BuildParams {
                max_leaf_size: leaf,
                ..BuildParams::BINNED
            };
            let w = MeshBvh8::from_mesh_bvh(&MeshBvh::build_indexed(pos, idx, &params));
            let mut work = TraversalStats::default();
            for r in &rays {
                let _ = w.closest_hit_counted(r, &mut work);
            }
            let ms = median_cpu_ms(passes, || trace_all(&w, &rays));
            (work, ms)
        };
        // The write-back of a restructured tree (a partial rebuild of the top only), and an
        // optimisation's searches beyond it.
        let mut rws = crate::bvh::topology::RestructureWorkspace::default();
        let mut ps = crate::bvh::partial::PartialScratch::default();
        let mut cut = crate::bvh::partial::PartialCut::default();
        bvh.rebuild_indexed(pos, idx, &build, &mut ws);
        cut.reset(&bvh, &mut ps);
        let restructure = median_cpu_ms(passes, || {
            bvh.partial_rebuild(&mut cut, 0.0, &build, &mut rws, &mut ps);
            wide.collapse_from(&bvh);
        });
        let restructure_ns = (restructure * 1e6 / n as f64).max(1e-3);
        let mut os = crate::bvh::optimize::OptimizeScratch::default();
        let visits = std::cell::Cell::new(0u64);
        let optimize = median_cpu_ms(passes, || {
            let st = bvh.optimize(
                crate::bvh::optimize::OptimizeBudget::default(),
                &mut rws,
                &mut os,
            );
            visits.set(st.visits);
            wide.collapse_from(&bvh);
        });
        let visit_ns =
            ((optimize * 1e6 - restructure_ns * n as f64) / visits.get().max(1) as f64).max(1e-3);
        // Sampling in the trace's own pass: every ray traced through an engine as a sampled ray
        // is (both levels counted, its box counts, its entries kept), against the plain trace
        // of the same rays.
        let mut engine = super::Engine::new(super::EngineConfig::default());
        let id = engine.add_mesh(pos.clone(), idx.clone());
        engine.add_instance(id, glam::Affine3A::IDENTITY);
        engine.update();
        let mut log = Vec::with_capacity(rays.len());
        let plain = median_cpu_ms(passes, || engine.trace_as_sampled(&rays, false, &mut log));
        let recorded = median_cpu_ms(passes, || engine.trace_as_sampled(&rays, true, &mut log));
        let sample_ns = ((recorded - plain) * 1e6 / rays.len().max(1) as f64).max(1e-3);
        let (w1, t1) = trace_with(2);
        let (w2, t2) = trace_with(16);
        let (node, tri) = solve_trace_prices(w1, t1, w2, t2);
        Self {
            refit_ns_per_tri: refit * 1e6 / n as f64,
            rebuild_ns_per_tri_log: rebuild * 1e6 / rebuild_units(n),
            estimate_ns_per_tri: estimate * 1e6 / fresh.sample_len().max(1) as f64,
            trace_ns_per_node: node,
            trace_ns_per_tri: tri,
            restructure_ns_per_tri: restructure_ns,
            optimize_ns_per_visit: visit_ns,
            sample_ns_per_ray: sample_ns,
            clip_rebuild_share_per_pose2: clip_share,
        }
    }
}

/// Poses the calibration's clip-aware rebuild is timed with.
const CLIP_POSES: usize = 4;

/// `side x side` rays from a point outside `bounds` towards it, spread over a 45 degree cone.
fn view_rays(bounds: &crate::geom::Aabb, side: usize) -> Vec<Ray> {
    let c = bounds.center();
    let eye = c + Vec3::new(0.45, 0.35, 1.0).normalize() * bounds.extent().length().max(1e-6);
    let fwd = (c - eye).normalize();
    let right = fwd.cross(Vec3::Y).normalize();
    let up = right.cross(fwd);
    let s = (22.5f32).to_radians().tan();
    let mut rays = Vec::with_capacity(side * side);
    for y in 0..side {
        for x in 0..side {
            let sx = (2.0 * (x as f32 + 0.5) / side as f32 - 1.0) * s;
            let sy = (2.0 * (y as f32 + 0.5) / side as f32 - 1.0) * s;
            rays.push(Ray::new(eye, (fwd + right * sx + up * sy).normalize()));
        }
    }
    rays
}

/// Least wall-clock length of one timed pass of the calibration, ms.
const MIN_PASS_MS: f64 = 50.0;

fn trace_all(w: &MeshBvh8, rays: &[Ray]) {
    use rayon::prelude::*;
    rays.par_chunks(256).for_each(|c| {
        for r in c {
            std::hint::black_box(w.closest_hit(r));
        }
    });
}

/// Node and triangle prices (ns) from two timed traces of different work mixes; when the two
/// mixes cannot separate them (nearly proportional, or a negative solution), one price per
/// unit of work (nodes plus triangles) from both together.
fn solve_trace_prices(w1: TraversalStats, t1: f64, w2: TraversalStats, t2: f64) -> (f64, f64) {
    let (n1, p1, n2, p2) = (
        w1.nodes as f64,
        w1.prims as f64,
        w2.nodes as f64,
        w2.prims as f64,
    );
    let (t1, t2) = (t1 * 1e6, t2 * 1e6);
    let det = n1 * p2 - n2 * p1;
    let scale = (n1 * p2).abs().max((n2 * p1).abs());
    if det.abs() > 0.05 * scale {
        let node = (t1 * p2 - t2 * p1) / det;
        let tri = (n1 * t2 - n2 * t1) / det;
        if node > 0.0 && tri > 0.0 {
            return (node, tri);
        }
    }
    let unit = (t1 + t2) / (n1 + p1 + n2 + p2).max(1.0);
    (unit, unit)
}

/// Median CPU time (ms) of one run of `f` over `passes` passes, after one untimed run. Each
/// pass repeats `f` for at least [`MIN_PASS_MS`] of wall clock and divides: a pool thread still
/// running when the clock is read counts its time only up to its last scheduler event, and
/// one interruption weighs less in a longer pass.
fn median_cpu_ms(passes: usize, mut f: impl FnMut()) -> f64 {
    f();
    let mut v: Vec<f64> = (0..passes)
        .map(|_| {
            let t = crate::cputime::CpuClock::now();
            let mut runs = 0u32;
            while runs == 0 || t.elapsed_ms().wall_ms < MIN_PASS_MS {
                f();
                runs += 1;
            }
            let e = t.elapsed_ms();
            // Without CPU times (not Linux), the wall clock.
            let ms = if e.cpu_ms > 0.0 { e.cpu_ms } else { e.wall_ms };
            ms / f64::from(runs)
        })
        .collect();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_mixes_separate_the_prices() {
        let w = |n, p| TraversalStats { nodes: n, prims: p };
        // 10 ns a node, 3 a triangle.
        let (a, b) = (w(1000, 200), w(400, 900));
        let t = |x: TraversalStats| (10.0 * x.nodes as f64 + 3.0 * x.prims as f64) * 1e-6;
        let (node, tri) = solve_trace_prices(a, t(a), b, t(b));
        assert!((node - 10.0).abs() < 1e-9 && (tri - 3.0).abs() < 1e-9);
        // Proportional mixes: one price for both.
        let (node, tri) = solve_trace_prices(a, t(a), w(2000, 400), 2.0 * t(a));
        assert_eq!(node, tri);
        assert!(node > 0.0);
    }

    #[test]
    fn modelled_costs_scale_with_work() {
        let p = Prices::default();
        assert!((p.refit_ms(2000) - 2.0 * p.refit_ms(1000)).abs() < 1e-12);
        assert!(p.rebuild_ms(2000) > 2.0 * p.rebuild_ms(1000));
        let w = TraversalStats {
            nodes: 1_000_000,
            prims: 0,
        };
        assert!((p.trace_ms(w) - p.trace_ns_per_node).abs() < 1e-9);
    }

    #[test]
    fn prices_round_trip_and_bad_files_are_errors() {
        let dir = std::env::temp_dir().join(format!("dynbvh-prices-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("p.json");
        let p = Prices::default();
        std::fs::write(&f, serde_json::to_string(&p).unwrap()).unwrap();
        assert_eq!(Prices::load(&f).unwrap(), p);
        std::fs::write(&f, "{\"refit_ns_per_tri\": 1}").unwrap();
        let e = Prices::load(&f).unwrap_err().to_string();
        assert!(e.contains("p.json"), "{e}");
        let mut bad = p;
        bad.trace_ns_per_tri = -1.0;
        std::fs::write(&f, serde_json::to_string(&bad).unwrap()).unwrap();
        assert!(Prices::load(&f).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
