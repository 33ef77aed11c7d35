//! Ray sets of its own when no ray file is given: a pinhole camera looking at a box, and rays
//! with random origins in the box and random directions.

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
    let eye = c + Vec3::new(0.45, 0.35, 1.0).normalize() * 2.0 * half_diag.max(1e-6);
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

/// `n` rays with origins uniform in `bounds` and directions uniform on the sphere
/// (deterministic for a given `seed`).
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
    (0..n)
        .map(|_| {
            let o = bounds.min + Vec3::new(next(), next(), next()) * bounds.extent();
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
