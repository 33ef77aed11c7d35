//! The per-frame engine: a two-level scene whose deforming meshes are refitted or rebuilt each
//! frame as a [`Policy`] decides from the measured SAH degradation, the oracle that finds the
//! best schedule in hindsight, and the frame sources (glTF animations, generated meshes) that
//! drive it.

pub mod estimate;
pub mod gltf;
pub mod memory;
pub mod oracle;
pub mod policy;
pub mod prices;
pub mod ray_work;
pub mod routine;
mod scene;
pub mod source;
pub mod stats;
pub mod watch;

pub use memory::EngineMemory;
pub use policy::{Action, Decision, ParsePolicyError, Policy};
pub use prices::Prices;
pub use ray_work::{CostMeasure, Query, SampleEntry, WorkEstimate};
pub use scene::{
    Engine, EngineConfig, HitDetail, InstanceId, MeshId, QueryFilter, SceneHit, ScenePoint, Timing,
    TlasPolicy, Traversal, WorkerPriority, expected_work, expected_work_wide, tree_sah,
};
pub use source::FrameSource;
pub use stats::{FrameStats, MeshStats};
