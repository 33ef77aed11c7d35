//! The look of a frame: key light, hemisphere ambient, a checkered ground that fades into a
//! gradient sky, per-instance colours, and the heat map's colour scale.

use super::camera::Camera;
use crate::geom::Aabb;
use glam::Vec3;
use std::sync::OnceLock;

/// A ground plane under the scene (`y = height`), checkered, fading into the background
/// between `inner` and `outer` (distances from `center` in the xz plane).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ground {
    /// Height of the plane.
    pub height: f32,
    /// Centre of the lit disc (its y is ignored).
    pub center: Vec3,
    /// Radius where fading starts.
    pub inner: f32,
    /// Radius where only the background remains.
    pub outer: f32,
    /// Side of a checker square.
    pub tile: f32,
}

/// Everything about a frame's look that does not depend on the geometry's current pose.
#[derive(Clone, Debug, PartialEq)]
pub struct Stage {
    /// The camera.
    pub camera: Camera,
    /// Unit vector toward the key light (a distant light).
    pub light: Vec3,
    /// The ground plane, if drawn.
    pub ground: Option<Ground>,
    /// How far shadow rays start off the surface, along its geometric normal.
    pub offset: f32,
    /// Linear albedo of instances, used round-robin.
    pub palette: Vec<Vec3>,
}

/// Instance colours (sRGB): clay, teal, gold, slate blue, sage, rose, sand, violet.
const PALETTE_SRGB: [[u8; 3]; 8] = [
    [204, 132, 98],
    [84, 160, 160],
    [214, 178, 84],
    [110, 128, 204],
    [134, 178, 110],
    [204, 110, 134],
    [210, 194, 160],
    [150, 116, 190],
];

impl Stage {
    /// A stage for a scene occupying `bounds` (over the whole animation), seen by `camera`:
    /// the key light comes from above, left and in front of the camera; the ground (if
    /// asked) lies under the box.
    #[must_use]
    pub fn new(camera: Camera, bounds: &Aabb, ground: bool) -> Self {
        let flat = |v: Vec3| Vec3::new(v.x, 0.0, v.z).try_normalize();
        let back = flat(-camera.forward).unwrap_or(Vec3::Z);
        let right = flat(camera.right).unwrap_or_else(|| back.cross(Vec3::Y));
        let light = (Vec3::Y * 1.5 - right * 0.8 + back * 0.7).normalize();
        let ok = !bounds.is_empty() && bounds.is_finite();
        // Relative to the scene's size, whatever its scale (a point gets a size of its own).
        let size = if ok {
            let s = bounds.extent().length();
            if s > 0.0 {
                s
            } else {
                bounds.center().abs().max_element().max(1.0) * 1e-3
            }
        } else {
            1.0
        };
        let ground = (ground && ok).then(|| {
            let e = bounds.extent();
            let r = 0.5 * e.x.hypot(e.z).max(e.y);
            Ground {
                height: bounds.min.y - size * 1e-3,
                center: bounds.center(),
                inner: r * 1.3,
                outer: r * 3.5,
                tile: nice_tile(e.x.max(e.z).max(e.y) / 5.0),
            }
        });
        Self {
            camera,
            light,
            ground,
            offset: size * 2e-5,
            palette: PALETTE_SRGB
                .iter()
                .map(|c| Vec3::from_array(c.map(srgb_to_linear)))
                .collect(),
        }
    }

    /// Linear colour of the sky seen along unit direction `d`.
    #[must_use]
    #[inline]
    pub fn background(&self, d: Vec3) -> Vec3 {
        const ZENITH: Vec3 = Vec3::new(0.16, 0.24, 0.42);
        const HORIZON: Vec3 = Vec3::new(0.62, 0.66, 0.72);
        const NADIR: Vec3 = Vec3::new(0.30, 0.30, 0.33);
        let y = d.y;
        if y >= 0.0 {
            HORIZON.lerp(ZENITH, y.sqrt().min(1.0))
        } else {
            HORIZON.lerp(NADIR, (-y).sqrt().min(1.0))
        }
    }

    /// Linear albedo of an instance.
    #[must_use]
    #[inline]
    pub fn albedo(&self, instance: u32) -> Vec3 {
        self.palette[instance as usize % self.palette.len()]
    }
}

/// The power of ten, or 2 or 5 times one, nearest below `x`.
fn nice_tile(x: f32) -> f32 {
    if !(x > 0.0 && x.is_finite()) {
        return 1.0;
    }
    let p = 10f32.powf(x.log10().floor());
    let m = x / p;
    p * if m >= 5.0 {
        5.0
    } else if m >= 2.0 {
        2.0
    } else {
        1.0
    }
}

/// Light arriving on a surface with unit normal `n` (facing the viewer), not counting the
/// albedo: hemisphere ambient plus the key light times `lit` (0 in shadow).
#[must_use]
#[inline]
pub fn irradiance(n: Vec3, light: Vec3, lit: f32) -> Vec3 {
    const SKY: Vec3 = Vec3::new(0.30, 0.34, 0.42);
    const BOUNCE: Vec3 = Vec3::new(0.16, 0.14, 0.12);
    const KEY: Vec3 = Vec3::new(1.05, 0.98, 0.88);
    let ambient = BOUNCE.lerp(SKY, n.y * 0.5 + 0.5);
    ambient + KEY * (n.dot(light).max(0.0) * lit)
}

/// A small Blinn highlight toward `light` seen along unit direction `d`.
#[must_use]
#[inline]
pub fn highlight(n: Vec3, d: Vec3, light: Vec3, lit: f32) -> f32 {
    let h = (light - d).normalize_or_zero();
    let c = n.dot(h).max(0.0);
    let c2 = c * c;
    let c4 = c2 * c2;
    let c8 = c4 * c4;
    0.12 * c8 * c8 * c8 * lit
}

/// Hermite step between `a` and `b`.
#[must_use]
#[inline]
pub fn smoothstep(a: f32, b: f32, x: f32) -> f32 {
    let t = ((x - a) / (b - a)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// sRGB byte to linear.
#[must_use]
pub fn srgb_to_linear(c: u8) -> f32 {
    let c = f32::from(c) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

const LUT_SIZE: usize = 4096;

fn lut() -> &'static [u8; LUT_SIZE] {
    static LUT: OnceLock<[u8; LUT_SIZE]> = OnceLock::new();
    LUT.get_or_init(|| {
        let mut t = [0u8; LUT_SIZE];
        for (i, o) in t.iter_mut().enumerate() {
            let c = i as f64 / (LUT_SIZE - 1) as f64;
            let s = if c <= 0.003_130_8 {
                12.92 * c
            } else {
                1.055 * c.powf(1.0 / 2.4) - 0.055
            };
            *o = (s * 255.0).round().clamp(0.0, 255.0) as u8;
        }
        t
    })
}

/// Linear colour to sRGB bytes (clamped), through a table.
#[must_use]
#[inline]
pub fn to_srgb(c: Vec3) -> [u8; 3] {
    let t = lut();
    let q = |x: f32| t[(x.clamp(0.0, 1.0) * (LUT_SIZE - 1) as f32 + 0.5) as usize];
    [q(c.x), q(c.y), q(c.z)]
}

/// The heat map's colours from no work to the top of the scale (sRGB): deep blue, violet,
/// magenta, orange, yellow, pale yellow.
const HEAT: [[u8; 3]; 6] = [
    [18, 16, 60],
    [70, 36, 140],
    [160, 44, 128],
    [228, 96, 56],
    [250, 186, 40],
    [255, 250, 190],
];

/// Colour of `work` on a scale whose top is `max` (beyond it: the top colour).
#[must_use]
#[inline]
pub fn heat_color(work: f32, max: f32) -> [u8; 3] {
    let x = if max > 0.0 {
        (work / max).clamp(0.0, 1.0)
    } else {
        1.0
    };
    let f = x * (HEAT.len() - 1) as f32;
    let i = (f as usize).min(HEAT.len() - 2);
    let t = f - i as f32;
    let (a, b) = (HEAT[i], HEAT[i + 1]);
    [0, 1, 2].map(|k| (f32::from(a[k]) + (f32::from(b[k]) - f32::from(a[k])) * t).round() as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trip() {
        for c in [0u8, 1, 10, 50, 128, 200, 254, 255] {
            let l = srgb_to_linear(c);
            assert_eq!(to_srgb(Vec3::splat(l))[0], c);
        }
    }

    #[test]
    fn heat_scale_ends() {
        assert_eq!(heat_color(0.0, 100.0), HEAT[0]);
        assert_eq!(heat_color(100.0, 100.0), HEAT[5]);
        assert_eq!(heat_color(1e9, 100.0), HEAT[5]);
    }

    #[test]
    fn tiles_are_round() {
        for (x, want) in [(0.37, 0.2), (7.0, 5.0), (1.0, 1.0), (130.0, 100.0)] {
            assert!((nice_tile(x) - want).abs() < want * 1e-5, "{x}");
        }
    }
}
