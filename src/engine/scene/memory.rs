//! [`Engine::memory`]: the bytes an engine holds, by what they are for.

use super::Engine;
use crate::bvh::MeshBvh8;
use crate::bvh::held;
use crate::engine::memory::EngineMemory;
use std::sync::PoisonError;

impl Engine {
    /// The bytes the engine holds, by what they are for ([`EngineMemory`]): its meshes'
    /// geometry, the trees rays walk, the spare trees it keeps beside them and its scratch.
    /// A mesh added static keeps no spare tree.
    #[must_use]
    pub fn memory(&self) -> EngineMemory {
        let wide = |w: &Option<MeshBvh8>| w.as_ref().map_or(0, MeshBvh8::storage_bytes);
        let mut m = EngineMemory::default();
        for e in &self.meshes {
            m.geometry += held(&e.positions) + held(&e.indices);
            m.trees += e.bvh.storage_bytes() + wide(&e.wide);
            m.spares += e.prev.storage_bytes() + wide(&e.prev_wide);
            m.scratch += e.fresh.memory_bytes() + e.cut.memory_bytes() + e.clip.memory_bytes();
        }
        m.trees += self.tlas.storage_bytes()
            + held(&self.tlas_boxes)
            + held(&self.tlas_instances)
            + held(&self.instances);
        m.spares += self.background.memory_bytes();
        let order = self
            .order
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .memory_bytes();
        m.scratch += self.workspace.memory_bytes()
            + self.restructure.ws.memory_bytes()
            + self.restructure.optimize.memory_bytes()
            + self.restructure.partial.memory_bytes()
            + held(&self.entries)
            + held(&self.mesh_samples)
            + order;
        m
    }
}
