use glam::Vec3;

/// A ray `origin + t * dir`, hitting what lies at `t` in the half-open interval `[tmin, tmax)`,
/// with its reciprocal direction precomputed for the slab test.
///
/// Every query of the crate reports hits with `tmin <= t < tmax` (single rays, packets, wide
/// trees, the engine). Box tests ([`Ray::hit_box`]) are conservative: they accept the closed
/// interval and round the far end up, so they never reject what the triangle test would accept.
///
/// `origin` and `dir` are read and changed through methods ([`Ray::origin`], [`Ray::set_origin`],
/// ...) because the slab test's values derived from them must follow; `tmin` and `tmax` are plain
/// fields (nothing is derived from them).
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    /// Origin.
    pub(crate) origin: Vec3,
    /// Direction (need not be normalised; `t` is measured in its units).
    pub(crate) dir: Vec3,
    /// Reciprocal direction; a zero component (either sign) becomes `+inf`.
    pub(crate) inv_dir: Vec3,
    /// Origin the slab test subtracts from a box's lower corner: the origin, except on an axis
    /// along which the ray does not move, where it is one ulp above. With `slab_hi` one ulp
    /// below, a ray whose origin lies on a box face of such an axis (it runs inside the face's
    /// plane) gets distances of `-inf` and `+inf` for that slab, never `0 * inf`: it is inside
    /// the slab, however close to zero the coordinates are. See [`Ray::hit_box`].
    pub(crate) slab_lo: Vec3,
    /// Origin the slab test subtracts from a box's upper corner (see `slab_lo`).
    pub(crate) slab_hi: Vec3,
    /// Start of the interval (included).
    pub tmin: f32,
    /// End of the interval (excluded).
    pub tmax: f32,
}

/// `γ(3)` of Pharr, Jakob & Humphreys: a bound on the relative rounding error of three f32
/// operations. The slab test's far distance is scaled by `1 + 2γ(3)` (Ize 2013) so that the box
/// test stays conservative under rounding.
const GAMMA3: f32 = 3.0 * (f32::EPSILON * 0.5) / (1.0 - 3.0 * (f32::EPSILON * 0.5));
pub(crate) const FAR_SCALE: f32 = 1.0 + 2.0 * GAMMA3;

impl Ray {
    /// A ray over `[0, inf)`.
    #[must_use]
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self::with_range(origin, dir, 0.0, f32::INFINITY)
    }

    /// A ray over `[tmin, tmax)`.
    #[must_use]
    pub fn with_range(origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> Self {
        let mut ray = Self {
            origin,
            dir,
            inv_dir: Vec3::ZERO,
            slab_lo: Vec3::ZERO,
            slab_hi: Vec3::ZERO,
            tmin,
            tmax,
        };
        ray.derive();
        ray
    }

    /// The ray from `from` towards `to` over `[0, 1)`: `t = 1` is `to` itself, which is not
    /// included (a line-of-sight query between two surface points does not hit the target).
    #[must_use]
    pub fn segment(from: Vec3, to: Vec3) -> Self {
        Self::with_range(from, to - from, 0.0, 1.0)
    }

    /// Origin.
    #[must_use]
    #[inline]
    pub fn origin(&self) -> Vec3 {
        self.origin
    }

    /// Direction (not normalised by the ray; `t` is measured in its units).
    #[must_use]
    #[inline]
    pub fn dir(&self) -> Vec3 {
        self.dir
    }

    /// Reciprocal direction the slab test uses; a zero component (either sign) is `+inf`.
    #[must_use]
    #[inline]
    pub fn inv_dir(&self) -> Vec3 {
        self.inv_dir
    }

    /// Moves the origin (the interval is kept).
    #[inline]
    pub fn set_origin(&mut self, origin: Vec3) {
        self.origin = origin;
        self.derive();
    }

    /// Changes the direction (the interval is kept, in units of the new direction).
    #[inline]
    pub fn set_dir(&mut self, dir: Vec3) {
        self.dir = dir;
        self.derive();
    }

    /// Sets the interval `[tmin, tmax)`.
    #[inline]
    pub fn set_range(&mut self, tmin: f32, tmax: f32) {
        self.tmin = tmin;
        self.tmax = tmax;
    }

    /// Recomputes the slab test's values from `origin` and `dir`.
    fn derive(&mut self) {
        let inv = |d: f32| if d == 0.0 { f32::INFINITY } else { 1.0 / d };
        let o = self.origin.to_array();
        let d = self.dir.to_array();
        let nudge = |step: fn(f32) -> f32| {
            Vec3::from(std::array::from_fn::<f32, 3, _>(|a| {
                if d[a] == 0.0 { step(o[a]) } else { o[a] }
            }))
        };
        self.inv_dir = Vec3::new(inv(d[0]), inv(d[1]), inv(d[2]));
        self.slab_lo = nudge(f32::next_up);
        self.slab_hi = nudge(f32::next_down);
    }

    /// The point at distance `t`.
    #[must_use]
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }

    /// Slab test against the box `[bmin, bmax]` from `tmin` to `tmax`: the entry distance, or
    /// `None` when the ray misses. Conservative: the interval is taken closed, and a ray that
    /// touches the box is never rejected through rounding (the far distance, and `tmax` with it,
    /// is scaled up by `1 + 2γ(3)`), so the box test accepts every hit of `[tmin, tmax)`.
    ///
    /// On an axis along which the ray does not move, the slab is `(-inf, +inf)` when the origin
    /// lies within it, faces included (the nudged origins `slab_lo` and `slab_hi` keep the
    /// differences non-zero), and `(+inf, +inf)` or `(-inf, -inf)` when it lies outside by more
    /// than an ulp. Only a face exactly one ulp beyond the origin
    /// gives `0 * inf = NaN`; the ray then misses the box, and either answer is right.
    #[must_use]
    #[inline(always)]
    pub fn hit_box(&self, bmin: Vec3, bmax: Vec3, tmax: f32) -> Option<f32> {
        let t0 = (bmin - self.slab_lo) * self.inv_dir;
        let t1 = (bmax - self.slab_hi) * self.inv_dir;
        let near = t0.min(t1);
        let far = t0.max(t1);
        // Plain compares compile to single min/max instructions, unlike f32::min/max. A NaN
        // (see above) drops out of `near` and `far` unless both are NaN, and in the compares
        // below it can only drop other candidates: the answer gets more conservative.
        let tn = fmax(fmax(near.x, near.y), fmax(near.z, self.tmin));
        let tf = fmin(fmin(far.x, far.y), fmin(far.z, tmax)) * FAR_SCALE;
        if tn <= tf { Some(tn) } else { None }
    }
}

#[inline(always)]
fn fmax(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

#[inline(always)]
fn fmin(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// A ray's hit: distance, barycentrics of the second and third vertex, and the primitive id.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance along the ray, in units of its direction.
    pub t: f32,
    /// Barycentric weight of the triangle's second vertex.
    pub u: f32,
    /// Barycentric weight of the triangle's third vertex.
    pub v: f32,
    /// The primitive (triangle) index in the input order.
    pub prim: u32,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_parallel_ray_on_box_face_has_no_nan() {
        // Origin exactly on the box's min-y plane, direction with zero y and z components.
        let r = Ray::new(Vec3::new(-5.0, 0.0, 0.5), Vec3::X);
        let hit = r.hit_box(
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 1.0),
            f32::INFINITY,
        );
        assert_eq!(hit, Some(5.0));
        // Outside the slab: a miss.
        let r = Ray::new(Vec3::new(-5.0, -0.001, 0.5), Vec3::X);
        assert_eq!(
            r.hit_box(Vec3::ZERO, Vec3::ONE, f32::INFINITY),
            None,
            "ray below the box"
        );
    }

    #[test]
    fn setters_keep_the_slab_values() {
        let target = (Vec3::new(2.0, 0.0, 0.0), Vec3::new(3.0, 1.0, 1.0));
        let mut r = Ray::new(Vec3::new(0.0, 0.5, 0.5), Vec3::Y);
        assert_eq!(r.hit_box(target.0, target.1, f32::INFINITY), None);
        r.set_dir(Vec3::X);
        assert_eq!(r.hit_box(target.0, target.1, f32::INFINITY), Some(2.0));
        r.set_origin(Vec3::new(-1.0, 0.0, 0.0));
        assert_eq!(r.hit_box(target.0, target.1, f32::INFINITY), Some(3.0));
        let fresh = Ray::new(r.origin(), r.dir());
        assert_eq!(r.inv_dir(), fresh.inv_dir());
        assert_eq!(r.slab_lo, fresh.slab_lo);
        assert_eq!(r.slab_hi, fresh.slab_hi);
    }

    #[test]
    fn segment_excludes_its_end() {
        let r = Ray::segment(Vec3::ZERO, Vec3::new(0.0, 0.0, 4.0));
        assert_eq!((r.tmin, r.tmax), (0.0, 1.0));
        assert_eq!(r.at(1.0), Vec3::new(0.0, 0.0, 4.0));
    }

    #[test]
    fn flat_box_is_hit() {
        let r = Ray::new(Vec3::new(0.5, 0.5, -1.0), Vec3::Z);
        let hit = r.hit_box(
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            f32::INFINITY,
        );
        assert_eq!(hit, Some(1.0));
    }
}
