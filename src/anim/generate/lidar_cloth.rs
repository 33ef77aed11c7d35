//! The sensor scene of [`Kind::LidarCloth`](super::Kind::LidarCloth): a cloth sheet that
//! ripples, billows, swirls and folds over a static ground, with rigid boxes moving above and
//! around it. Y is up.

use super::{Generated, Rng, cube, grid, key_times, primitive};
use crate::anim::glb_writer::GlbWriter;
use glam::{Mat4, Quat, Vec3};
use serde_json::{Value, json};
use std::f32::consts::{PI, TAU};

/// Length of the loop in seconds.
const DURATION: f32 = 4.0;
/// LINEAR keys per channel, every 1/8 s (the last equals the first).
const KEYS: usize = 33;
/// Half the sheet's side.
const HALF: f32 = 4.0;
/// The sheet's rest height.
const CLOTH_Y: f32 = 1.0;
/// Half the ground quad's side.
const GROUND: f32 = 6.0;
/// Height of the travelling wave.
const AMPLITUDE: f32 = 0.5;
/// Its wavelength.
const WAVELENGTH: f32 = 4.0;
/// Height of the billow in the middle of the sheet.
const BILLOW: f32 = 1.2;
/// The fold's hinge is the line x = `HINGE` (at the rest height, along z).
const HINGE: f32 = 1.0;
/// Half the width of the band over which the hinge's weight goes from 0 to 1.
const BAND: f32 = 0.25;
/// The fold's largest angle.
const FOLD_DEGREES: f32 = 150.0;
/// Rings of the swirl, about the y axis every `RING_STEP` of rest radius from the centre.
const RINGS: usize = 6;
/// Radius from one ring to the next (the last lies beyond the sheet's corners).
const RING_STEP: f32 = 1.2;
/// The outermost ring's largest turn.
const SWIRL_DEGREES: f32 = 90.0;
/// The rigid boxes.
const MOVERS: usize = 6;

/// One rigid box: a pivot node (translation and rotation, keyed when they hold one value per
/// key time, static when they hold one) carrying the cube on a child node (a static offset and
/// scale).
struct Mover {
    name: &'static str,
    translation: Vec<Vec3>,
    rotation: Vec<Quat>,
    offset: Vec3,
    scale: Vec3,
}

impl Mover {
    /// World matrix of the cube at key `k`.
    fn world(&self, k: usize) -> Mat4 {
        let t = self.translation[k.min(self.translation.len() - 1)];
        let r = self.rotation[k.min(self.rotation.len() - 1)];
        Mat4::from_rotation_translation(r, t)
            * Mat4::from_scale_rotation_translation(self.scale, Quat::IDENTITY, self.offset)
    }
}

/// The glTF document under construction: nodes, animation samplers and channels.
#[derive(Default)]
struct Doc {
    nodes: Vec<Value>,
    samplers: Vec<Value>,
    channels: Vec<Value>,
}

impl Doc {
    /// Animates `path` of `node` with a new LINEAR sampler of key times `input` and values
    /// `output` (accessor indices).
    fn animate(&mut self, node: usize, path: &str, input: usize, output: usize) {
        self.samplers
            .push(json!({"input": input, "output": output, "interpolation": "LINEAR"}));
        self.share(node, path, self.samplers.len() - 1);
    }

    /// Animates `path` of `node` with the existing sampler `sampler`.
    fn share(&mut self, node: usize, path: &str, sampler: usize) {
        self.channels
            .push(json!({"sampler": sampler, "target": {"node": node, "path": path}}));
    }
}

/// The boxes at the key `times`: a sled shuttling across above the sheet, three cubes
/// circling it on pivots at different heights and speeds, one tumbling above the sheet's -x
/// part and one bobbing over a corner. `seed` varies their sizes, radii, heights and phases.
fn movers(times: &[f32], seed: u64) -> Vec<Mover> {
    let omega = TAU / DURATION;
    let mut rng = Rng::new(seed);
    let sizes: [f32; MOVERS] = std::array::from_fn(|_| 0.4 + 0.25 * rng.next());
    let keyed = |f: &dyn Fn(f32) -> Vec3| times.iter().map(|&t| f(t)).collect::<Vec<_>>();
    let turning = |f: &dyn Fn(f32) -> Quat| times.iter().map(|&t| f(t)).collect::<Vec<_>>();
    let mut out = Vec::with_capacity(MOVERS);
    let lane = -2.0 - rng.next();
    out.push(Mover {
        name: "sled",
        translation: keyed(&|t| Vec3::new(-5.0 * (omega * t).cos(), 3.1, lane)),
        rotation: vec![Quat::IDENTITY],
        offset: Vec3::ZERO,
        scale: Vec3::new(1.4, 0.5, 0.9) * (sizes[0] + 0.5),
    });
    for (i, (name, turns)) in [("orbiter0", 1.0), ("orbiter1", -1.0), ("orbiter2", 2.0)]
        .into_iter()
        .enumerate()
    {
        let height = 1.8 + 0.8 * i as f32 + 0.3 * rng.next();
        let radius = 5.0 + 0.4 * rng.next();
        let phase = TAU * rng.next();
        out.push(Mover {
            name,
            translation: vec![Vec3::new(0.0, height, 0.0)],
            rotation: turning(&|t| Quat::from_rotation_y(phase + turns * omega * t)),
            offset: Vec3::new(radius, 0.0, 0.0),
            scale: Vec3::splat(sizes[1 + i]),
        });
    }
    let axis = Vec3::new(1.0, 1.0, 0.0).normalize();
    out.push(Mover {
        name: "tumbler",
        translation: keyed(&|t| Vec3::new(-2.0, 3.8 + 0.3 * (omega * t).sin(), 1.5)),
        rotation: turning(&|t| Quat::from_axis_angle(axis, omega * t)),
        offset: Vec3::ZERO,
        scale: Vec3::splat(sizes[4] + 0.2),
    });
    out.push(Mover {
        name: "bobber",
        translation: keyed(&|t| Vec3::new(-3.0, 2.5 + 0.6 * (2.0 * omega * t).sin(), 3.0)),
        rotation: turning(&|t| Quat::from_rotation_y(-omega * t)),
        offset: Vec3::ZERO,
        scale: Vec3::splat(sizes[5]),
    });
    out
}

/// The fold's angle at time `t`: 0 outside `1..3` s, `FOLD_DEGREES` at 2 s.
fn fold(t: f32) -> f32 {
    if (1.0..3.0).contains(&t) {
        FOLD_DEGREES.to_radians() * (PI * (t - 1.0) / 2.0).sin().powi(2)
    } else {
        0.0
    }
}

/// The three morph weights at time `t`: the wave's `(a cos φ, a sin φ)` and the billow's.
fn morph_weights(t: f32) -> [f32; 3] {
    let calm = 1.0 - 0.6 * fold(t) / FOLD_DEGREES.to_radians();
    let (s, c) = (4.0 * PI * t / DURATION).sin_cos();
    [calm * c, calm * s, (PI * t / 2.0).sin().powi(2)]
}

/// The sensor scene with about `n` triangles.
///
/// The sheet (8 × 8 in the x-z plane at height 1, nearly all of the `n` triangles) is morphed
/// by three targets, then skinned on a rig of six rings about the y axis, each carrying a
/// hinge (4 weights per vertex: the two rings around its rest radius, each with and without
/// the hinge):
/// - targets 0 and 1 (`A sin θ`, `A cos θ` in y, θ the phase along a diagonal, wavelength 4)
///   weighted `(a cos φ, a sin φ)` make the wave `a A sin(θ + φ)` travel across the sheet, two
///   periods per loop, calmer (`a` down to 0.4) while the sheet is folded;
/// - target 2, a dome (1.2 high in the middle, 0 at the edges) weighted `sin²(πt / 2)`, lifts
///   the sheet twice per loop, as a gust from below;
/// - the rings turn about y by up to 90° (the outermost; the centre stays) as `sin(2πt / 4)`,
///   so the sheet swirls one way and back, then the other way: neighbouring triangles shear
///   apart at every scale;
/// - the hinges, on the line x = 1, turn the sheet's +x part (weighted smoothly over a band of
///   ±0.25) about z up to 150° and back between t = 1 and 3 s, folding a third of the sheet
///   over the rest: triangles that were apart come together.
///
/// Both are what a refitted tree degrades under. The boxes are [`movers`]; all keys are
/// LINEAR, every 1/8 s of a 4 s loop.
pub(super) fn lidar_cloth(n: usize, seed: u64) -> Generated {
    let times = key_times(KEYS, DURATION);
    let movers = movers(&times, seed);
    let (cube_pos, cube_tris) = cube(1.0);
    let mover_triangles = MOVERS * cube_tris.len();

    // The sheet; rows run along -z so that the triangles face +y.
    let quads = n.saturating_sub(2 + mover_triangles) / 2;
    let cols = ((quads as f32).sqrt().round() as usize).max(2);
    let rows = ((quads as f32 / cols as f32).round() as usize).max(2);
    let (pos, tris) = grid(cols, rows, |u, v| {
        Vec3::new(HALF * (2.0 * u - 1.0), CLOTH_Y, HALF * (1.0 - 2.0 * v))
    });
    let (dx, dz) = 30f32.to_radians().sin_cos();
    let theta = |p: &Vec3| TAU / WAVELENGTH * (p.x * dx + p.z * dz);
    let lift = |f: &dyn Fn(&Vec3) -> f32| pos.iter().map(|p| Vec3::Y * f(p)).collect::<Vec<_>>();
    let d_sin = lift(&|p| AMPLITUDE * theta(p).sin());
    let d_cos = lift(&|p| AMPLITUDE * theta(p).cos());
    let d_dome = lift(&|p| {
        let c = |x: f32| (PI * x / (2.0 * HALF)).cos().max(0.0);
        BILLOW * c(p.x) * c(p.z)
    });

    // The rig: ring k is joint 2k (at the origin, turning about y), its hinge joint 2k + 1.
    let hinge_at = Vec3::new(HINGE, CLOTH_Y, 0.0);
    let (joint_ids, joint_weights): (Vec<[u16; 4]>, Vec<[f32; 4]>) = pos
        .iter()
        .map(|p| {
            let u = p.x.hypot(p.z) / RING_STEP;
            let k = (u.floor() as usize).min(RINGS - 2);
            let f = (u - k as f32).min(1.0);
            let s = ((p.x - (HINGE - BAND)) / (2.0 * BAND)).clamp(0.0, 1.0);
            let h = s * s * (3.0 - 2.0 * s);
            let r = 2 * k as u16;
            (
                [r, r + 2, r + 1, r + 3],
                [(1.0 - f) * (1.0 - h), f * (1.0 - h), (1.0 - f) * h, f * h],
            )
        })
        .unzip();
    let hinge_turn: Vec<Quat> = times
        .iter()
        .map(|&t| Quat::from_rotation_z(fold(t)))
        .collect();
    let ring_turn: Vec<Vec<Quat>> = (0..RINGS)
        .map(|k| {
            let most = SWIRL_DEGREES.to_radians() * k as f32 / (RINGS - 1) as f32;
            times
                .iter()
                .map(|&t| Quat::from_rotation_y(most * (TAU * t / DURATION).sin()))
                .collect()
        })
        .collect();
    let bind: Vec<Mat4> = (0..RINGS)
        .flat_map(|_| [Mat4::IDENTITY, Mat4::from_translation(-hinge_at)])
        .collect();

    // Buffers.
    let mut w = GlbWriter::default();
    let mut prim = primitive(w.vec3s(&pos), w.indices(&tris));
    prim["targets"] = json!([
        {"POSITION": w.vec3s(&d_sin)},
        {"POSITION": w.vec3s(&d_cos)},
        {"POSITION": w.vec3s(&d_dome)},
    ]);
    prim["attributes"]["JOINTS_0"] = json!(w.joints(&joint_ids));
    let flat_weights: Vec<f32> = joint_weights.iter().flatten().copied().collect();
    prim["attributes"]["WEIGHTS_0"] = json!(w.floats(&flat_weights, "VEC4", 4));
    let bind_matrices = w.mat4s(&bind);
    let ground_pos = [
        Vec3::new(-GROUND, 0.0, -GROUND),
        Vec3::new(GROUND, 0.0, -GROUND),
        Vec3::new(GROUND, 0.0, GROUND),
        Vec3::new(-GROUND, 0.0, GROUND),
    ];
    let ground = primitive(w.vec3s(&ground_pos), w.indices(&[[0, 2, 1], [0, 3, 2]]));
    let cube_prim = primitive(w.vec3s(&cube_pos), w.indices(&cube_tris));
    let ta = w.scalars(&times);
    let weight_keys: Vec<f32> = times.iter().flat_map(|&t| morph_weights(t)).collect();

    // Nodes: the rig, the cloth, the ground, then a pivot and a cube per box.
    let mut doc = Doc::default();
    let cloth = 1 + 2 * RINGS;
    let rings: Vec<usize> = (0..RINGS).map(|k| 1 + 2 * k).collect();
    doc.nodes
        .push(json!({"name": "cloth_rig", "children": rings}));
    doc.animate(cloth, "weights", ta, w.scalars(&weight_keys));
    let hinge_sampler = doc.samplers.len();
    doc.samplers
        .push(json!({"input": ta, "output": w.quats(&hinge_turn), "interpolation": "LINEAR"}));
    for (k, turn) in ring_turn.iter().enumerate() {
        let ring = doc.nodes.len();
        doc.nodes
            .push(json!({"name": format!("cloth_ring{k}"), "children": [ring + 1]}));
        doc.nodes
            .push(json!({"name": format!("cloth_hinge{k}"), "translation": hinge_at.to_array()}));
        doc.animate(ring, "rotation", ta, w.quats(turn));
        doc.share(ring + 1, "rotation", hinge_sampler);
    }
    doc.nodes
        .push(json!({"name": "cloth", "mesh": 0, "skin": 0}));
    doc.nodes.push(json!({"name": "ground", "mesh": 1}));
    let mut roots = vec![0, cloth, cloth + 1];
    for m in &movers {
        let pivot = doc.nodes.len();
        roots.push(pivot);
        let mut node = json!({"name": m.name, "children": [pivot + 1]});
        if let [t] = m.translation[..] {
            node["translation"] = json!(t.to_array());
        } else {
            doc.animate(pivot, "translation", ta, w.vec3s(&m.translation));
        }
        match m.rotation[..] {
            [r] if r == Quat::IDENTITY => {}
            [r] => node["rotation"] = json!(r.to_array()),
            _ => doc.animate(pivot, "rotation", ta, w.quats(&m.rotation)),
        }
        doc.nodes.push(node);
        doc.nodes
            .push(json!({"name": format!("{}_box", m.name), "mesh": 2,
            "translation": m.offset.to_array(), "scale": m.scale.to_array()}));
    }
    let root = json!({
        "scene": 0,
        "scenes": [{"nodes": roots}],
        "nodes": doc.nodes,
        "meshes": [
            {"name": "cloth", "primitives": [prim], "weights": morph_weights(0.0)},
            {"name": "ground", "primitives": [ground]},
            {"name": "box", "primitives": [cube_prim]},
        ],
        "skins": [{"joints": (1..cloth).collect::<Vec<_>>(), "inverseBindMatrices": bind_matrices, "skeleton": 0}],
        "animations": [{"name": "cloth", "channels": doc.channels, "samplers": doc.samplers}],
    });

    // Analytic positions at a few key times: morph, then blend the four joints.
    let checks = [0usize, 8, 12, 16, 21]
        .iter()
        .map(|&k| {
            let [w0, w1, w2] = morph_weights(times[k]);
            let hinge = Mat4::from_translation(hinge_at)
                * Mat4::from_quat(hinge_turn[k])
                * Mat4::from_translation(-hinge_at);
            let joint: Vec<Mat4> = ring_turn
                .iter()
                .flat_map(|turn| {
                    let ring = Mat4::from_quat(turn[k]);
                    [ring, ring * hinge]
                })
                .collect();
            let mut out = Vec::with_capacity(pos.len() + 4 + MOVERS * cube_pos.len());
            out.extend((0..pos.len()).map(|v| {
                let p = pos[v] + w0 * d_sin[v] + w1 * d_cos[v] + w2 * d_dome[v];
                (0..4)
                    .map(|i| {
                        let j = joint[joint_ids[v][i] as usize];
                        joint_weights[v][i] * j.transform_point3(p)
                    })
                    .sum::<Vec3>()
            }));
            out.extend(ground_pos);
            for m in &movers {
                let world = m.world(k);
                out.extend(cube_pos.iter().map(|p| world.transform_point3(*p)));
            }
            (times[k], out)
        })
        .collect();
    Generated {
        glb: w.finish(root),
        triangles: tris.len() + 2 + mover_triangles,
        duration: DURATION,
        checks,
    }
}
