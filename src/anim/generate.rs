//! Deterministic animated test scenes written as `.glb`, each with the generator's own
//! analytic world positions at a few key times (to check the loader and poser against).

mod lidar_cloth;

use super::glb_writer::GlbWriter;
use glam::{Mat4, Quat, Vec3};
use serde_json::json;
use std::f32::consts::{PI, TAU};

/// Which scene to generate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// A skinned tube bending on a chain of joints (LINEAR rotations).
    Tube,
    /// A grid with a travelling wave from two morph targets (CUBICSPLINE weights).
    Wave,
    /// Many rigid cubes orbiting (LINEAR rotations) or hopping (STEP translations).
    Orbit,
    /// A sphere whose triangles fly apart along their normals (one morph target).
    Explode,
    /// Two halves of a mesh that trade places (one morph target).
    Swap,
    /// A sensor scene: a cloth sheet that billows, ripples and folds over (morph targets and a
    /// skinned hinge) over a static ground, with a few rigid boxes moving above and around it
    /// (LINEAR node translations and rotations).
    LidarCloth,
}

impl Kind {
    /// All kinds.
    pub const ALL: [Kind; 6] = [
        Kind::Tube,
        Kind::Wave,
        Kind::Orbit,
        Kind::Explode,
        Kind::Swap,
        Kind::LidarCloth,
    ];

    /// Lower-case name, as the CLI takes it.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Kind::Tube => "tube",
            Kind::Wave => "wave",
            Kind::Orbit => "orbit",
            Kind::Explode => "explode",
            Kind::Swap => "swap",
            Kind::LidarCloth => "lidar-cloth",
        }
    }

    /// Parses a name from [`Kind::name`].
    #[must_use]
    pub fn parse(s: &str) -> Option<Kind> {
        Kind::ALL.into_iter().find(|k| k.name() == s)
    }
}

/// A generated file and what the generator knows about it.
pub struct Generated {
    /// The `.glb` bytes.
    pub glb: Vec<u8>,
    /// Triangles in the flattened scene.
    pub triangles: usize,
    /// Duration of the (single) animation in seconds.
    pub duration: f32,
    /// Analytic world positions of the flattened scene (instances in depth-first order) at a
    /// few key times: `(t, positions)`.
    pub checks: Vec<(f32, Vec<Vec3>)>,
}

/// A small deterministic random generator (xorshift64*).
struct Rng(u64);

impl Rng {
    fn new(seed: u64) -> Rng {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    /// Uniform in [0, 1).
    fn next(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let x = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D);
        (x >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// Generates `kind` with about `triangles` triangles (at least a small minimum); the same
/// arguments always give the same bytes.
#[must_use]
pub fn generate(kind: Kind, triangles: usize, seed: u64) -> Generated {
    let n = triangles.max(16);
    match kind {
        Kind::Tube => skinned_tube(n, 4, TubeWeights::Linear),
        Kind::Wave => wave(n),
        Kind::Orbit => orbit(n, seed),
        Kind::Explode => explode(n, seed),
        Kind::Swap => swap(n),
        Kind::LidarCloth => lidar_cloth::lidar_cloth(n, seed),
    }
}

/// A grid of `cols` × `rows` quads over `[0,1]²` mapped by `f`, as positions and triangles.
fn grid(cols: usize, rows: usize, f: impl Fn(f32, f32) -> Vec3) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let mut pos = Vec::with_capacity((cols + 1) * (rows + 1));
    for r in 0..=rows {
        for c in 0..=cols {
            pos.push(f(c as f32 / cols as f32, r as f32 / rows as f32));
        }
    }
    let mut tris = Vec::with_capacity(cols * rows * 2);
    let w = cols as u32 + 1;
    for r in 0..rows as u32 {
        for c in 0..cols as u32 {
            let a = r * w + c;
            tris.push([a, a + 1, a + w + 1]);
            tris.push([a, a + w + 1, a + w]);
        }
    }
    (pos, tris)
}

/// Key times `0, d/(k-1), ..., d`.
fn key_times(k: usize, d: f32) -> Vec<f32> {
    (0..k).map(|i| d * i as f32 / (k - 1) as f32).collect()
}

/// A primitive JSON with positions, indices and optional extra attributes/targets.
fn primitive(pos: usize, idx: usize) -> serde_json::Value {
    json!({"attributes": {"POSITION": pos}, "indices": idx})
}

/// How [`skinned_tube`] weights its vertices to the joints.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TubeWeights {
    /// Two influences: linear interpolation between the two joints around the vertex (joints
    /// from the tube's bottom to its top). [`Kind::Tube`] is this with 4 joints.
    Linear,
    /// Four influences, all non-zero on every vertex: the uniform cubic B-spline weights of the
    /// four joints around the vertex (a smooth falloff that sums to 1). The first and last
    /// joints sit beyond the tube's ends, and no ring of vertices lies on a knot of the spline,
    /// where one of the four weights would vanish.
    Cubic,
}

impl TubeWeights {
    /// Non-zero weights per vertex.
    #[must_use]
    pub fn influences(self) -> usize {
        match self {
            TubeWeights::Linear => 2,
            TubeWeights::Cubic => 4,
        }
    }
}

/// The four uniform cubic B-spline weights at fraction `f` of a knot interval (in f64: near a
/// knot the smallest weight is `f³/6`, which must not round to zero).
fn cubic_bspline(f: f64) -> [f32; 4] {
    let g = 1.0 - f;
    let (f2, f3) = (f * f, f * f * f);
    [
        g * g * g / 6.0,
        (3.0 * f3 - 6.0 * f2 + 4.0) / 6.0,
        (-3.0 * f3 + 3.0 * f2 + 3.0 * f + 1.0) / 6.0,
        f3 / 6.0,
    ]
    .map(|w| w as f32)
}

/// A skinned tube along +y, about `triangles` triangles, bending on a chain of `joints` joints
/// (LINEAR rotations, each joint after the first bending about z) with `weights` per vertex.
///
/// `joints` is at least 2 for [`TubeWeights::Linear`]; for [`TubeWeights::Cubic`] it is at
/// least 4 and rounded up to an even count (which keeps rings off the spline's knots).
/// `skinned_tube(n, 4, TubeWeights::Linear)` is `generate(Kind::Tube, n, _)`, byte for byte.
#[must_use]
pub fn skinned_tube(triangles: usize, joints: usize, weights: TubeWeights) -> Generated {
    const SEG: usize = 16;
    const HEIGHT: f32 = 4.0;
    const DUR: f32 = 2.0;
    let n = triangles.max(16);
    let cubic = weights == TubeWeights::Cubic;
    let joint_count = if cubic {
        joints.max(4).next_multiple_of(2)
    } else {
        joints.max(2)
    };
    let rings = (n / (2 * SEG)).max(1);
    let (pos, tris) = grid(SEG, rings, |u, v| {
        let a = u * TAU;
        Vec3::new(0.3 * a.cos(), v * HEIGHT, -0.3 * a.sin())
    });
    // Joint j sits at height `base + j * step`. Linear: joints from the bottom to the top.
    // Cubic: the spline parameter is u = j at joint j; the tube spans u in (1, J - 2), offset
    // by half a ring so that with J - 3 odd no ring height (2r + 1) h / 2 is a knot.
    let ring = HEIGHT / rings as f32;
    let (base, step) = if cubic {
        let step = (HEIGHT + ring) / (joint_count - 3) as f32;
        (-step - ring / 2.0, step)
    } else {
        (0.0, HEIGHT / (joint_count - 1) as f32)
    };
    let mut joint_ids = Vec::with_capacity(pos.len());
    let mut joint_weights = Vec::with_capacity(pos.len());
    for p in &pos {
        if cubic {
            let u = ((f64::from(p.y) - f64::from(base)) / f64::from(step))
                .clamp(1.0, (joint_count - 2) as f64);
            let k = (u.floor() as usize).clamp(1, joint_count - 3);
            let j = (k - 1) as u16;
            joint_ids.push([j, j + 1, j + 2, j + 3]);
            joint_weights.push(cubic_bspline(u - k as f64));
        } else {
            let u = (p.y / step).clamp(0.0, (joint_count - 1) as f32);
            let j = (u.floor() as usize).min(joint_count - 2);
            let f = u - j as f32;
            joint_ids.push([j as u16, j as u16 + 1, 0, 0]);
            joint_weights.push([1.0 - f, f, 0.0, 0.0]);
        }
    }
    let times = key_times(17, DUR);
    // Joint j > 0 bends about z by 0.6 (3 / (J - 1)) sin(2πt/DUR + j): 0.6 for 4 joints.
    let amplitude = 0.6 * (3.0 / (joint_count - 1) as f32);
    let angle = |j: usize, t: f32| amplitude * (TAU * t / DUR + j as f32).sin();
    let ibm: Vec<Mat4> = (0..joint_count)
        .map(|j| Mat4::from_translation(Vec3::new(0.0, -(base + j as f32 * step), 0.0)))
        .collect();
    let mut w = GlbWriter::default();
    let pa = w.vec3s(&pos);
    let ia = w.indices(&tris);
    let ja = w.joints(&joint_ids);
    let wflat: Vec<f32> = joint_weights.iter().flatten().copied().collect();
    let wa = w.floats(&wflat, "VEC4", 4);
    let ba = w.mat4s(&ibm);
    let ta = w.scalars(&times);
    let mut nodes = vec![];
    let mut channels = vec![];
    let mut samplers = vec![];
    for j in 0..joint_count {
        let mut node = json!({"name": format!("joint{j}")});
        if j > 0 {
            node["translation"] = json!([0.0, step, 0.0]);
        } else if base != 0.0 {
            node["translation"] = json!([0.0, base, 0.0]);
        }
        if j + 1 < joint_count {
            node["children"] = json!([j + 1]);
        }
        nodes.push(node);
        if j > 0 {
            let q: Vec<Quat> = times
                .iter()
                .map(|&t| Quat::from_rotation_z(angle(j, t)))
                .collect();
            let oa = w.quats(&q);
            samplers.push(json!({"input": ta, "output": oa, "interpolation": "LINEAR"}));
            channels.push(
                json!({"sampler": samplers.len() - 1, "target": {"node": j, "path": "rotation"}}),
            );
        }
    }
    // The skinned node has a transform that skinning must ignore.
    nodes.push(json!({"name": "tube", "mesh": 0, "skin": 0, "translation": [5.0, 0.0, 0.0]}));
    let mut prim = primitive(pa, ia);
    prim["attributes"]["JOINTS_0"] = json!(ja);
    prim["attributes"]["WEIGHTS_0"] = json!(wa);
    let root = json!({
        "scene": 0,
        "scenes": [{"nodes": [0, joint_count]}],
        "nodes": nodes,
        "meshes": [{"name": "tube", "primitives": [prim]}],
        "skins": [{"joints": (0..joint_count).collect::<Vec<_>>(), "inverseBindMatrices": ba, "skeleton": 0}],
        "animations": [{"name": "bend", "channels": channels, "samplers": samplers}],
    });
    let influences = weights.influences();
    let checks = [0usize, 3, 8, 13]
        .iter()
        .map(|&k| {
            let t = times[k];
            let mut world = Mat4::from_translation(Vec3::new(0.0, base, 0.0));
            let mut jm = Vec::with_capacity(joint_count);
            for (j, b) in ibm.iter().enumerate() {
                if j > 0 {
                    world = world
                        * Mat4::from_translation(Vec3::new(0.0, step, 0.0))
                        * Mat4::from_quat(Quat::from_rotation_z(angle(j, t)));
                }
                jm.push(world * *b);
            }
            let p = pos
                .iter()
                .zip(joint_ids.iter().zip(&joint_weights))
                .map(|(p, (j, w))| {
                    (0..influences)
                        .map(|i| w[i] * jm[j[i] as usize].transform_point3(*p))
                        .sum()
                })
                .collect();
            (t, p)
        })
        .collect();
    Generated {
        glb: w.finish(root),
        triangles: tris.len(),
        duration: DUR,
        checks,
    }
}

/// Grid with a travelling wave: targets sin and cos of x, weights (cos φ, sin φ) as
/// CUBICSPLINE keys with exact derivatives as tangents.
fn wave(n: usize) -> Generated {
    const DUR: f32 = 2.0;
    let side = ((n / 2) as f32).sqrt().ceil().max(2.0) as usize;
    let (pos, tris) = grid(side, side, |u, v| {
        Vec3::new(4.0 * u - 2.0, 4.0 * v - 2.0, 0.0)
    });
    let theta = |p: &Vec3| p.x * PI;
    let d_sin: Vec<Vec3> = pos.iter().map(|p| Vec3::Z * 0.3 * theta(p).sin()).collect();
    let d_cos: Vec<Vec3> = pos.iter().map(|p| Vec3::Z * 0.3 * theta(p).cos()).collect();
    let times = key_times(9, DUR);
    let phi = |t: f32| TAU * t / DUR;
    let dphi = TAU / DUR;
    let mut values = Vec::new();
    for &t in &times {
        let (s, c) = phi(t).sin_cos();
        values.extend([-s * dphi, c * dphi]); // in-tangent
        values.extend([c, s]); // value
        values.extend([-s * dphi, c * dphi]); // out-tangent
    }
    let mut w = GlbWriter::default();
    let pa = w.vec3s(&pos);
    let ia = w.indices(&tris);
    let sa = w.vec3s(&d_sin);
    let ca = w.vec3s(&d_cos);
    let ta = w.scalars(&times);
    let oa = w.scalars(&values);
    let mut prim = primitive(pa, ia);
    prim["targets"] = json!([{"POSITION": sa}, {"POSITION": ca}]);
    let root = json!({
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "wave", "mesh": 0, "rotation": Quat::from_rotation_x(-PI / 2.0).to_array()}],
        "meshes": [{"name": "wave", "primitives": [prim], "weights": [1.0, 0.0]}],
        "animations": [{"name": "travel", "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}],
            "samplers": [{"input": ta, "output": oa, "interpolation": "CUBICSPLINE"}]}],
    });
    let node = Mat4::from_quat(Quat::from_rotation_x(-PI / 2.0));
    let checks = [0usize, 1, 3, 6]
        .iter()
        .map(|&k| {
            let (s, c) = phi(times[k]).sin_cos();
            let p = (0..pos.len())
                .map(|v| node.transform_point3(pos[v] + c * d_sin[v] + s * d_cos[v]))
                .collect();
            (times[k], p)
        })
        .collect();
    Generated {
        glb: w.finish(root),
        triangles: tris.len(),
        duration: DUR,
        checks,
    }
}

/// A unit cube's corners and triangles, scaled by `s`.
fn cube(s: f32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let pos = (0..8)
        .map(|i| {
            Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32) * s - s / 2.0
        })
        .collect();
    let tris = vec![
        [0, 2, 1],
        [1, 2, 3],
        [4, 5, 6],
        [5, 7, 6],
        [0, 1, 4],
        [1, 5, 4],
        [2, 6, 3],
        [3, 6, 7],
        [0, 4, 2],
        [2, 4, 6],
        [1, 3, 5],
        [3, 7, 5],
    ];
    (pos, tris)
}

/// Cubes on pivots: even pivots spin about y (LINEAR), odd pivots hop (STEP translation).
fn orbit(n: usize, seed: u64) -> Generated {
    const DUR: f32 = 4.0;
    let count = (n / 12).max(2);
    let (pos, tris) = cube(0.2);
    let side = (count as f32).sqrt().ceil() as usize;
    let mut rng = Rng::new(seed);
    let times = key_times(9, DUR);
    let mut w = GlbWriter::default();
    let pa = w.vec3s(&pos);
    let ia = w.indices(&tris);
    let ta = w.scalars(&times);
    // Spin: 8 eighth-turns (slerp takes the short way between keys 45° apart).
    let spin: Vec<Quat> = times
        .iter()
        .map(|&t| Quat::from_rotation_y(TAU * t / DUR))
        .collect();
    let spin_a = w.quats(&spin);
    let (mut nodes, mut roots, mut channels, mut samplers) = (vec![], vec![], vec![], vec![]);
    samplers.push(json!({"input": ta, "output": spin_a, "interpolation": "LINEAR"}));
    let mut placements = Vec::with_capacity(count);
    for i in 0..count {
        let centre = Vec3::new((i % side) as f32, 0.0, (i / side) as f32) * 1.5;
        let radius = 0.3 + 0.4 * rng.next();
        let pivot = nodes.len();
        roots.push(pivot);
        nodes.push(json!({"translation": centre.to_array(), "children": [pivot + 1]}));
        nodes.push(json!({"mesh": 0, "translation": [radius, 0.0, 0.0]}));
        let hops: Vec<Vec3> = if i % 2 == 0 {
            channels.push(json!({"sampler": 0, "target": {"node": pivot, "path": "rotation"}}));
            Vec::new()
        } else {
            let h: Vec<Vec3> = times
                .iter()
                .map(|_| centre + Vec3::new(0.0, rng.next(), 0.0))
                .collect();
            let oa = w.vec3s(&h);
            samplers.push(json!({"input": ta, "output": oa, "interpolation": "STEP"}));
            channels.push(json!({"sampler": samplers.len() - 1, "target": {"node": pivot, "path": "translation"}}));
            h
        };
        placements.push((centre, radius, hops));
    }
    let root = json!({
        "scene": 0,
        "scenes": [{"nodes": roots}],
        "nodes": nodes,
        "meshes": [{"name": "cube", "primitives": [primitive(pa, ia)]}],
        "animations": [{"name": "orbit", "channels": channels, "samplers": samplers}],
    });
    let checks = [0usize, 2, 5, 8]
        .iter()
        .map(|&k| {
            let t = times[k];
            let mut out = Vec::with_capacity(count * pos.len());
            for (centre, radius, hops) in &placements {
                let pivot = if hops.is_empty() {
                    Mat4::from_translation(*centre) * Mat4::from_quat(spin[k])
                } else {
                    Mat4::from_translation(hops[k])
                };
                let m = pivot * Mat4::from_translation(Vec3::new(*radius, 0.0, 0.0));
                out.extend(pos.iter().map(|p| m.transform_point3(*p)));
            }
            (t, out)
        })
        .collect();
    Generated {
        glb: w.finish(root),
        triangles: count * tris.len(),
        duration: DUR,
        checks,
    }
}

/// Triangle soup sphere; one target pushes each triangle out along its normal.
fn explode(n: usize, seed: u64) -> Generated {
    const DUR: f32 = 2.0;
    let cols = ((n as f32).sqrt() * 1.4).ceil().max(4.0) as usize;
    let rows = (n / (2 * cols)).max(2);
    let (gp, gt) = grid(cols, rows, |u, v| {
        let (a, b) = (u * TAU, (v - 0.5) * PI * 0.98);
        Vec3::new(b.cos() * a.cos(), b.sin(), -b.cos() * a.sin())
    });
    let mut rng = Rng::new(seed);
    let mut pos = Vec::with_capacity(gt.len() * 3);
    let mut delta = Vec::with_capacity(gt.len() * 3);
    let mut tris = Vec::with_capacity(gt.len());
    for t in &gt {
        let c = t.map(|i| gp[i as usize]);
        let normal = (c[1] - c[0]).cross(c[2] - c[0]).normalize_or_zero();
        let d = normal * (1.0 + 2.0 * rng.next());
        let base = pos.len() as u32;
        pos.extend(c);
        delta.extend([d; 3]);
        tris.push([base, base + 1, base + 2]);
    }
    let times = vec![0.0, 1.0, 2.0];
    let values = [0.0f32, 1.0, 0.0];
    morph_file("explode", &pos, &tris, &delta, &times, &values, DUR)
}

/// Two grids that trade places through each other.
fn swap(n: usize) -> Generated {
    const DUR: f32 = 2.0;
    let side = ((n / 4) as f32).sqrt().ceil().max(2.0) as usize;
    let (a, at) = grid(side, side, |u, v| {
        Vec3::new(u - 2.5, v - 0.5, 0.1 * (u * 7.0).sin())
    });
    let mut pos = a.clone();
    let mut tris = at.clone();
    let base = pos.len() as u32;
    pos.extend(a.iter().map(|p| Vec3::new(p.x + 4.0, p.y, -p.z)));
    tris.extend(at.iter().map(|t| t.map(|i| i + base)));
    let delta: Vec<Vec3> = (0..pos.len())
        .map(|i| {
            if i < base as usize {
                Vec3::X * 4.0
            } else {
                Vec3::X * -4.0
            }
        })
        .collect();
    let times = vec![0.0, 1.0, 2.0];
    let values = [0.0f32, 1.0, 0.0];
    morph_file("swap", &pos, &tris, &delta, &times, &values, DUR)
}

/// A one-node, one-target morph animation with LINEAR weights.
fn morph_file(
    name: &str,
    pos: &[Vec3],
    tris: &[[u32; 3]],
    delta: &[Vec3],
    times: &[f32],
    values: &[f32],
    dur: f32,
) -> Generated {
    let mut w = GlbWriter::default();
    let pa = w.vec3s(pos);
    let ia = w.indices(tris);
    let da = w.vec3s(delta);
    let ta = w.scalars(times);
    let oa = w.scalars(values);
    let mut prim = primitive(pa, ia);
    prim["targets"] = json!([{"POSITION": da}]);
    let root = json!({
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": name, "mesh": 0}],
        "meshes": [{"name": name, "primitives": [prim]}],
        "animations": [{"name": name, "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}],
            "samplers": [{"input": ta, "output": oa, "interpolation": "LINEAR"}]}],
    });
    let mut checks: Vec<(f32, Vec<Vec3>)> = times
        .iter()
        .zip(values)
        .map(|(&t, &wt)| {
            (
                t,
                pos.iter().zip(delta).map(|(p, d)| *p + wt * *d).collect(),
            )
        })
        .collect();
    // Half way between the first two keys, LINEAR gives the average weight.
    let wt = (values[0] + values[1]) / 2.0;
    checks.push((
        (times[0] + times[1]) / 2.0,
        pos.iter().zip(delta).map(|(p, d)| *p + wt * *d).collect(),
    ));
    Generated {
        glb: w.finish(root),
        triangles: tris.len(),
        duration: dur,
        checks,
    }
}
