//! Posing a scene at time `t`: node world transforms, morph weights, joint matrices, and
//! morphed-then-skinned vertex positions written into buffers reused from call to call.

use super::scene::{Animation, Instance, Mesh, Property, Scene, SkinAttributes, TimeMode, Trs};
use crate::error::{Error, Result};
use crate::geom::TriMesh;
use glam::{Affine3A, Mat4, Quat, Vec3, Vec3A};
use rayon::prelude::*;

/// Vertex count above which an instance is deformed in parallel.
pub const PARALLEL_VERTICES: usize = 16 * 1024;

/// How an instance moves under one animation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum InstanceClass {
    /// Nothing animates the instance: its world positions never change.
    Static,
    /// Only node transforms of the instance or its ancestors animate: positions stay fixed in
    /// mesh space and one world transform moves them.
    Rigid,
    /// Vertices move relative to each other: animated skin joints or morph weights.
    Deforming,
}

impl InstanceClass {
    /// Lower-case name for printing.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            InstanceClass::Static => "static",
            InstanceClass::Rigid => "rigid",
            InstanceClass::Deforming => "deforming",
        }
    }
}

/// Classifies every instance of `scene` under animation `anim` (`None`: no animation, all
/// static).
#[must_use]
pub fn classify(scene: &Scene, anim: Option<&Animation>) -> Vec<InstanceClass> {
    let n = scene.nodes.len();
    let mut moving = vec![false; n];
    let mut morphing = vec![false; n];
    for ch in anim.iter().flat_map(|a| &a.channels) {
        match ch.property {
            Property::Weights => morphing[ch.node] = true,
            _ => moving[ch.node] = true,
        }
    }
    for &i in &scene.order {
        if let Some(p) = scene.nodes[i].parent {
            moving[i] |= moving[p];
        }
    }
    scene
        .instances
        .iter()
        .map(|inst| {
            let has_targets = !scene.meshes[inst.mesh].targets.is_empty();
            let joints_move = inst
                .skin
                .is_some_and(|s| scene.skins[s].joints.iter().any(|&j| moving[j]));
            if joints_move || (has_targets && morphing[inst.node]) {
                InstanceClass::Deforming
            } else if inst.skin.is_none() && moving[inst.node] {
                InstanceClass::Rigid
            } else {
                InstanceClass::Static
            }
        })
        .collect()
}

/// Poses one scene under one animation, reusing its buffers from call to call.
pub struct Poser<'s> {
    scene: &'s Scene,
    anim: Option<&'s Animation>,
    mode: TimeMode,
    classes: Vec<InstanceClass>,
    animated: Vec<usize>,
    trs: Vec<Trs>,
    local: Vec<Mat4>,
    world: Vec<Mat4>,
    node_instance: Vec<Option<usize>>,
    weights: Vec<Vec<f32>>,
    joints: Vec<Vec<Affine3A>>,
    buffers: Vec<Vec<Vec3>>,
    world_space: Vec<bool>,
    unweighted: Vec<Vec<u32>>,
    scratch: Vec<f32>,
    time: f32,
    posed: bool,
}

impl Scene {
    /// A poser for animation `anim` (`None`: rest pose), looping by default.
    pub fn poser(&self, anim: Option<usize>) -> Result<Poser<'_>> {
        Poser::new(self, anim)
    }

    /// Classifies every instance under animation `anim`.
    pub fn classify(&self, anim: Option<usize>) -> Result<Vec<InstanceClass>> {
        Ok(self.poser(anim)?.classes().to_vec())
    }

    /// All instances' triangles in world space at time `t` of animation `anim`.
    pub fn flatten_at(&self, anim: Option<usize>, t: f32) -> Result<TriMesh> {
        let mut p = self.poser(anim)?;
        p.pose(t);
        let mut out = TriMesh::default();
        p.flatten_into(&mut out);
        Ok(out)
    }

    /// All instances' triangles in world space with no animation (nodes at rest).
    #[must_use]
    pub fn flatten_rest(&self) -> TriMesh {
        self.flatten_at(None, 0.0).unwrap_or_default()
    }
}

impl<'s> Poser<'s> {
    /// A poser for `anim` of `scene`; fails when the animation index is out of range.
    pub fn new(scene: &'s Scene, anim: Option<usize>) -> Result<Self> {
        let anim = match anim {
            None => None,
            Some(a) => Some(scene.animations.get(a).ok_or_else(|| {
                Error::InvalidArgument(format!(
                    "animation {a} of {} in {}",
                    scene.animations.len(),
                    scene.path.display()
                ))
            })?),
        };
        let n = scene.nodes.len();
        let classes = classify(scene, anim);
        let mut animated: Vec<usize> = anim
            .iter()
            .flat_map(|a| &a.channels)
            .filter(|c| c.property != Property::Weights)
            .map(|c| c.node)
            .collect();
        animated.sort_unstable();
        animated.dedup();
        let mut node_instance = vec![None; n];
        for (i, inst) in scene.instances.iter().enumerate() {
            node_instance[inst.node] = Some(i);
        }
        let mut buffers = Vec::with_capacity(scene.instances.len());
        let mut world_space = Vec::with_capacity(scene.instances.len());
        for (inst, class) in scene.instances.iter().zip(&classes) {
            let mesh = &scene.meshes[inst.mesh];
            let ws = inst.skin.is_some() || *class == InstanceClass::Deforming;
            let owned = ws || inst.weights.iter().any(|&w| w != 0.0);
            world_space.push(ws);
            buffers.push(if owned {
                vec![Vec3::ZERO; mesh.positions.len()]
            } else {
                Vec::new()
            });
        }
        let width = anim
            .iter()
            .flat_map(|a| &a.samplers)
            .map(|s| s.width)
            .max()
            .unwrap_or(0);
        Ok(Poser {
            scene,
            anim,
            mode: TimeMode::default(),
            classes,
            animated,
            trs: scene.nodes.iter().map(|n| n.trs).collect(),
            local: scene.nodes.iter().map(|n| n.rest_matrix()).collect(),
            world: vec![Mat4::IDENTITY; n],
            node_instance,
            weights: scene.instances.iter().map(|i| i.weights.clone()).collect(),
            joints: scene
                .instances
                .iter()
                .map(|i| {
                    let k = i.skin.map_or(0, |s| scene.skins[s].joints.len());
                    vec![Affine3A::IDENTITY; k]
                })
                .collect(),
            unweighted: scene
                .instances
                .iter()
                .map(|i| unweighted_vertices(&scene.meshes[i.mesh], i))
                .collect(),
            buffers,
            world_space,
            scratch: vec![0.0; width.max(4)],
            time: 0.0,
            posed: false,
        })
    }

    /// Sets how times beyond the animation's duration are mapped.
    #[must_use]
    pub fn with_time_mode(mut self, mode: TimeMode) -> Self {
        self.mode = mode;
        self
    }

    /// The scene being posed.
    #[must_use]
    pub fn scene(&self) -> &'s Scene {
        self.scene
    }

    /// Class of each instance under this poser's animation.
    #[must_use]
    pub fn classes(&self) -> &[InstanceClass] {
        &self.classes
    }

    /// Animation time used by the last [`Poser::pose`] (after looping).
    #[must_use]
    pub fn time(&self) -> f32 {
        self.time
    }

    /// Maps a requested time to animation time under the time mode.
    #[must_use]
    pub fn map_time(&self, t: f32) -> f32 {
        let d = self.anim.map_or(0.0, |a| a.duration);
        if self.mode == TimeMode::Loop && d > 0.0 && !(0.0..=d).contains(&t) && t.is_finite() {
            t.rem_euclid(d)
        } else {
            t
        }
    }

    /// Poses the scene at time `t`: after this, [`Poser::positions`] and
    /// [`Poser::transform`] describe every instance. Allocates nothing after the first call.
    pub fn pose(&mut self, t: f32) {
        let t = self.map_time(t);
        self.time = t;
        let scene = self.scene;
        if let Some(anim) = self.anim {
            for &n in &self.animated {
                self.trs[n] = scene.nodes[n].trs;
            }
            for (i, inst) in scene.instances.iter().enumerate() {
                self.weights[i].copy_from_slice(&inst.weights);
            }
            for ch in &anim.channels {
                let s = &anim.samplers[ch.sampler];
                let out = &mut self.scratch[..s.width];
                s.sample(t, ch.property == Property::Rotation, out);
                let trs = &mut self.trs[ch.node];
                match ch.property {
                    Property::Translation => trs.translation = Vec3::from_slice(out),
                    Property::Scale => trs.scale = Vec3::from_slice(out),
                    Property::Rotation => {
                        let q = Quat::from_slice(out);
                        if q.length_squared() > 0.0 {
                            trs.rotation = q.normalize();
                        }
                    }
                    Property::Weights => {
                        if let Some(i) = self.node_instance[ch.node] {
                            let w = &mut self.weights[i];
                            if w.len() == out.len() {
                                w.copy_from_slice(out);
                            }
                        }
                    }
                }
            }
            for &n in &self.animated {
                self.local[n] = self.trs[n].matrix();
            }
        }
        for &n in &scene.order {
            self.world[n] = match scene.nodes[n].parent {
                Some(p) => self.world[p] * self.local[n],
                None => self.local[n],
            };
        }
        for (i, inst) in scene.instances.iter().enumerate() {
            if self.buffers[i].is_empty()
                || (self.posed && self.classes[i] != InstanceClass::Deforming)
            {
                continue;
            }
            if let Some(s) = inst.skin {
                let skin = &scene.skins[s];
                for (k, m) in self.joints[i].iter_mut().enumerate() {
                    *m = Affine3A::from_mat4(self.world[skin.joints[k]] * skin.inverse_bind[k]);
                }
            }
            let node_world = Affine3A::from_mat4(self.world[inst.node]);
            deform(
                &scene.meshes[inst.mesh],
                inst,
                &self.weights[i],
                &self.joints[i],
                self.world_space[i].then_some(node_world),
                &self.unweighted[i],
                &mut self.buffers[i],
            );
        }
        self.posed = true;
    }

    /// Positions of instance `i`, in the space that [`Poser::transform`] maps to world: world
    /// space for skinned and deforming instances, mesh space otherwise.
    #[must_use]
    pub fn positions(&self, i: usize) -> &[Vec3] {
        let b = &self.buffers[i];
        if b.is_empty() {
            &self.scene.meshes[self.scene.instances[i].mesh].positions
        } else {
            b
        }
    }

    /// Triangles of instance `i`, indexing [`Poser::positions`].
    #[must_use]
    pub fn indices(&self, i: usize) -> &'s [[u32; 3]] {
        &self.scene.meshes[self.scene.instances[i].mesh].indices
    }

    /// Transform from [`Poser::positions`] of instance `i` to world space (identity for skinned
    /// and deforming instances).
    #[must_use]
    pub fn transform(&self, i: usize) -> Mat4 {
        if self.world_space[i] {
            Mat4::IDENTITY
        } else {
            self.world[self.scene.instances[i].node]
        }
    }

    /// World matrix of every node after the last pose.
    #[must_use]
    pub fn world_matrices(&self) -> &[Mat4] {
        &self.world
    }

    /// Current morph weights of instance `i`.
    #[must_use]
    pub fn morph_weights(&self, i: usize) -> &[f32] {
        &self.weights[i]
    }

    /// Joint matrices (joint world × inverse bind) of skinned instance `i` (empty otherwise).
    #[must_use]
    pub fn joint_matrices(&self, i: usize) -> &[Affine3A] {
        &self.joints[i]
    }

    /// Writes all instances' triangles in world space into `out`, reusing its storage.
    /// Instance `i` occupies `scene.instances[i].triangles` and `.vertices`.
    pub fn flatten_into(&self, out: &mut TriMesh) {
        out.positions.clear();
        out.indices.clear();
        for i in 0..self.scene.instances.len() {
            let base = out.positions.len() as u32;
            let m = Affine3A::from_mat4(self.transform(i));
            let src = self.positions(i);
            if m == Affine3A::IDENTITY {
                out.positions.extend_from_slice(src);
            } else {
                out.positions
                    .extend(src.iter().map(|&p| m.transform_point3(p)));
            }
            out.indices
                .extend(self.indices(i).iter().map(|t| t.map(|v| v + base)));
        }
    }
}

/// Vertices per task of the parallel path and per pass of the serial one: a chunk's positions
/// stay in cache between the morph pass and the skin pass.
const CHUNK: usize = 2048;

/// Vertices of `mesh` whose skin weights are all zero (skinning leaves them to the node's
/// transform), when `inst` is skinned.
fn unweighted_vertices(mesh: &Mesh, inst: &Instance) -> Vec<u32> {
    match mesh.skin.as_ref().filter(|_| inst.skin.is_some()) {
        Some(sk) if sk.influences > 0 => sk
            .weights
            .chunks_exact(sk.influences)
            .enumerate()
            .filter(|(_, w)| w.iter().all(|&w| w == 0.0))
            .map(|(v, _)| v as u32)
            .collect(),
        _ => Vec::new(),
    }
}

/// Morphs then skins the vertices of `inst` into `out`; without a skin, `world` (if any) maps
/// the morphed positions to world space, and so it does for the skinned vertices listed in
/// `unweighted` (all their weights are zero).
fn deform(
    mesh: &Mesh,
    inst: &Instance,
    weights: &[f32],
    joints: &[Affine3A],
    world: Option<Affine3A>,
    unweighted: &[u32],
    out: &mut [Vec3],
) {
    let skin = mesh.skin.as_ref().filter(|_| inst.skin.is_some());
    let fallback = world.unwrap_or(Affine3A::IDENTITY);
    let morphing = weights.iter().zip(&mesh.targets).any(|(&w, _)| w != 0.0);
    let chunk = |start: usize, out: &mut [Vec3]| match skin {
        Some(sk) if morphing => {
            morph(mesh, weights, start, out);
            skin_chunk(sk, joints, start, out.iter_mut().map(|o| (*o, o)));
        }
        Some(sk) => {
            let rest = &mesh.positions[start..start + out.len()];
            skin_chunk(sk, joints, start, rest.iter().copied().zip(out));
        }
        None => {
            morph(mesh, weights, start, out);
            transform_all(&fallback, out);
        }
    };
    if out.len() > PARALLEL_VERTICES {
        out.par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(c, o)| chunk(c * CHUNK, o));
    } else {
        for (c, o) in out.chunks_mut(CHUNK).enumerate() {
            chunk(c * CHUNK, o);
        }
    }
    if skin.is_some() {
        for &v in unweighted {
            let v = v as usize;
            let p = &mut out[v..=v];
            morph(mesh, weights, v, p);
            transform_all(&fallback, p);
        }
    }
}

/// Writes the morphed rest positions of vertices `start..start + out.len()` into `out`:
/// the rest position plus each target's delta times its weight, targets in order.
fn morph(mesh: &Mesh, weights: &[f32], start: usize, out: &mut [Vec3]) {
    let range = start..start + out.len();
    out.copy_from_slice(&mesh.positions[range.clone()]);
    for (&w, deltas) in weights.iter().zip(&mesh.targets) {
        if w != 0.0 {
            for (o, &d) in out.iter_mut().zip(&deltas[range.clone()]) {
                *o += w * d;
            }
        }
    }
}

/// Maps every point of `out` by `m` (nothing to do for the identity).
fn transform_all(m: &Affine3A, out: &mut [Vec3]) {
    if *m != Affine3A::IDENTITY {
        for o in out {
            *o = m.transform_point3(*o);
        }
    }
}

/// Linear blend skinning of vertices `start..` of the mesh: each `(p, o)` of `points` (the
/// morphed position and where to write) gets the weighted sum of its joints' matrices applied
/// to `p`. Vertices whose weights are all zero get the origin (the caller places them).
fn skin_chunk<'o>(
    sk: &SkinAttributes,
    joints: &[Affine3A],
    start: usize,
    points: impl ExactSizeIterator<Item = (Vec3, &'o mut Vec3)>,
) {
    let k = sk.influences;
    let range = start * k..(start + points.len()) * k;
    let (js, ws) = (&sk.joints[range.clone()], &sk.weights[range]);
    if k == 4 {
        let (js, ws) = (js.as_chunks::<4>().0, ws.as_chunks::<4>().0);
        for (((p, o), j), w) in points.zip(js).zip(ws) {
            *o = blend4(joints, j, w, Vec3A::from(p)).into();
        }
    } else if k > 0 && k.is_multiple_of(4) {
        for (((p, o), j), w) in points.zip(js.chunks_exact(k)).zip(ws.chunks_exact(k)) {
            let p = Vec3A::from(p);
            let (j, w) = (j.as_chunks::<4>().0, w.as_chunks::<4>().0);
            *o = j
                .iter()
                .zip(w)
                .fold(Vec3A::ZERO, |acc, (j, w)| acc + blend4(joints, j, w, p))
                .into();
        }
    } else if k > 0 {
        for (((p, o), j), w) in points.zip(js.chunks_exact(k)).zip(ws.chunks_exact(k)) {
            let p = Vec3A::from(p);
            *o = j
                .iter()
                .zip(w)
                .fold(Vec3A::ZERO, |acc, (&j, &w)| {
                    acc + w * joints[usize::from(j)].transform_point3a(p)
                })
                .into();
        }
    }
}

/// `Σ w[i] · joints[j[i]] · p` over one set of four influences: the four affine matrices are
/// blended by weight, then the blend maps `p` once (one matrix-vector product instead of
/// four).
#[inline(always)]
fn blend4(joints: &[Affine3A], j: &[u16; 4], w: &[f32; 4], p: Vec3A) -> Vec3A {
    let m = |i: usize| &joints[usize::from(j[i])];
    let (a, b, c, d) = (m(0), m(1), m(2), m(3));
    let [w0, w1, w2, w3] = w.map(Vec3A::splat);
    let blend = |col: fn(&Affine3A) -> Vec3A| {
        madd(col(a), w0, madd(col(b), w1, madd(col(c), w2, col(d) * w3)))
    };
    let x = blend(|m| m.matrix3.x_axis);
    let y = blend(|m| m.matrix3.y_axis);
    let z = blend(|m| m.matrix3.z_axis);
    let t = blend(|m| m.translation);
    madd(
        x,
        Vec3A::splat(p.x),
        madd(y, Vec3A::splat(p.y), madd(z, Vec3A::splat(p.z), t)),
    )
}

/// `a * b + c`, fused when the target has FMA (glam's `mul_add` is a slow library call
/// otherwise).
#[inline(always)]
fn madd(a: Vec3A, b: Vec3A, c: Vec3A) -> Vec3A {
    #[cfg(target_feature = "fma")]
    {
        a.mul_add(b, c)
    }
    #[cfg(not(target_feature = "fma"))]
    {
        a * b + c
    }
}
