//! Ray sets of its own when no ray file is given: a pinhole camera looking at a box, rays with
//! random origins in the box and random directions, and a spinning lidar-like fan above it.

use crate::geom::{Aabb, Ray};
use glam::Vec3;

/// A named set of rays.
#[derive(Clone, Debug)]
pub struct RaySet {
    /// Name in reports (`camera`, `random`, or the file stem).
    pub name: String,
    /// The rays.
    pub rays: Vec<Ray>,
}

/// `w x h` primary rays of a pinhole camera (45 degree vertical field of view) placed outside
/// `bounds` and looking at its centre from the direction (0.45, 0.35, 1).
#[must_use]
pub fn camera_rays(bounds: &Aabb, w: usize, h: usize) -> Vec<Ray> {
    let c = bounds.center();
    let half_diag = bounds.extent().length() * 0.5;
    let eye = c + Vec3::new(0.45, 0.35, 1.0).normalize() * 2.0 * reach(bounds, half_diag);
    let fwd = (c - eye).normalize();
    let right = fwd.cross(Vec3::Y).normalize();
    let up = right.cross(fwd);
    let tanh = (45f32.to_radians() * 0.5).tan();
    let mut rays = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let sx = (2.0 * (x as f32 + 0.5) / w as f32 - 1.0) * tanh;
            let sy = (1.0 - 2.0 * (y as f32 + 0.5) / h as f32) * tanh;
            rays.push(Ray::new(eye, (fwd + right * sx + up * sy).normalize()));
        }
    }
    rays
}

/// `size` where it is positive; for a box that is one point (every triangle degenerate in
/// one place), a size of its own, relative to its coordinates, so that the rays do not all
/// start inside every box of the tree.
fn reach(bounds: &Aabb, size: f32) -> f32 {
    if size > 0.0 {
        size
    } else {
        let c = bounds.center();
        if c.is_finite() {
            c.abs().max_element().max(1.0) * 1e-3
        } else {
            1.0
        }
    }
}

/// `n` rays with origins uniform in `bounds` and directions uniform on the sphere
/// (deterministic for a given `seed`; a box that is one point gets a small cube around it).
#[must_use]
pub fn random_rays(bounds: &Aabb, n: usize, seed: u64) -> Vec<Ray> {
    let mut state = seed;
    let mut next = move || {
        // splitmix64
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    };
    // A box that is one point is widened to a cube around it (see `reach`).
    let (lo, ext) = if bounds.extent().max_element() > 0.0 {
        (bounds.min, bounds.extent())
    } else {
        let r = reach(bounds, 0.0);
        (bounds.min - Vec3::splat(r), Vec3::splat(2.0 * r))
    };
    (0..n)
        .map(|_| {
            let o = lo + Vec3::new(next(), next(), next()) * ext;
            let z = 2.0 * next() - 1.0;
            let phi = std::f32::consts::TAU * next();
            let s = (1.0 - z * z).max(0.0).sqrt();
            Ray::new(o, Vec3::new(s * phi.cos(), s * phi.sin(), z))
        })
        .collect()
}

/// About `n` rays of a square camera image, as a lower-resolution image of the same view (every
/// k-th row and column) so that they stay coherent; the first `n` rays when the set is not a
/// square image.
#[must_use]
pub fn image_subset(rays: &[Ray], n: usize) -> Vec<Ray> {
    let side = (rays.len() as f64).sqrt().round() as usize;
    if side * side != rays.len() || rays.len() <= n {
        return rays.iter().take(n).copied().collect();
    }
    let step = ((rays.len() as f64 / n.max(1) as f64).sqrt().round() as usize).max(1);
    (0..side)
        .step_by(step)
        .flat_map(|y| (0..side).step_by(step).map(move |x| rays[y * side + x]))
        .collect()
}

/// Angle below the horizon of the steepest beam of [`lidar_rays`], in degrees.
pub const LIDAR_STEEPEST_DEGREES: f32 = 85.0;

/// Range of the angle below the horizon of the shallowest beam of [`lidar_rays`], in degrees
/// (within it, the angle at which that beam meets the box's floor at its nearer side).
pub const LIDAR_SHALLOWEST_DEGREES: [f32; 2] = [10.0, 75.0];

/// Fewest and most beams of [`lidar_rays`] (see [`lidar_channels`]).
pub const LIDAR_CHANNELS: [usize; 2] = [16, 64];

/// Beams (vertical channels) of a lidar fan of `n` rays: the divisor of `n` within
/// [`LIDAR_CHANNELS`] closest to `n / 1024` (the larger one of two as close), so that
/// channels × azimuths = `n`; when `n` has no such divisor, `n / 1024` itself (clamped to
/// that range and to `n`), and the last azimuth fires only the first `n mod channels` beams.
/// 0 for no rays.
#[must_use]
pub fn lidar_channels(n: usize) -> usize {
    if n == 0 {
        return 0;
    }
    let [lo, hi] = LIDAR_CHANNELS;
    let target = (n / 1024).clamp(lo, hi);
    (lo..=hi)
        .filter(|c| n.is_multiple_of(*c))
        .min_by_key(|&c| (c.abs_diff(target), usize::MAX - c))
        .unwrap_or(target.min(n))
}

/// Writes into `out` (cleared first) exactly `n` rays of a spinning lidar above `bounds`:
/// [`lidar_channels`]`(n)` beams fanned in elevation, fired together at each of `n / channels`
/// azimuths evenly spaced over a full turn. Each frame is one full 360° sweep; what rotates
/// from frame to frame is the sweep's phase, by the golden ratio's fraction of the azimuth
/// spacing per frame, so that successive frames fire between each other's azimuths, as a
/// spinning sensor not synchronised with the frame clock does, while every frame sees the
/// whole scene. The same arguments always give the same rays.
///
/// Y is up (glTF's convention). The sensor sits above the box's centre, at its top plus 5% of
/// its diagonal, outside the geometry the box holds, like a sensor on a mast (at the origin
/// for an empty or unbounded box). The beams point down and outward, evenly spaced in
/// elevation from [`LIDAR_STEEPEST_DEGREES`] below the horizon (the first beam) to the angle
/// at which a beam meets the box's floor at the nearer of its side walls, clamped to
/// [`LIDAR_SHALLOWEST_DEGREES`] (the last beam). In the axis directions every beam thus
/// reaches the floor inside the box: over a scene on a ground plane nearly every ray hits
/// something, and the pattern keeps its shape relative to the scene at any scale. Rays are
/// ordered azimuth by azimuth, each azimuth's beams from the steepest to the shallowest:
/// consecutive rays are coherent. Directions are unit vectors; rays span `[0, inf)`.
///
/// The sensor follows the box: pass the same box every frame (say, the first frame's scene
/// box) for a sensor that stays put. Allocates nothing once `out` has room for `n` rays.
pub fn lidar_rays(bounds: &Aabb, n: usize, frame: usize, out: &mut Vec<Ray>) {
    out.clear();
    out.reserve(n);
    let channels = lidar_channels(n);
    if channels == 0 {
        return;
    }
    let azimuths = n.div_ceil(channels);
    let top = bounds
        .center()
        .with_y(bounds.max.y + 0.05 * bounds.extent().length());
    let origin = if top.is_finite() { top } else { Vec3::ZERO };
    let [lo, hi] = LIDAR_SHALLOWEST_DEGREES;
    let reach = 0.5 * bounds.extent().x.min(bounds.extent().z);
    let floor = (origin.y - bounds.min.y).atan2(reach).to_degrees();
    let shallowest = if floor.is_finite() {
        floor.clamp(lo, hi)
    } else {
        hi
    };
    let mut beams = [(0.0f32, 0.0f32); LIDAR_CHANNELS[1]];
    for (c, beam) in beams.iter_mut().take(channels).enumerate() {
        let f = if channels > 1 {
            c as f32 / (channels - 1) as f32
        } else {
            0.5
        };
        let below = LIDAR_STEEPEST_DEGREES + (shallowest - LIDAR_STEEPEST_DEGREES) * f;
        *beam = (-below).to_radians().sin_cos();
    }
    // The golden ratio's fraction, taken in f64 so that late frames keep their phase.
    let spacing = std::f64::consts::TAU / azimuths as f64;
    let phase = (frame as f64 * 0.618_033_988_749_894_9).fract() * spacing;
    for a in 0..azimuths {
        let (sin_az, cos_az) = ((phase + a as f64 * spacing) as f32).sin_cos();
        let fired = channels.min(n - a * channels);
        for &(sin_el, cos_el) in &beams[..fired] {
            out.push(Ray::new(
                origin,
                Vec3::new(cos_el * cos_az, sin_el, cos_el * sin_az),
            ));
        }
    }
}

/// Nodes visited plus triangles tested by the closest hits of `rays`, `trace` tracing one ray
/// with the counters (the deterministic cost the rung and clip reports compare trees by).
pub fn closest_hit_work(
    rays: &[Ray],
    mut trace: impl FnMut(&Ray, &mut crate::bvh::TraversalStats),
) -> f64 {
    let mut w = crate::bvh::TraversalStats::default();
    for r in rays {
        trace(r, &mut w);
    }
    (w.nodes + w.prims) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::anim::generate::{Kind, generate};
    use crate::anim::{LoadOptions, Scene};
    use crate::bvh::{BuildParams, MeshBvh};
    use std::path::Path;

    fn lidar(bounds: &Aabb, n: usize, frame: usize) -> Vec<Ray> {
        let mut out = Vec::new();
        lidar_rays(bounds, n, frame, &mut out);
        out
    }

    fn same(a: &[Ray], b: &[Ray]) -> bool {
        a.len() == b.len()
            && a.iter()
                .zip(b)
                .all(|(x, y)| x.origin == y.origin && x.dir == y.dir)
    }

    #[test]
    fn lidar_channels_divide_the_count_when_they_can() {
        assert_eq!(lidar_channels(0), 0);
        assert_eq!(lidar_channels(5), 5);
        assert_eq!(lidar_channels(1000), 20);
        assert_eq!(lidar_channels(20_000), 20);
        assert_eq!(lidar_channels(23_040), 24);
        assert_eq!(lidar_channels(1 << 20), 64);
        assert_eq!(lidar_channels(1_000_000), 64);
        // 20011 is prime: the target, and a short last azimuth.
        assert_eq!(lidar_channels(20_011), 19);
        for n in [16, 100, 999, 4096, 30_000, 99_991, 250_000] {
            let c = lidar_channels(n);
            assert!((1..=64).contains(&c) && c <= n, "{n}: {c}");
        }
    }

    #[test]
    fn lidar_rays_are_exactly_n_unit_and_reach_the_floor_within_the_box() {
        let b = Aabb::new(Vec3::new(-6.0, 0.0, -8.0), Vec3::new(6.0, 5.0, 8.0));
        let top = 5.0 + 0.05 * b.extent().length();
        for n in [1, 5, 17, 1000, 20_011, 23_040, 100_000] {
            let rays = lidar(&b, n, 3);
            assert_eq!(rays.len(), n);
            let mut farthest = 0.0f32;
            for r in &rays {
                assert_eq!(r.origin, Vec3::new(0.0, top, 0.0));
                assert!((r.dir.length() - 1.0).abs() < 1e-6, "{n}: {:?}", r.dir);
                assert!(r.dir.y < 0.0, "{n}: {:?}", r.dir);
                let floor = r.at(-top / r.dir.y);
                farthest = farthest.max(floor.x.hypot(floor.z));
            }
            // The first beam is the steepest; the shallowest meets the floor at the nearer side
            // wall, x = ±6.
            if n >= 16 {
                let steepest = -LIDAR_STEEPEST_DEGREES.to_radians().sin();
                assert!(
                    (rays[0].dir.y - steepest).abs() < 1e-6,
                    "{n}: {:?}",
                    rays[0]
                );
                assert!((farthest - 6.0).abs() < 1e-3, "{n}: {farthest}");
            }
        }
        assert!(lidar(&b, 0, 0).is_empty());
        // An empty box puts the sensor at the origin.
        assert!(
            lidar(&Aabb::EMPTY, 64, 0)
                .iter()
                .all(|r| r.origin == Vec3::ZERO && r.dir.is_finite())
        );
    }

    #[test]
    fn lidar_rays_are_deterministic_differ_by_frame_and_reuse_storage() {
        let b = Aabb::new(Vec3::splat(-1.0), Vec3::splat(1.0));
        assert!(same(&lidar(&b, 5000, 7), &lidar(&b, 5000, 7)));
        let frames: Vec<Vec<Ray>> = (0..8).map(|f| lidar(&b, 5000, f)).collect();
        for i in 0..frames.len() {
            for j in 0..i {
                assert!(!same(&frames[i], &frames[j]), "frames {i} and {j}");
            }
        }
        // Each frame is a full sweep: its azimuths cover the circle, only the phase moves.
        let azimuth = |r: &Ray| r.dir.z.atan2(r.dir.x);
        let (a0, a1) = (azimuth(&frames[0][0]), azimuth(&frames[1][0]));
        let spacing = std::f32::consts::TAU / (5000 / lidar_channels(5000)) as f32;
        assert!(a0.abs() < 1e-6 && a1 > 0.0 && a1 < spacing, "{a0} {a1}");
        let mut out = Vec::with_capacity(5000);
        let ptr = out.as_ptr();
        for frame in 0..4 {
            lidar_rays(&b, 5000, frame, &mut out);
            assert_eq!((out.as_ptr(), out.capacity()), (ptr, 5000));
        }
    }

    /// Over the sensor scene's clip, nearly every ray hits something and most hit the cloth,
    /// even when it is folded (t = 2 s) and the ground shows where a third of it was.
    #[test]
    fn lidar_rays_mostly_hit_the_cloth_scene() {
        let g = generate(Kind::LidarCloth, 3000, 1);
        let (scene, _) =
            Scene::from_slice(Path::new("cloth.glb"), &g.glb, &LoadOptions::default()).unwrap();
        let cloth = scene.instances[0].triangles.clone();
        let bounds = scene.flatten_at(Some(0), 0.0).unwrap().bounds();
        let mut rays = Vec::new();
        for frame in 0..8 {
            let t = g.duration * frame as f32 / 8.0;
            let mesh = scene.flatten_at(Some(0), t).unwrap();
            let bvh = MeshBvh::build(&mesh, &BuildParams::BINNED);
            lidar_rays(&bounds, 4000, frame, &mut rays);
            let hits: Vec<_> = rays.iter().filter_map(|r| bvh.closest_hit(r)).collect();
            let on_cloth = hits
                .iter()
                .filter(|h| cloth.contains(&(h.prim as usize)))
                .count();
            let (hit, on_cloth) = (
                hits.len() as f32 / rays.len() as f32,
                on_cloth as f32 / rays.len() as f32,
            );
            assert!(
                hit > 0.95 && on_cloth > 0.6,
                "t={t}: hit {hit}, cloth {on_cloth}"
            );
        }
    }
}
