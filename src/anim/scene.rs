//! The owned scene model: nodes, meshes, skins, animations and the mesh instances of the chosen
//! glTF scene.

use glam::{Mat4, Quat, Vec3};
use std::fmt;
use std::ops::Range;
use std::path::PathBuf;

/// Something valid but skipped or repaired while loading; printed by the CLI.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Warning(pub String);

impl fmt::Display for Warning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// Translation, rotation and scale of a node.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trs {
    /// Translation.
    pub translation: Vec3,
    /// Unit rotation quaternion.
    pub rotation: Quat,
    /// Scale.
    pub scale: Vec3,
}

impl Trs {
    /// The identity transform.
    pub const IDENTITY: Trs = Trs {
        translation: Vec3::ZERO,
        rotation: Quat::IDENTITY,
        scale: Vec3::ONE,
    };

    /// The matrix `T * R * S`.
    #[must_use]
    pub fn matrix(&self) -> Mat4 {
        Mat4::from_scale_rotation_translation(self.scale, self.rotation, self.translation)
    }
}

/// A node of the glTF node forest.
#[derive(Clone, Debug)]
pub struct Node {
    /// Name from the file.
    pub name: Option<String>,
    /// Parent node, `None` for roots.
    pub parent: Option<usize>,
    /// Child nodes.
    pub children: Vec<usize>,
    /// Rest transform as TRS (decomposed from `matrix` when the node has one).
    pub trs: Trs,
    /// The node's matrix, when the file gives one instead of TRS (used unless animated).
    pub matrix: Option<Mat4>,
    /// glTF mesh index.
    pub mesh: Option<usize>,
    /// glTF skin index.
    pub skin: Option<usize>,
    /// Node's default morph weights.
    pub weights: Option<Vec<f32>>,
}

impl Node {
    /// The rest local matrix.
    #[must_use]
    pub fn rest_matrix(&self) -> Mat4 {
        self.matrix.unwrap_or_else(|| self.trs.matrix())
    }
}

/// Per-vertex skinning attributes of a mesh: `influences` joint/weight pairs per vertex.
#[derive(Clone, Debug, Default)]
pub struct SkinAttributes {
    /// Pairs per vertex (4 per JOINTS_n/WEIGHTS_n set).
    pub influences: usize,
    /// Joint indices into the skin's joint list, `influences` per vertex.
    pub joints: Vec<u16>,
    /// Weights summing to 1 per vertex (or all zero), `influences` per vertex.
    pub weights: Vec<f32>,
}

/// Rest geometry of one glTF mesh, all surface primitives merged.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    /// Name from the file.
    pub name: Option<String>,
    /// Index of the mesh in the file.
    pub gltf_index: usize,
    /// Rest vertex positions (mesh space).
    pub positions: Vec<Vec3>,
    /// Triangles (winding as the spec's strip and fan rules give).
    pub indices: Vec<[u32; 3]>,
    /// Morph target position deltas, one full vertex array per target.
    pub targets: Vec<Vec<Vec3>>,
    /// The mesh's default morph weights (zeros when the file has none).
    pub weights: Vec<f32>,
    /// Skinning attributes, when the primitives have JOINTS_0/WEIGHTS_0.
    pub skin: Option<SkinAttributes>,
    /// Triangle range of each surface primitive kept.
    pub primitives: Vec<Range<usize>>,
}

/// A skin: joint nodes and their inverse bind matrices.
#[derive(Clone, Debug)]
pub struct Skin {
    /// Name from the file.
    pub name: Option<String>,
    /// Joint node indices.
    pub joints: Vec<usize>,
    /// One inverse bind matrix per joint.
    pub inverse_bind: Vec<Mat4>,
}

/// What an animation channel drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Property {
    /// Node translation.
    Translation,
    /// Node rotation.
    Rotation,
    /// Node scale.
    Scale,
    /// Morph weights of the node's mesh.
    Weights,
}

/// Keyframe interpolation mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interpolation {
    /// Hold the value of the previous key.
    Step,
    /// Linear (slerp for rotations).
    Linear,
    /// Cubic Hermite spline with in/out tangents.
    CubicSpline,
}

/// Keyframes: strictly increasing times and `width` values per key (three groups of `width`
/// — in-tangent, value, out-tangent — for cubic splines).
#[derive(Clone, Debug)]
pub struct Sampler {
    /// Interpolation mode.
    pub interpolation: Interpolation,
    /// Key times in seconds.
    pub times: Vec<f32>,
    /// Key values.
    pub values: Vec<f32>,
    /// Components per value.
    pub width: usize,
}

/// One animated property of one node.
#[derive(Clone, Copy, Debug)]
pub struct Channel {
    /// Target node.
    pub node: usize,
    /// Target property.
    pub property: Property,
    /// Index into the animation's samplers.
    pub sampler: usize,
}

/// A glTF animation.
#[derive(Clone, Debug)]
pub struct Animation {
    /// Name from the file.
    pub name: Option<String>,
    /// Channels (ones the engine cannot use are dropped with a warning).
    pub channels: Vec<Channel>,
    /// Samplers.
    pub samplers: Vec<Sampler>,
    /// Time of the last key over all channels, in seconds.
    pub duration: f32,
}

/// One placement of a mesh by a node of the chosen scene.
#[derive(Clone, Debug)]
pub struct Instance {
    /// The placing node.
    pub node: usize,
    /// Index into [`Scene::meshes`].
    pub mesh: usize,
    /// glTF skin index, when the instance is skinned.
    pub skin: Option<usize>,
    /// Default morph weights (the node's, else the mesh's), one per target.
    pub weights: Vec<f32>,
    /// This instance's triangles in a flattened mesh.
    pub triangles: Range<usize>,
    /// This instance's vertices in a flattened mesh.
    pub vertices: Range<usize>,
}

/// A loaded glTF scene, ready to pose.
#[derive(Clone, Debug)]
pub struct Scene {
    /// The file it came from.
    pub path: PathBuf,
    /// The chosen glTF scene index (`None` when the file has no scenes and all roots are used).
    pub scene_index: Option<usize>,
    /// Names of all scenes in the file.
    pub scene_names: Vec<Option<String>>,
    /// All nodes of the file.
    pub nodes: Vec<Node>,
    /// All nodes, parents before children.
    pub order: Vec<usize>,
    /// Root nodes of the chosen scene.
    pub roots: Vec<usize>,
    /// Meshes the chosen scene places.
    pub meshes: Vec<Mesh>,
    /// All skins of the file.
    pub skins: Vec<Skin>,
    /// All animations of the file.
    pub animations: Vec<Animation>,
    /// Mesh instances of the chosen scene, in depth-first order.
    pub instances: Vec<Instance>,
}

/// How posing maps a time beyond the animation's duration.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TimeMode {
    /// `t` beyond `[0, duration]` wraps modulo the duration.
    #[default]
    Loop,
    /// Every channel holds its first/last key outside its key range.
    Clamp,
}

impl Scene {
    /// Total triangles over all instances.
    #[must_use]
    pub fn triangle_count(&self) -> usize {
        self.instances.last().map_or(0, |i| i.triangles.end)
    }

    /// Total vertices over all instances.
    #[must_use]
    pub fn vertex_count(&self) -> usize {
        self.instances.last().map_or(0, |i| i.vertices.end)
    }

    /// Triangle range of each instance in a flattened mesh, in instance order.
    #[must_use]
    pub fn instance_triangle_ranges(&self) -> Vec<Range<usize>> {
        self.instances.iter().map(|i| i.triangles.clone()).collect()
    }

    /// The instance owning triangle `tri` of a flattened mesh.
    #[must_use]
    pub fn instance_of_triangle(&self, tri: usize) -> Option<usize> {
        let k = self.instances.partition_point(|i| i.triangles.end <= tri);
        (k < self.instances.len() && self.instances[k].triangles.contains(&tri)).then_some(k)
    }

    /// Finds an animation by name, or by index given as a decimal string.
    #[must_use]
    pub fn find_animation(&self, key: &str) -> Option<usize> {
        self.animations
            .iter()
            .position(|a| a.name.as_deref() == Some(key))
            .or_else(|| {
                key.parse::<usize>()
                    .ok()
                    .filter(|&i| i < self.animations.len())
            })
    }
}
