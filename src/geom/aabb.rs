use glam::Vec3;

/// Axis-aligned bounding box. The empty box has `min = +inf`, `max = -inf`, so that growing it by
/// any point gives that point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Lower corner.
    pub min: Vec3,
    /// Upper corner.
    pub max: Vec3,
}

impl Default for Aabb {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Aabb {
    /// The empty box: the identity of [`Aabb::union`].
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    /// A box from its two corners.
    #[must_use]
    pub const fn new(min: Vec3, max: Vec3) -> Self {
        Self { min, max }
    }

    /// The smallest box holding all `points`.
    #[must_use]
    pub fn from_points(points: &[Vec3]) -> Self {
        points.iter().fold(Self::EMPTY, |b, &p| b.grow(p))
    }

    /// This box grown to hold `p`.
    #[must_use]
    #[inline]
    pub fn grow(self, p: Vec3) -> Self {
        Self {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    /// The smallest box holding both.
    #[must_use]
    #[inline]
    pub fn union(self, o: Aabb) -> Self {
        Self {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    /// True when the box holds no point.
    #[must_use]
    #[inline]
    pub fn is_empty(&self) -> bool {
        !(self.min.x <= self.max.x && self.min.y <= self.max.y && self.min.z <= self.max.z)
    }

    /// `max - min` (negative for the empty box).
    #[must_use]
    #[inline]
    pub fn extent(&self) -> Vec3 {
        self.max - self.min
    }

    /// The centre point.
    #[must_use]
    #[inline]
    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    /// Half the surface area (`xy + yz + zx`); 0 for the empty box. SAH costs only use ratios
    /// of areas, so the factor 2 is left out.
    #[must_use]
    #[inline]
    pub fn half_area(&self) -> f32 {
        let e = (self.max - self.min).max(Vec3::ZERO);
        e.x * e.y + e.y * e.z + e.z * e.x
    }

    /// [`Aabb::half_area`] in `f64`, which does not overflow for any finite box (the `f32`
    /// products overflow once extents pass about 1e19), for costs summed over a tree.
    #[must_use]
    #[inline]
    pub fn half_area_f64(&self) -> f64 {
        let e = (self.max - self.min).max(Vec3::ZERO);
        let (x, y, z) = (f64::from(e.x), f64::from(e.y), f64::from(e.z));
        x * y + y * z + z * x
    }

    /// Index (0, 1, 2) of the longest axis.
    #[must_use]
    pub fn largest_axis(&self) -> usize {
        let e = self.extent();
        if e.x >= e.y && e.x >= e.z {
            0
        } else if e.y >= e.z {
            1
        } else {
            2
        }
    }

    /// True when `o` lies inside this box (boundaries included). The empty box is inside every box.
    #[must_use]
    pub fn contains(&self, o: &Aabb) -> bool {
        o.is_empty() || (self.min.cmple(o.min).all() && o.max.cmple(self.max).all())
    }

    /// The box of a triangle as trees store it: NaN coordinates are ignored (an axis on which
    /// all three are NaN is empty), infinite ones clamped (see [`Aabb::sanitized`]).
    #[must_use]
    #[inline]
    pub fn of_triangle(t: &[Vec3; 3]) -> Self {
        // `f32::min`/`max` skip a NaN operand, unlike glam's vector min/max.
        let lo = |k: usize| t[0][k].min(t[1][k]).min(t[2][k]);
        let hi = |k: usize| t[0][k].max(t[1][k]).max(t[2][k]);
        Self::new(
            Vec3::new(lo(0), lo(1), lo(2)),
            Vec3::new(hi(0), hi(1), hi(2)),
        )
        .sanitized()
    }

    /// This box with every bound a finite number, so that unions, areas and centroids never
    /// produce NaN: a NaN bound makes its axis empty (`min = f32::MAX`, `max = -f32::MAX`),
    /// infinite bounds are clamped to `±f32::MAX`.
    #[must_use]
    #[inline]
    pub fn sanitized(self) -> Self {
        let fix = |v: f32, if_nan: f32| {
            if v.is_nan() {
                if_nan
            } else {
                v.clamp(-f32::MAX, f32::MAX)
            }
        };
        Self::new(
            Vec3::new(
                fix(self.min.x, f32::MAX),
                fix(self.min.y, f32::MAX),
                fix(self.min.z, f32::MAX),
            ),
            Vec3::new(
                fix(self.max.x, -f32::MAX),
                fix(self.max.y, -f32::MAX),
                fix(self.max.z, -f32::MAX),
            ),
        )
    }

    /// The box of this box transformed by `m` (Arvo's method: centre and absolute-matrix
    /// extent), widened by a few ulps so that every transformed point of the box, rounded as
    /// `m.transform_point3` rounds it, lies inside. The empty box stays empty.
    #[must_use]
    pub fn transformed(&self, m: &glam::Affine3A) -> Self {
        if self.is_empty() {
            return *self;
        }
        let c = m.transform_point3(self.center());
        let h = self.extent() * 0.5;
        let a = m.matrix3;
        let e = Vec3::from(a.x_axis.abs() * h.x + a.y_axis.abs() * h.y + a.z_axis.abs() * h.z);
        let pad = (c.abs() + e) * (4.0 * f32::EPSILON);
        Self::new(c - e - pad, c + e + pad)
    }

    /// True when both corners are finite numbers.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.min.is_finite() && self.max.is_finite()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_is_identity_of_union() {
        let b = Aabb::new(Vec3::new(-1.0, 0.0, 2.0), Vec3::new(1.0, 3.0, 4.0));
        assert_eq!(Aabb::EMPTY.union(b), b);
        assert!(Aabb::EMPTY.is_empty());
        assert_eq!(Aabb::EMPTY.half_area(), 0.0);
        assert!(b.contains(&Aabb::EMPTY));
        assert_eq!(b.half_area(), 2.0 * 3.0 + 3.0 * 2.0 + 2.0 * 2.0);
        assert_eq!(b.largest_axis(), 1);
    }
}
