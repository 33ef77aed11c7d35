//! What an engine holds in memory, by what it is for ([`super::Engine::memory`]): what a
//! simulator sizing its scenes reads, or one checking that a mesh that does not deform keeps no
//! spare tree.

use serde::Serialize;

/// Bytes an engine holds, by what they are for: the storage its buffers have, room reserved
/// for later rebuilds included (the engine sizes its trees and scratch in the first frames, so
/// that the frame loop allocates nothing after them).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct EngineMemory {
    /// Vertex positions and triangle indices of every mesh.
    pub geometry: usize,
    /// The trees rays walk: each mesh's binary tree and 8-wide tree, and the top-level tree
    /// over the instances with its instance boxes.
    pub trees: usize,
    /// Trees kept beside them: room for the tree a rebuild replaces, kept refitted while the
    /// rebuild is on trial (and its 8-wide tree), and the buffers of a background build.
    pub spares: usize,
    /// Scratch of builds, rebuilds and estimates: the build and restructure workspaces, the
    /// fresh-build estimators' subsamples, the partial rebuilds' cuts, the clip's sampled
    /// poses, the ray sample's entries.
    pub scratch: usize,
}

impl EngineMemory {
    /// All of it.
    #[must_use]
    pub fn total(&self) -> usize {
        self.geometry + self.trees + self.spares + self.scratch
    }
}
