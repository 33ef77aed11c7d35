//! Incoherent rays reordered before a batch is traced.
//!
//! Rays whose paths through the scene lie close together walk the same nodes and leaves; traced
//! one after the other, the second finds them in cache. Random rays (ambient occlusion, diffuse
//! bounces, a simulator's scattered queries) arrive in no such order, and on a tree larger than
//! the cache each of their walks waits on memory. Reordering them by where they travel is the
//! idea of memory-coherent ray tracing (Pharr et al. 1997) and of ray reordering by estimated
//! hit points (Moon et al. 2010); here each ray's key is the Morton code of the middle of its
//! span through the scene's box, 7 bits an axis, and the batch is sorted by key with a
//! least-significant-digit radix sort (two passes of 11 bits), linear in the rays.
//!
//! A batch whose adjacent rays already travel much closer together than rays far apart in it
//! (camera images, a lidar's sweep) is left as it is: a sample of pairs decides, before any key
//! of the whole batch is computed. Reordering changes which ray is traced when, never a ray's
//! answer.

use crate::geom::{Aabb, Ray};
use crate::parallel::Probe;
use glam::Vec3;
use rayon::prelude::*;

/// Bits of a key per axis.
const AXIS_BITS: u32 = 7;
/// Bits of one radix pass.
const DIGIT_BITS: u32 = 11;
/// Radix passes that cover a key.
const PASSES: usize = (3 * AXIS_BITS).div_ceil(DIGIT_BITS) as usize;
/// The key of a ray whose span misses the scene's box (or is not a number): the last cell's.
const MISS_KEY: u32 = (1 << (3 * AXIS_BITS)) - 1;
/// Pairs of rays sampled to judge a batch's coherence.
const COHERENCE_PAIRS: usize = 256;
/// How much closer than rays far apart adjacent rays are in a coherent batch.
const COHERENT_SHARE: f64 = 0.25;

/// Scratch for reordering batches of rays (reused: a batch allocates only to grow it past the
/// largest batch so far).
#[derive(Clone, Debug, Default)]
pub struct RayOrder {
    /// `key << 32 | index`, then the same sorted by the radix passes.
    pairs: Vec<u64>,
    tmp: Vec<u64>,
    /// The batch's indices in tracing order (when reordered).
    order: Vec<u32>,
}

impl RayOrder {
    /// Bytes held.
    #[must_use]
    pub fn memory_bytes(&self) -> usize {
        use crate::bvh::held;
        held(&self.pairs) + held(&self.tmp) + held(&self.order)
    }

    /// Batches smaller than this are traced as they come: their walks share little, and the
    /// sort's fixed costs (the digit counts) are not repaid.
    pub const MIN_RAYS: usize = 4096;

    /// Plans the order of `rays` against the scene's box `scene`: for a large incoherent batch,
    /// its indices in the order to trace them; `None` for a batch that is small or already
    /// coherent, to be traced as it comes.
    pub fn plan(&mut self, rays: &[Ray], scene: &Aabb) -> Option<&[u32]> {
        Self::reordered(rays, scene).then(|| self.by_key(rays, scene))
    }

    /// The indices of `rays` sorted by key, whatever the batch (at most `u32::MAX` rays).
    fn by_key(&mut self, rays: &[Ray], scene: &Aabb) -> &[u32] {
        let cells = Cells::new(scene);
        self.pairs.clear();
        self.pairs.extend(
            rays.iter()
                .enumerate()
                .map(|(i, r)| u64::from(cells.key(r)) << 32 | i as u64),
        );
        self.sort();
        &self.order
    }

    /// True when [`RayOrder::plan`] reorders the batch: it is large and incoherent.
    #[must_use]
    pub fn reordered(rays: &[Ray], scene: &Aabb) -> bool {
        rays.len() >= Self::MIN_RAYS && rays.len() <= u32::MAX as usize && !coherent(rays, scene)
    }

    /// Sorts `pairs` by key (stable, digit by digit from the least significant), writing the
    /// indices in key order to `order`.
    fn sort(&mut self) {
        const BUCKETS: usize = 1 << DIGIT_BITS;
        let n = self.pairs.len();
        // Every pass's digit counts in one read of the keys.
        let mut counts = [[0u32; BUCKETS]; PASSES];
        for &p in &self.pairs {
            let k = (p >> 32) as u32;
            for (pass, c) in counts.iter_mut().enumerate() {
                c[digit(k, pass)] += 1;
            }
        }
        self.tmp.resize(n, 0);
        self.order.resize(n, 0);
        for (pass, c) in counts.iter().enumerate() {
            let mut start = [0u32; BUCKETS];
            let mut sum = 0;
            for (s, &c) in start.iter_mut().zip(c) {
                *s = sum;
                sum += c;
            }
            let (from, to) = if pass % 2 == 0 {
                (&self.pairs, &mut self.tmp)
            } else {
                (&self.tmp, &mut self.pairs)
            };
            if pass == PASSES - 1 {
                for &p in from.iter() {
                    let d = digit((p >> 32) as u32, pass);
                    self.order[start[d] as usize] = p as u32;
                    start[d] += 1;
                }
            } else {
                for &p in from.iter() {
                    let d = digit((p >> 32) as u32, pass);
                    to[start[d] as usize] = p;
                    start[d] += 1;
                }
            }
        }
    }
}

/// Parts a batch is cut into a thread when there are several.
const PARTS_A_THREAD: usize = 4;

/// Rays a task answers at a time in a batch traced as it comes.
const RUN: usize = 256;

/// Rays ahead in the planned order whose data is asked for before their turn: they lie
/// anywhere in the batch.
const AHEAD: usize = 8;

/// Answers a batch of rays in parallel, `out[i] = f(&rays[i])`, in the order [`RayOrder`]
/// plans: the batch is cut into parts, a few a thread, and each part is ordered and answered
/// by one task (so the ordering runs in parallel too, and each task writes only its own part's
/// answers). Holds the scratch, reused between batches: a batch allocates only to grow it.
#[derive(Clone, Debug, Default)]
pub struct RayBatch {
    parts: Vec<RayOrder>,
}

impl RayBatch {
    /// Bytes held.
    #[must_use]
    pub fn memory_bytes(&self) -> usize {
        crate::bvh::held(&self.parts) + self.parts.iter().map(RayOrder::memory_bytes).sum::<usize>()
    }

    /// `out[i] = f(&rays[i])` for every ray, on the current rayon pool's threads; a batch that
    /// [`RayOrder::reordered`] judges incoherent against `scene` is answered part by part, each
    /// part in key order; the others as they come.
    ///
    /// # Panics
    /// When `out` and `rays` differ in length.
    pub fn run<T: Send>(
        &mut self,
        rays: &[Ray],
        scene: &Aabb,
        out: &mut [T],
        f: impl Fn(&Ray) -> T + Sync,
    ) {
        assert_eq!(rays.len(), out.len(), "one output per ray");
        if !RayOrder::reordered(rays, scene) {
            as_they_come(rays, out, f);
            return;
        }
        // One part on one thread; on several, a few a thread, so that a thread another
        // process holds up leaves its other parts to the rest.
        let threads = rayon::current_num_threads();
        let parts = if threads == 1 {
            1
        } else {
            PARTS_A_THREAD * threads
        }
        .min(rays.len() / RayOrder::MIN_RAYS)
        .max(1);
        let size = rays.len().div_ceil(parts).max(1);
        if self.parts.len() < parts {
            self.parts.resize_with(parts, RayOrder::default);
        }
        // A few rays spread over the batch, timed, decide whether the parts are worth the
        // pool; the parts answer them again (a few dozen among thousands).
        let split = Probe::run(rays.len(), |i| out[i] = f(&rays[i])).split();
        let part = |((order, rays), out): ((&mut RayOrder, &[Ray]), &mut [T])| {
            // Each part ordered as the batch was judged, not judged again.
            let order = order.by_key(rays, scene);
            for (j, &i) in order.iter().enumerate() {
                // The ray and its answer's slot a few rays ahead, anywhere in the part.
                if let Some(&next) = order.get(j + AHEAD) {
                    crate::simd::prefetch_all(&rays[next as usize]);
                    crate::simd::prefetch(&out[next as usize]);
                }
                out[i as usize] = f(&rays[i as usize]);
            }
        };
        if split {
            self.parts[..parts]
                .par_iter_mut()
                .zip(rays.par_chunks(size))
                .zip(out.par_chunks_mut(size))
                .for_each(part);
        } else {
            self.parts[..parts]
                .iter_mut()
                .zip(rays.chunks(size))
                .zip(out.chunks_mut(size))
                .for_each(part);
        }
    }
}

/// `out[i] = f(&rays[i])` in the batch's own order: on the current rayon pool's threads in runs
/// small enough to keep them evenly busy, or on the calling thread when the batch is too small
/// to be worth the pool ([`crate::parallel`]).
///
/// # Panics
/// When `out` and `rays` differ in length.
pub fn as_they_come<T: Send>(rays: &[Ray], out: &mut [T], f: impl Fn(&Ray) -> T + Sync) {
    crate::parallel::map(rays, out, RUN, f);
}

/// Digit `pass` of a key, from the least significant.
#[inline(always)]
fn digit(key: u32, pass: usize) -> usize {
    ((key >> (pass as u32 * DIGIT_BITS)) & ((1 << DIGIT_BITS) - 1)) as usize
}

/// True when adjacent rays travel much closer together than rays far apart in the batch: over
/// a sample of pairs spread through the batch, the middles of adjacent rays' spans lie less
/// than [`COHERENT_SHARE`] as far apart as those of rays half a batch apart (pairs with a ray
/// that misses the box left out). Scale-free: a coarse camera image is coherent as a fine one
/// is.
fn coherent(rays: &[Ray], scene: &Aabb) -> bool {
    let cells = Cells::new(scene);
    let pairs = COHERENCE_PAIRS.min(rays.len() / 2);
    let step = (rays.len() / 2).div_ceil(pairs.max(1)).max(1);
    let half = rays.len() / 2;
    let (mut near, mut far) = (0.0f64, 0.0f64);
    for i in (0..half).step_by(step) {
        let (Some(a), Some(b), Some(c)) = (
            cells.middle(&rays[i]),
            cells.middle(&rays[i + 1]),
            cells.middle(&rays[i + half]),
        ) else {
            continue;
        };
        near += f64::from(a.distance(b));
        far += f64::from(a.distance(c));
    }
    // No spread at all (every sampled ray misses the box, or they are one ray): nothing to
    // gain from an order.
    far == 0.0 || near < COHERENT_SHARE * far
}

/// The scene's box cut into `2^AXIS_BITS` cells an axis.
struct Cells {
    min: Vec3,
    max: Vec3,
    /// Cells per unit length on each axis.
    scale: Vec3,
}

impl Cells {
    fn new(scene: &Aabb) -> Self {
        let cells = (1u32 << AXIS_BITS) as f32;
        // A flat box (a ground plane) is one cell thick on its flat axis; a scale that is not
        // finite (a box of subnormal size) likewise.
        let per_unit = |size: f32| {
            let scale = cells / size;
            if size > 0.0 && scale < f32::INFINITY {
                scale
            } else {
                0.0
            }
        };
        let size = scene.max - scene.min;
        Self {
            min: scene.min,
            max: scene.max,
            scale: Vec3::new(per_unit(size.x), per_unit(size.y), per_unit(size.z)),
        }
    }

    /// The middle of the ray's span through the box (within its own interval), in cells from
    /// the box's lower corner; `None` when the span misses the box or is not a number.
    #[inline(always)]
    fn middle(&self, r: &Ray) -> Option<Vec3> {
        let (o, inv) = (r.origin(), r.inv_dir());
        let t0 = (self.min - o) * inv;
        let t1 = (self.max - o) * inv;
        let near = t0.min(t1).max_element().max(r.tmin);
        let far = t0.max(t1).min_element().min(r.tmax);
        let mid = (o + r.dir() * (0.5 * (near + far)) - self.min) * self.scale;
        // Not `near > far`: a NaN span is a miss too.
        (near <= far && mid.is_finite()).then_some(mid)
    }

    /// The Morton code of the cell holding the middle of the ray's span through the box
    /// (within its own interval); [`MISS_KEY`] for a ray whose span misses the box. Not
    /// inlined: inlined, the key loop is vectorised with gathers of the rays' fields, which
    /// take longer than the scalar loop.
    #[inline(never)]
    fn key(&self, r: &Ray) -> u32 {
        let Some(mid) = self.middle(r) else {
            return MISS_KEY;
        };
        let top = ((1u32 << AXIS_BITS) - 1) as f32;
        // Non-negative and at most `top` (the `as` conversion saturates at 0 for the rest).
        let p = mid.min(Vec3::splat(top)).to_array().map(|x| x as u32);
        spread(p[0]) | spread(p[1]) << 1 | spread(p[2]) << 2
    }
}

/// The low [`AXIS_BITS`] bits of `v` moved to every third bit.
fn spread(v: u32) -> u32 {
    let mut x = v & 0x3ff;
    x = (x | x << 16) & 0x0300_00ff;
    x = (x | x << 8) & 0x0300_f00f;
    x = (x | x << 4) & 0x030c_30c3;
    (x | x << 2) & 0x0924_9249
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(r: &Ray, scene: &Aabb) -> u32 {
        Cells::new(scene).key(r)
    }

    fn unit() -> Aabb {
        Aabb {
            min: Vec3::ZERO,
            max: Vec3::ONE,
        }
    }

    /// Rays from points spread over the unit box in directions that change from ray to ray.
    fn scattered(n: usize) -> Vec<Ray> {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut f = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        (0..n)
            .map(|_| {
                let o = Vec3::new(f(), f(), f());
                let d = Vec3::new(f() - 0.5, f() - 0.5, f() - 0.5);
                Ray::new(o, d)
            })
            .collect()
    }

    #[test]
    fn spread_interleaves_the_bits() {
        assert_eq!(spread(0b1), 0b1);
        assert_eq!(spread(0b11), 0b1001);
        assert_eq!(spread(0x3ff), 0x0924_9249);
        // Keys order cells along the Z curve: x is the lowest bit of each triple.
        let k = |x, y, z| spread(x) | spread(y) << 1 | spread(z) << 2;
        assert_eq!(k(1, 0, 0), 1);
        assert_eq!(k(0, 1, 0), 2);
        assert_eq!(k(0, 0, 1), 4);
        assert_eq!(k(2, 0, 0), 8);
    }

    #[test]
    fn an_incoherent_batch_is_ordered_by_key_and_keeps_every_ray_once() {
        let rays = scattered(20_000);
        let scene = unit();
        let mut o = RayOrder::default();
        let order = o
            .plan(&rays, &scene)
            .expect("scattered rays are reordered")
            .to_vec();
        let mut seen = vec![false; rays.len()];
        for &i in &order {
            assert!(!seen[i as usize], "ray {i} twice");
            seen[i as usize] = true;
        }
        assert!(seen.iter().all(|&s| s));
        // Sorted by key; equal keys keep their input order (the sort is stable).
        for w in order.windows(2) {
            let (a, b) = (w[0] as usize, w[1] as usize);
            let (ka, kb) = (key(&rays[a], &scene), key(&rays[b], &scene));
            assert!(ka < kb || (ka == kb && a < b), "{ka} {kb}");
        }
        // The scratch is reused: a second batch gives its own order.
        let fewer = &rays[..10_000];
        let again = o.plan(fewer, &scene).unwrap();
        assert_eq!(again.len(), fewer.len());
    }

    #[test]
    fn coherent_and_small_batches_keep_their_order() {
        let scene = unit();
        let mut o = RayOrder::default();
        // A camera's rows, coarse or fine: neighbours travel side by side.
        let eye = Vec3::new(0.5, 0.5, -2.0);
        for side in [64, 128, 512] {
            let camera: Vec<Ray> = (0..side * side)
                .map(|i| {
                    let (x, y) = ((i % side) as f32, (i / side) as f32);
                    let target = Vec3::new(x / side as f32, y / side as f32, 0.5);
                    Ray::new(eye, target - eye)
                })
                .collect();
            assert!(o.plan(&camera, &scene).is_none(), "{side}x{side}");
        }
        assert!(o.plan(&scattered(RayOrder::MIN_RAYS - 1), &scene).is_none());
        // Every ray misses the box: no order helps.
        let away = vec![Ray::new(Vec3::splat(3.0), Vec3::ONE); RayOrder::MIN_RAYS];
        assert!(o.plan(&away, &scene).is_none());
        assert!(o.plan(&[], &scene).is_none());
    }

    #[test]
    fn a_flat_scene_orders_its_rays_on_its_other_two_axes() {
        // A ground plane at y = 0, rays from scattered points above it to scattered points in
        // it (away from its edges).
        let scene = Aabb {
            min: Vec3::new(0.0, 0.0, 0.0),
            max: Vec3::new(1.0, 0.0, 1.0),
        };
        let a = scattered(20_000);
        let b = scattered(20_000 + 7);
        let rays: Vec<Ray> = a
            .iter()
            .zip(&b[7..])
            .map(|(p, q)| {
                let from = p.origin() + Vec3::Y;
                let to = Vec3::new(0.05 + 0.9 * q.origin().x, 0.0, 0.05 + 0.9 * q.origin().z);
                Ray::new(from, to - from)
            })
            .collect();
        let keys: Vec<u32> = rays.iter().map(|r| key(r, &scene)).collect();
        assert!(
            keys.iter().all(|&k| k != MISS_KEY),
            "every ray meets the plane"
        );
        assert!(
            keys.iter().any(|&k| k != keys[0]),
            "keys spread over the plane"
        );
        assert!(RayOrder::default().plan(&rays, &scene).is_some());
    }

    #[test]
    fn rays_that_miss_the_scene_or_are_not_numbers_go_last() {
        let scene = unit();
        let mut rays = scattered(RayOrder::MIN_RAYS * 2);
        let away = Ray::new(Vec3::splat(3.0), Vec3::ONE);
        let nan = Ray::new(Vec3::splat(f32::NAN), Vec3::X);
        rays[7] = away;
        rays[100] = nan;
        assert_eq!(key(&away, &scene), MISS_KEY);
        assert_eq!(key(&nan, &scene), MISS_KEY);
        let mut o = RayOrder::default();
        let order = o.plan(&rays, &scene).unwrap();
        assert_eq!(&order[order.len() - 2..], &[7, 100]);
    }
}
