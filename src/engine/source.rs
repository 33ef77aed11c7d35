//! Frame sources: what poses a scene frame after frame and writes it into an [`Engine`], so
//! that benchmarks and tests can replay the same frames under every policy.

use super::{Engine, EngineConfig, InstanceId, MeshId, SceneHit};
use crate::geom::{TriMesh, shapes};
use glam::{Affine3A, Vec3};
use std::time::Instant;

/// A recorded or generated animation the engine can replay.
pub trait FrameSource {
    /// A name for reports.
    fn name(&self) -> String;
    /// Number of frames after the initial pose (frames are `1 ..= frames`; frame 0 is the pose
    /// the engine is built at).
    fn frames(&self) -> usize;
    /// Poses frame `frame` and builds a fresh engine over it.
    fn build(&mut self, frame: usize, config: EngineConfig) -> Engine;
    /// Poses frame `frame` and writes it into `engine` (which `build` made), recording the
    /// pose time; the caller then calls [`Engine::update`].
    fn advance(&mut self, engine: &mut Engine, frame: usize);
    /// The meshes that deform (the ones a policy governs), the same for every engine `build`
    /// makes.
    fn deforming(&self) -> &[MeshId];
    /// World triangles of the current pose.
    fn flatten_into(&self, out: &mut TriMesh);
    /// Index in [`FrameSource::flatten_into`]'s mesh of the triangle `hit` reports.
    fn flat_triangle(&self, hit: &SceneHit) -> usize;
    /// Triangles in the scene.
    fn triangle_count(&self) -> usize;
    /// The number reports give this source's frame 0: 0, unless the source is a stretch of a
    /// longer sequence ([`Window`]), so that its frames keep the longer sequence's numbers.
    fn first_frame(&self) -> usize {
        0
    }
}

/// Frames `start..end` (end excluded) of another source, as a source of its own: its frame 0
/// is `start` (the pose engines are built at) and its last frame `end - 1`.
pub struct Window<'a> {
    inner: &'a mut dyn FrameSource,
    start: usize,
    end: usize,
}

impl<'a> Window<'a> {
    /// The stretch `start..end` of `inner`, or `None` unless it holds at least two frames
    /// within `inner`'s `0 ..= frames()`.
    pub fn new(inner: &'a mut dyn FrameSource, start: usize, end: usize) -> Option<Self> {
        (start + 2 <= end && end <= inner.frames() + 1).then_some(Self { inner, start, end })
    }
}

impl FrameSource for Window<'_> {
    fn name(&self) -> String {
        format!("{} frames {}..{}", self.inner.name(), self.start, self.end)
    }

    fn frames(&self) -> usize {
        self.end - self.start - 1
    }

    fn build(&mut self, frame: usize, config: EngineConfig) -> Engine {
        self.inner.build(self.start + frame, config)
    }

    fn advance(&mut self, engine: &mut Engine, frame: usize) {
        self.inner.advance(engine, self.start + frame);
    }

    fn deforming(&self) -> &[MeshId] {
        self.inner.deforming()
    }

    fn flatten_into(&self, out: &mut TriMesh) {
        self.inner.flatten_into(out);
    }

    fn flat_triangle(&self, hit: &SceneHit) -> usize {
        self.inner.flat_triangle(hit)
    }

    fn triangle_count(&self) -> usize {
        self.inner.triangle_count()
    }

    fn first_frame(&self) -> usize {
        self.inner.first_frame() + self.start
    }
}

/// A generated deforming mesh: a bumpy sphere under a travelling sine wave, one instance.
pub struct SineSphere {
    rest: Vec<Vec3>,
    indices: Vec<[u32; 3]>,
    frames: usize,
    amplitude: f32,
    phase_step: f32,
    mesh: [MeshId; 1],
    posed: usize,
}

impl SineSphere {
    /// A sphere of about `triangles` triangles, deformed by a wave of `amplitude` (fraction
    /// of its size) advancing `phase_step` radians per frame, over `frames` frames.
    #[must_use]
    pub fn new(triangles: usize, frames: usize, amplitude: f32, phase_step: f32) -> Self {
        let m = shapes::bumpy_sphere(triangles);
        Self {
            posed: 0,
            rest: m.positions,
            indices: m.indices,
            frames,
            amplitude,
            phase_step,
            mesh: [MeshId(0)],
        }
    }

    fn pose_into(&self, frame: usize, out: &mut [Vec3]) {
        shapes::sine_deform(
            &self.rest,
            out,
            self.amplitude,
            frame as f32 * self.phase_step,
        );
    }
}

impl FrameSource for SineSphere {
    fn name(&self) -> String {
        format!("sine sphere {} triangles", self.indices.len())
    }

    fn frames(&self) -> usize {
        self.frames
    }

    fn build(&mut self, frame: usize, config: EngineConfig) -> Engine {
        let mut cur = vec![Vec3::ZERO; self.rest.len()];
        self.pose_into(frame, &mut cur);
        self.posed = frame;
        let mut e = Engine::new(config);
        let m = e.add_mesh(cur, self.indices.clone());
        e.add_instance(m, Affine3A::IDENTITY);
        self.mesh = [m];
        e.update();
        e
    }

    fn advance(&mut self, engine: &mut Engine, frame: usize) {
        let t = Instant::now();
        let out = engine.positions_mut(self.mesh[0]);
        self.pose_into(frame, out);
        engine.record_pose(t.elapsed().as_secs_f64() * 1e3);
        self.posed = frame;
    }

    fn deforming(&self) -> &[MeshId] {
        &self.mesh
    }

    fn flatten_into(&self, out: &mut TriMesh) {
        out.positions.clear();
        out.positions.resize(self.rest.len(), Vec3::ZERO);
        self.pose_into(self.posed, &mut out.positions);
        out.indices.clear();
        out.indices.extend_from_slice(&self.indices);
    }

    fn flat_triangle(&self, hit: &SceneHit) -> usize {
        debug_assert_eq!(hit.instance, InstanceId(0));
        hit.prim as usize
    }

    fn triangle_count(&self) -> usize {
        self.indices.len()
    }
}
