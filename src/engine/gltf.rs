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
//!
//! Meshes of static and rigid instances are added as static ([`Engine::add_static_mesh`]):
//! with the wide traversal they keep only the 8-wide tree.
//!
//! # Quick start
//!
//! Load a file, build an engine at the animation's start, then pose it at any time (a frame
//! grid is not needed: [`GltfSource::set_time`] takes any `t`, looping beyond the animation's
//! duration by default, or clamping with [`TimeMode::Clamp`]), update and cast rays:
//!
//! ```
//! use dynbvh::anim::Scene;
//! use dynbvh::engine::gltf::{FrameTimes, GltfSource};
//! use dynbvh::engine::EngineConfig;
//! use dynbvh::geom::Ray;
//! use dynbvh::glam::Vec3;
//!
//! let (scene, _warnings) = Scene::load("animations/tube.glb")?;
//! let mut source = GltfSource::new(&scene, Some(0), FrameTimes::Count(1))?;
//! let mut engine = source.engine(EngineConfig::default());
//! let centre = engine.bounds().center();
//! let rays: Vec<Ray> = (0..64)
//!     .map(|k| {
//!         let a = k as f32 * std::f32::consts::TAU / 64.0;
//!         Ray::new(centre + Vec3::new(a.cos(), 0.0, a.sin()) * 10.0, -Vec3::new(a.cos(), 0.0, a.sin()))
//!     })
//!     .collect();
//! let mut hits = vec![None; rays.len()];
//! for step in 0..5 {
//!     source.set_time(&mut engine, 0.37 * step as f32)?; // any time, in seconds
//!     engine.update(); // refit or rebuild the bent tube's tree, as the policy decides
//!     engine.trace_closest(&rays, &mut hits); // also feeds the policy its trace time
//! }
//! assert!(hits.iter().any(Option::is_some));
//! # Ok::<(), dynbvh::Error>(())
//! ```

use super::source::FrameSource;
use super::{Engine, EngineConfig, InstanceId, MeshId, SceneHit};
use crate::anim::{InstanceClass, Poser, Scene, TimeMode};
use crate::error::Result;
use crate::geom::TriMesh;
use glam::{Affine3A, Vec3};
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
    /// Poses a deforming mesh's first tree is built for (0: a plain build of frame 0).
    clip_poses: usize,
    clip_rebuilds: bool,
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
            clip_poses: 0,
            clip_rebuilds: false,
        })
    }

    /// Builds each deforming mesh's first tree (an engine built at frame 0) for the clip:
    /// `poses` frames are sampled evenly over the replay, first and last included (at most
    /// [`crate::bvh::build::clip::MAX_POSES`]), and the tree is built for them
    /// ([`Engine::build_for_clip`]). Later rebuilds stay plain unless
    /// [`GltfSource::with_clip_rebuilds`]. 0 (the default): plain builds throughout.
    #[must_use]
    pub fn with_clip_aware(mut self, poses: usize) -> Self {
        self.clip_poses = poses;
        self
    }

    /// With [`GltfSource::with_clip_aware`]: the policies' rebuilds are clip-aware too. An
    /// engine built at frame `b` builds each deforming mesh's tree for pose `b` and the
    /// sampled poses after it, and is given those poses ([`Engine::set_clip_ahead`]), so that
    /// each rebuild at a later frame is built the same way (the oracle's trees, built at every
    /// frame, are then the policies' rebuilds). Once no sampled pose is ahead, builds are
    /// plain.
    #[must_use]
    pub fn with_clip_rebuilds(mut self, yes: bool) -> Self {
        self.clip_rebuilds = yes;
        self
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

    /// How [`GltfSource::set_time`] maps a time beyond the animation (the default,
    /// [`TimeMode::Loop`], wraps it modulo the duration; [`TimeMode::Clamp`] holds the first and
    /// last keys).
    #[must_use]
    pub fn with_time_mode(mut self, mode: TimeMode) -> Self {
        self.poser = self.poser.with_time_mode(mode);
        self
    }

    /// A new engine holding the scene posed at frame 0 (the animation's start), its trees
    /// built: [`FrameSource::build`] at frame 0.
    #[must_use]
    pub fn engine(&mut self, config: EngineConfig) -> Engine {
        self.build(0, config)
    }

    /// Poses `engine` (built by this source) at animation time `t` seconds: deforming meshes'
    /// positions and rigid instances' transforms are written, to be taken in by the next
    /// [`Engine::update`]. Any finite `t` is allowed; beyond `[0, duration]` it loops or is
    /// clamped as the time mode says ([`GltfSource::with_time_mode`]). The posing time is
    /// recorded ([`Engine::record_pose`]).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`](crate::Error::InvalidArgument) when `t` is not finite, or
    /// when this source has not built an engine yet or `engine` has fewer instances than it
    /// placed (pose an engine built by [`GltfSource::engine`] or [`FrameSource::build`] of this
    /// source; instances added to it afterwards are left alone).
    pub fn set_time(&mut self, engine: &mut Engine, t: f32) -> Result<()> {
        if !t.is_finite() {
            return Err(crate::Error::InvalidArgument(format!(
                "{}: animation time {t} is not finite",
                self.name
            )));
        }
        if self.plan.len() != self.poser.scene().instances.len()
            || self.plan.len() > engine.instance_count()
        {
            return Err(crate::Error::InvalidArgument(format!(
                "{}: the engine has {} instances, the source placed {}: pose an engine this \
                 source built",
                self.name,
                engine.instance_count(),
                self.plan.len()
            )));
        }
        self.write_pose(engine, t);
        Ok(())
    }

    /// Poses the scene at `t` and writes what moves into `engine`.
    fn write_pose(&mut self, engine: &mut Engine, t: f32) {
        let start = Instant::now();
        self.poser.pose(t);
        for (i, p) in self.plan.iter().enumerate() {
            match *p {
                Plan::Deforming(m) => engine.set_positions(m, self.poser.positions(i)),
                Plan::Rigid(id) => {
                    engine.set_transform(id, Affine3A::from_mat4(self.poser.transform(i)));
                }
                Plan::Static => {}
            }
        }
        engine.record_pose(start.elapsed().as_secs_f64() * 1e3);
    }
}

impl GltfSource<'_> {
    /// Poses the deforming meshes `posed` (mesh, instance) at the clip's sampled frames after
    /// `frame`, builds their trees for `frame` and those poses, and with clip-aware rebuilds
    /// gives the engine the poses for them; leaves the poser at `frame`. The engine has not
    /// been updated yet (its first update takes in `frame`).
    fn build_for_clip(&mut self, engine: &mut Engine, posed: &[(MeshId, usize)], frame: usize) {
        let last = self.times.len() - 1;
        let k = self
            .clip_poses
            .min(crate::bvh::build::clip::MAX_POSES)
            .min(last + 1);
        let sampled = (0..k).map(|j| if k == 1 { 0 } else { j * last / (k - 1) });
        let ahead: Vec<usize> = sampled.filter(|&s| s > frame).collect();
        if ahead.is_empty() {
            return;
        }
        let mut poses: Vec<Vec<(u64, Vec<Vec3>)>> = vec![Vec::with_capacity(k); posed.len()];
        for &s in &ahead {
            self.poser.pose(self.times[s]);
            for (p, &(_, i)) in poses.iter_mut().zip(posed) {
                p.push(((s - frame + 1) as u64, self.poser.positions(i).to_vec()));
            }
        }
        self.poser.pose(self.times[frame]);
        for (p, &(mesh, i)) in poses.into_iter().zip(posed) {
            let mut views: Vec<&[Vec3]> = vec![self.poser.positions(i)];
            views.extend(p.iter().map(|(_, q)| q.as_slice()));
            // The poses come from the mesh's own instance: the counts agree, and the updates
            // ahead are at least 2.
            let built = engine.build_for_clip(mesh, &views);
            debug_assert!(built.is_ok(), "{built:?}");
            if self.clip_rebuilds {
                let set = engine.set_clip_ahead(mesh, p);
                debug_assert!(set.is_ok(), "{set:?}");
            }
        }
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
        let mut posed = Vec::new();
        for (i, inst) in scene.instances.iter().enumerate() {
            let class = self.poser.classes()[i];
            let positions = self.poser.positions(i);
            let indices = self.poser.indices(i);
            let rest = &scene.meshes[inst.mesh].positions;
            // Only deforming meshes are refitted or rebuilt; the others keep no more than
            // their queries need.
            let mesh = if class == InstanceClass::Deforming {
                engine.add_mesh(positions.to_vec(), indices.to_vec())
            } else if positions.as_ptr() == rest.as_ptr() {
                *shared
                    .entry(inst.mesh)
                    .or_insert_with(|| engine.add_static_mesh(positions.to_vec(), indices.to_vec()))
            } else {
                engine.add_static_mesh(positions.to_vec(), indices.to_vec())
            };
            let id = engine.add_instance(mesh, Affine3A::from_mat4(self.poser.transform(i)));
            self.plan.push(match class {
                InstanceClass::Deforming => {
                    self.deforming.push(mesh);
                    posed.push((mesh, i));
                    Plan::Deforming(mesh)
                }
                InstanceClass::Rigid => Plan::Rigid(id),
                InstanceClass::Static => Plan::Static,
            });
        }
        // An engine built at a later frame stands for a rebuild there (as the oracle builds
        // them): built as the policies' rebuilds are.
        if self.clip_poses > 0 && (frame == 0 || self.clip_rebuilds) && !posed.is_empty() {
            self.build_for_clip(&mut engine, &posed, frame);
        }
        engine.update();
        engine
    }

    fn advance(&mut self, engine: &mut Engine, frame: usize) {
        self.write_pose(engine, self.times[frame]);
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
