//! Animated glTF 2.0 scenes: loading (`.gltf`, `.glb`, data URIs, sparse and quantized
//! accessors), keyframe sampling, and posing at any time `t` into reused buffers.
//!
//! ```no_run
//! use dynbvh::anim::Scene;
//! let (scene, warnings) = Scene::load("scene.glb")?;
//! for w in &warnings {
//!     eprintln!("warning: {w}");
//! }
//! let mut poser = scene.poser(scene.find_animation("0"))?;
//! poser.pose(1.5);
//! let mut flat = dynbvh::geom::TriMesh::default();
//! poser.flatten_into(&mut flat);
//! # Ok::<(), dynbvh::Error>(())
//! ```

mod accessor;
pub mod generate;
mod glb_writer;
mod load;
mod mesh_load;
mod pose;
mod sampler;
mod scene;
mod source;

pub use accessor::{DECODED_BASE, DECODED_PER_INPUT_BYTE, decoded_limit};
pub use load::LoadOptions;
pub use pose::{InstanceClass, PARALLEL_VERTICES, Poser, classify};
pub use sampler::slerp;
pub use scene::{
    Animation, Channel, Instance, Interpolation, Mesh, Node, Property, Sampler, Scene, Skin,
    SkinAttributes, TimeMode, Trs, Warning,
};
