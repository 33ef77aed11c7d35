//! Driving the engine from an animated glTF scene.
//!
//! Each glTF mesh instance becomes one engine instance, in the scene's instance order:
//! - deforming instances (animated skins or morph weights) get a mesh of their own in world
//!   space, written every frame and refitted or rebuilt as the policy says;
//! - static and rigid instances whose vertices are the glTF mesh's rest positions share one
//!   mesh per glTF mesh, built once in mesh space, and the instance carries the node's world
//!   transform (updated every frame for rigid ones);
//! - other static or rigid instances (skinned but unanimated, or morphed by fixed weights) get
//!   a mesh of their own, built once.

use super::source::FrameSource;
use super::{Engine, EngineConfig, InstanceId, MeshId, SceneHit};
use crate::anim::{InstanceClass, Poser, Scene};
use crate::error::Result;
use crate::geom::TriMesh;
use glam::Affine3A;
use std::collections::HashMap;
use std::time::Instant;

/// When frames are taken.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FrameTimes {
    /// `n` frames spread evenly over one loop of the animation (frame `n` is its end).
    Count(usize),
    /// Frames at this rate from the start to the end of the animation.
    Fps(f32),
}

/// Most frames a [`GltfSource`] timeline may hold (its frame times are kept in memory):
/// about 9.7 hours at 30 fps.
pub const MAX_FRAMES: usize = 1 << 20;

/// An animated glTF scene replayed frame by frame.
pub struct GltfSource<'s> {
    poser: Poser<'s>,
    name: String,
    times: Vec<f32>,
    plan: Vec<Plan>,
    deforming: Vec<MeshId>,
}

#[derive(Clone, Copy, Debug)]
enum Plan {
    /// Written every frame.
    Deforming(MeshId),
    /// Transform set every frame.
    Rigid(InstanceId),
    /// Never changes.
    Static,
}

impl<'s> GltfSource<'s> {
    /// Replays animation `anim` of `scene` (`None`: the rest pose, every frame the same) at the
    /// given frame times; frame 0 is the animation's start. More than [`MAX_FRAMES`] frames
    /// is an [`Error::InvalidArgument`](crate::Error::InvalidArgument).
    pub fn new(scene: &'s Scene, anim: Option<usize>, times: FrameTimes) -> Result<Self> {
        let poser = scene.poser(anim)?;
        let duration = anim.map_or(0.0, |a| scene.animations[a].duration);
        let frames = match times {
            FrameTimes::Count(n) => n as f64,
            FrameTimes::Fps(fps) => (f64::from(duration) * f64::from(fps)).ceil().max(1.0),
        };
        if frames > MAX_FRAMES as f64 {
            let asked = match times {
                FrameTimes::Count(n) => format!("{n} frames"),
                FrameTimes::Fps(fps) => format!("{fps} fps over {duration} s: {frames:.3e} frames"),
            };
            return Err(crate::Error::InvalidArgument(format!(
                "{}: {asked}, above the bound of {MAX_FRAMES} frames",
                scene.path.display()
            )));
        }
        let times = match times {
            FrameTimes::Count(n) => (0..=n)
                .map(|k| {
                    if n == 0 {
                        0.0
                    } else {
                        // The product overflows for durations near f32::MAX.
                        let t = duration * k as f32;
                        if t.is_finite() {
                            t / n as f32
                        } else {
                            duration * (k as f32 / n as f32)
                        }
                    }
                })
                .collect(),
            FrameTimes::Fps(fps) => {
                let n = frames as usize;
                (0..=n).map(|k| (k as f32 / fps).min(duration)).collect()
            }
        };
        let name = match anim {
            Some(a) => format!(
                "{} [{}]",
                scene.path.display(),
                scene.animations[a]
                    .name
                    .clone()
                    .unwrap_or_else(|| a.to_string())
            ),
            None => scene.path.display().to_string(),
        };
        Ok(Self {
            poser,
            name,
            times,
            plan: Vec::new(),
            deforming: Vec::new(),
        })
    }

    /// Animation time of each frame (index 0 is the pose the engine is built at).
    #[must_use]
    pub fn times(&self) -> &[f32] {
        &self.times
    }

    /// The poser (after the last frame written).
    #[must_use]
    pub fn poser(&self) -> &Poser<'s> {
        &self.poser
    }
}

impl FrameSource for GltfSource<'_> {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn frames(&self) -> usize {
        self.times.len() - 1
    }

    fn build(&mut self, frame: usize, config: EngineConfig) -> Engine {
        self.poser.pose(self.times[frame]);
        let scene = self.poser.scene();
        let mut engine = Engine::new(config);
        let mut shared: HashMap<usize, MeshId> = HashMap::new();
        self.plan.clear();
        self.deforming.clear();
        for (i, inst) in scene.instances.iter().enumerate() {
            let class = self.poser.classes()[i];
            let positions = self.poser.positions(i);
            let indices = self.poser.indices(i);
            let rest = &scene.meshes[inst.mesh].positions;
            let mesh = if class != InstanceClass::Deforming && positions.as_ptr() == rest.as_ptr() {
                *shared
                    .entry(inst.mesh)
                    .or_insert_with(|| engine.add_mesh(positions.to_vec(), indices.to_vec()))
            } else {
                engine.add_mesh(positions.to_vec(), indices.to_vec())
            };
            let id = engine.add_instance(mesh, Affine3A::from_mat4(self.poser.transform(i)));
            self.plan.push(match class {
                InstanceClass::Deforming => {
                    self.deforming.push(mesh);
                    Plan::Deforming(mesh)
                }
                InstanceClass::Rigid => Plan::Rigid(id),
                InstanceClass::Static => Plan::Static,
            });
        }
        engine.update();
        engine
    }

    fn advance(&mut self, engine: &mut Engine, frame: usize) {
        let t = Instant::now();
        self.poser.pose(self.times[frame]);
        for (i, p) in self.plan.iter().enumerate() {
            match *p {
                Plan::Deforming(m) => engine.set_positions(m, self.poser.positions(i)),
                Plan::Rigid(id) => {
                    engine.set_transform(id, Affine3A::from_mat4(self.poser.transform(i)));
                }
                Plan::Static => {}
            }
        }
        engine.record_pose(t.elapsed().as_secs_f64() * 1e3);
    }

    fn deforming(&self) -> &[MeshId] {
        &self.deforming
    }

    fn flatten_into(&self, out: &mut TriMesh) {
        self.poser.flatten_into(out);
    }

    fn flat_triangle(&self, hit: &SceneHit) -> usize {
        self.poser.scene().instances[hit.instance.0 as usize]
            .triangles
            .start
            + hit.prim as usize
    }

    fn triangle_count(&self) -> usize {
        self.poser.scene().triangle_count()
    }
}
