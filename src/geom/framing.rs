//! The box a camera frames: the points' bounds, less the few that lie far outside the rest
//! (one vertex at 1e30 in a mesh a metre across would otherwise put the camera 1e30 away,
//! where the whole mesh is smaller than a ray's rounding error and every ray tests every
//! triangle).

use super::Aabb;
use glam::Vec3;

/// Half the most points the quantiles are taken from (an even sample of the rest).
const SAMPLE: usize = 1 << 16;

/// Share of the points below the low quantile and above the high one, on each axis.
const TAIL: f64 = 0.005;

/// The bounds of the points `visit` hands over (it is called once, or twice when something is
/// left out, and must give the same points each time; points that are not finite are
/// skipped), and how many of them were left out as far outliers.
///
/// On each axis the 0.5% and 99.5% quantiles of the points (of an even sample of at most
/// about 128k of them) bound their core; a point is kept when it lies within twice the core's
/// largest side of the core on every axis. Nothing is left out of a set of fewer than 200
/// points (its quantiles are its extremes), nor where the core is one point. An ordinary
/// mesh keeps every vertex: its extremes lie far closer to its quantiles than that.
pub fn framing_bounds(visit: impl Fn(&mut dyn FnMut(Vec3))) -> (Aabb, u64) {
    let mut n = 0usize;
    let mut all = Aabb::EMPTY;
    // Every `stride`-th point; when the sample fills up, every other one is dropped and the
    // stride doubles, so it stays an even sample in one pass.
    let mut sample = Vec::new();
    let mut stride = 1usize;
    visit(&mut |p| {
        if p.is_finite() {
            if n.is_multiple_of(stride) {
                sample.push(p);
                if sample.len() == 2 * SAMPLE {
                    let mut k = 0;
                    sample.retain(|_| {
                        k += 1;
                        k % 2 == 1
                    });
                    stride *= 2;
                }
            }
            n += 1;
            all = all.grow(p);
        }
    });
    if n < 200 {
        return (all, 0);
    }
    let Some(keep) = keep_box(&sample) else {
        return (all, 0);
    };
    if all.min.cmpge(keep.min).all() && all.max.cmple(keep.max).all() {
        return (all, 0);
    }
    let mut kept = Aabb::EMPTY;
    let mut left_out = 0u64;
    visit(&mut |p| {
        if p.is_finite() {
            if p.cmpge(keep.min).all() && p.cmple(keep.max).all() {
                kept = kept.grow(p);
            } else {
                left_out += 1;
            }
        }
    });
    (kept, left_out)
}

/// The box beyond which a point of `sample` counts as a far outlier, or `None` when the
/// sample's core is a single point (nothing to measure "far" by).
fn keep_box(sample: &[Vec3]) -> Option<Aabb> {
    let n = sample.len();
    let lo_at = ((n as f64 * TAIL) as usize).min(n - 1);
    let hi_at = n - 1 - lo_at;
    let mut coords: Vec<f32> = Vec::with_capacity(n);
    let mut core = Aabb::EMPTY;
    for axis in 0..3 {
        coords.clear();
        coords.extend(sample.iter().map(|p| p[axis]));
        let (_, lo, rest) = coords.select_nth_unstable_by(lo_at, f32::total_cmp);
        let lo = *lo;
        let hi = if hi_at > lo_at {
            *rest
                .select_nth_unstable_by(hi_at - lo_at - 1, f32::total_cmp)
                .1
        } else {
            lo
        };
        core.min[axis] = lo;
        core.max[axis] = hi;
    }
    let margin = 2.0 * core.extent().max_element();
    if !(margin > 0.0 && margin.is_finite()) {
        return None;
    }
    let m = Vec3::splat(margin);
    Some(Aabb::new(core.min - m, core.max + m))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: u32) -> Vec<Vec3> {
        (0..n * n)
            .map(|k| Vec3::new((k % n) as f32, (k / n) as f32, 0.0))
            .collect()
    }

    fn frame(points: &[Vec3]) -> (Aabb, u64) {
        framing_bounds(|f| points.iter().for_each(|&p| f(p)))
    }

    #[test]
    fn an_ordinary_mesh_keeps_every_point() {
        let mut pts = grid(100);
        // A thin spike of a few points, 1.6 times the grid's size long: still part of the mesh.
        pts.extend((0..5).map(|k| Vec3::new(50.0, 50.0, 40.0 * k as f32)));
        let (b, out) = frame(&pts);
        assert_eq!(out, 0);
        assert_eq!(b, Aabb::from_points(&pts));
    }

    #[test]
    fn far_vertices_are_left_out() {
        for far in [
            Vec3::splat(1e30),
            Vec3::new(0.0, 0.0, -1e6),
            Vec3::new(3e38, -3e38, 1.0),
        ] {
            let mut pts = grid(100);
            pts[5050] = far;
            pts.push(Vec3::NAN);
            let (b, out) = frame(&pts);
            assert_eq!(out, 1, "{far}");
            assert_eq!(
                b,
                Aabb::new(Vec3::ZERO, Vec3::new(99.0, 99.0, 0.0)),
                "{far}"
            );
        }
    }

    #[test]
    fn large_sets_are_sampled_evenly() {
        // 300k points: the sample is thinned twice; the far point is still found.
        let mut pts = grid(550);
        pts[1000] = Vec3::new(0.0, -1e20, 0.0);
        let (b, out) = frame(&pts);
        assert_eq!(out, 1);
        assert_eq!(b, Aabb::new(Vec3::ZERO, Vec3::new(549.0, 549.0, 0.0)));
    }

    #[test]
    fn small_sets_and_single_points_are_kept_whole() {
        let pts = [Vec3::ZERO, Vec3::X, Vec3::splat(1e30)];
        assert_eq!(frame(&pts), (Aabb::from_points(&pts), 0));
        let mut pts = vec![Vec3::ONE; 1000];
        pts.push(Vec3::splat(1e30));
        assert_eq!(frame(&pts), (Aabb::from_points(&pts), 0));
        assert_eq!(frame(&[]).1, 0);
    }
}
