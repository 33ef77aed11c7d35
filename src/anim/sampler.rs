//! Keyframe interpolation: STEP, LINEAR (shortest-path slerp for rotations) and CUBICSPLINE,
//! holding the first/last key outside the key range.

use super::scene::{Interpolation, Sampler};

/// Spherical linear interpolation of unit quaternions `a` to `b` along the shorter arc.
#[must_use]
pub fn slerp(a: [f32; 4], b: [f32; 4], s: f32) -> [f32; 4] {
    let mut d: f32 = (0..4).map(|i| a[i] * b[i]).sum();
    let mut b = b;
    if d < 0.0 {
        b = b.map(|x| -x);
        d = -d;
    }
    let (ka, kb) = if d > 0.9995 {
        (1.0 - s, s)
    } else {
        let theta0 = d.min(1.0).acos();
        let theta = s * theta0;
        let (sin0, sin) = (theta0.sin(), theta.sin());
        (theta.cos() - d * sin / sin0, sin / sin0)
    };
    let q: [f32; 4] = std::array::from_fn(|i| ka * a[i] + kb * b[i]);
    normalize4(q)
}

/// `q / |q|`, or `q` unchanged when its length is zero.
fn normalize4(q: [f32; 4]) -> [f32; 4] {
    let len = q.iter().map(|x| x * x).sum::<f32>().sqrt();
    if len > 0.0 { q.map(|x| x / len) } else { q }
}

impl Sampler {
    /// Value slice of key `k` (the middle group for cubic splines).
    fn value(&self, k: usize) -> &[f32] {
        let w = self.width;
        let at = match self.interpolation {
            Interpolation::CubicSpline => (3 * k + 1) * w,
            _ => k * w,
        };
        &self.values[at..at + w]
    }

    /// First time with a key.
    #[must_use]
    pub fn start(&self) -> f32 {
        self.times.first().copied().unwrap_or(0.0)
    }

    /// Last time with a key.
    #[must_use]
    pub fn end(&self) -> f32 {
        self.times.last().copied().unwrap_or(0.0)
    }

    /// Writes the value at time `t` into `out` (`width` floats). `rotation` selects slerp for
    /// LINEAR and normalization for CUBICSPLINE, on 4-wide values.
    pub fn sample(&self, t: f32, rotation: bool, out: &mut [f32]) {
        let n = self.times.len();
        let w = self.width;
        let out = &mut out[..w];
        if n == 0 {
            return;
        }
        // Clamp outside the keys (also catches NaN t).
        if t.is_nan() || t <= self.times[0] {
            out.copy_from_slice(self.value(0));
            return;
        }
        if t >= self.times[n - 1] {
            out.copy_from_slice(self.value(n - 1));
            return;
        }
        let k = self.times.partition_point(|&x| x <= t) - 1;
        let (t0, t1) = (self.times[k], self.times[k + 1]);
        let dt = t1 - t0;
        let s = (t - t0) / dt;
        match self.interpolation {
            Interpolation::Step => out.copy_from_slice(self.value(k)),
            Interpolation::Linear if rotation && w == 4 => {
                let a = self.value(k);
                let b = self.value(k + 1);
                out.copy_from_slice(&slerp(
                    [a[0], a[1], a[2], a[3]],
                    [b[0], b[1], b[2], b[3]],
                    s,
                ));
            }
            Interpolation::Linear => {
                let (a, b) = (self.value(k), self.value(k + 1));
                for i in 0..w {
                    out[i] = a[i] + s * (b[i] - a[i]);
                }
            }
            Interpolation::CubicSpline => {
                let v = &self.values;
                let p0 = (3 * k + 1) * w;
                let b0 = (3 * k + 2) * w; // out-tangent of key k
                let a1 = (3 * k + 3) * w; // in-tangent of key k + 1
                let p1 = (3 * k + 4) * w;
                let (s2, s3) = (s * s, s * s * s);
                let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
                let h10 = s3 - 2.0 * s2 + s;
                let h01 = -2.0 * s3 + 3.0 * s2;
                let h11 = s3 - s2;
                for i in 0..w {
                    out[i] = h00 * v[p0 + i]
                        + h10 * dt * v[b0 + i]
                        + h01 * v[p1 + i]
                        + h11 * dt * v[a1 + i];
                }
                if rotation && w == 4 {
                    let q = normalize4([out[0], out[1], out[2], out[3]]);
                    out.copy_from_slice(&q);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sampler(interpolation: Interpolation, values: Vec<f32>) -> Sampler {
        Sampler {
            interpolation,
            times: vec![1.0, 2.0, 4.0],
            values,
            width: 1,
        }
    }

    #[test]
    fn step_linear_clamp() {
        let mut o = [0.0];
        let s = sampler(Interpolation::Linear, vec![10.0, 20.0, 0.0]);
        for (t, want) in [
            (0.0, 10.0),
            (1.5, 15.0),
            (3.0, 10.0),
            (9.0, 0.0),
            (f32::NAN, 10.0),
        ] {
            s.sample(t, false, &mut o);
            assert_eq!(o[0], want, "t={t}");
        }
        let s = sampler(Interpolation::Step, vec![10.0, 20.0, 0.0]);
        s.sample(1.99, false, &mut o);
        assert_eq!(o[0], 10.0);
        s.sample(2.0, false, &mut o);
        assert_eq!(o[0], 20.0);
    }

    #[test]
    fn cubic_hits_keys_and_uses_scaled_tangents() {
        // in, value, out per key; out-tangent 1 at key 0, in-tangent 0 at key 1.
        let s = Sampler {
            interpolation: Interpolation::CubicSpline,
            times: vec![0.0, 2.0],
            values: vec![0.0, 0.0, 1.0, 0.0, 1.0, 0.0],
            width: 1,
        };
        let mut o = [0.0];
        s.sample(1.0, false, &mut o);
        // s = 0.5: h10 = 0.125, dt = 2, h01 = 0.5 → 0.25 + 0.5.
        assert!((o[0] - 0.75).abs() < 1e-6);
    }

    #[test]
    fn slerp_takes_short_path() {
        let a = [0.0, 0.0, 0.0, 1.0];
        let h = std::f32::consts::FRAC_1_SQRT_2;
        let b = [0.0, 0.0, -h, -h]; // same rotation as +90° about z, negated
        let q = slerp(a, b, 0.5);
        let want = glam::Quat::from_rotation_z(std::f32::consts::FRAC_PI_4);
        assert!(glam::Quat::from_array(q).dot(want).abs() > 0.99999);
    }
}
