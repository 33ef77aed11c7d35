//! Scene edits beyond moving things: replacing a mesh's triangles, removing meshes and
//! instances. Ids stay valid: an edit never renumbers other meshes or instances, and a
//! removed id is never given out again (it stays a dead slot, counted by
//! [`Engine::mesh_count`] / [`Engine::instance_count`]). Edits may allocate; the next
//! [`Engine::update`] rebuilds the top-level tree.

use super::{Engine, InstanceId, MeshId, MeshSample, RaySample};
use crate::bvh::MeshBvh;
use crate::error::{Error, Result};
use glam::Vec3;

impl Engine {
    /// Replaces `mesh`'s vertices and triangles (any counts) and builds its trees now; every
    /// instance placing it shows the new mesh from the next update on. The mesh's policy state
    /// starts afresh, as for a new mesh; a static mesh ([`Engine::add_static_mesh`]) stays
    /// static.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `mesh` is not a live mesh of this engine or a vertex
    /// index is out of range.
    pub fn replace_mesh(
        &mut self,
        mesh: MeshId,
        positions: Vec<Vec3>,
        indices: Vec<[u32; 3]>,
    ) -> Result<()> {
        self.check_mesh(mesh)?;
        if let Some((k, t)) = indices
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&i| i as usize >= positions.len()))
        {
            return Err(Error::InvalidArgument(format!(
                "replace_mesh({mesh:?}): triangle {k} has vertex index {:?} beyond the {} vertices",
                t,
                positions.len()
            )));
        }
        self.background.cancel(mesh);
        let fixed = self.meshes[mesh.0 as usize].fixed;
        let entry = self.new_mesh_entry(positions, indices, fixed);
        self.meshes[mesh.0 as usize] = entry;
        for inst in &mut self.instances {
            if inst.mesh == mesh.0 {
                inst.dirty = true;
            }
        }
        self.relink();
        Ok(())
    }

    /// Removes an instance: no query sees it again, and its id is not reused.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when it is not a live instance of this engine.
    pub fn remove_instance(&mut self, i: InstanceId) -> Result<()> {
        self.check_instance(i)?;
        let inst = &mut self.instances[i.0 as usize];
        inst.removed = true;
        inst.visible = false;
        self.relink();
        Ok(())
    }

    /// Removes a mesh no live instance places, freeing its vertices and trees; its id is not
    /// reused.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when it is not a live mesh of this engine, or an instance
    /// still places it (remove that first).
    pub fn remove_mesh(&mut self, mesh: MeshId) -> Result<()> {
        self.check_mesh(mesh)?;
        if let Some(k) = self
            .instances
            .iter()
            .position(|inst| inst.mesh == mesh.0 && !inst.removed)
        {
            return Err(Error::InvalidArgument(format!(
                "remove_mesh({mesh:?}): instance {k} still places it"
            )));
        }
        self.background.cancel(mesh);
        let m = &mut self.meshes[mesh.0 as usize];
        m.positions = Vec::new();
        m.indices = Vec::new();
        m.bvh = MeshBvh::default();
        m.prev = MeshBvh::default();
        m.prev_wide = None;
        m.wide = None;
        m.probe = None;
        m.dirty = false;
        m.moved = false;
        m.removed = true;
        self.relink();
        Ok(())
    }

    /// True for an instance that was added and not removed.
    #[must_use]
    pub fn is_live_instance(&self, i: InstanceId) -> bool {
        self.instances.get(i.0 as usize).is_some_and(|x| !x.removed)
    }

    /// True for a mesh that was added and not removed.
    #[must_use]
    pub fn is_live_mesh(&self, mesh: MeshId) -> bool {
        self.meshes.get(mesh.0 as usize).is_some_and(|m| !m.removed)
    }

    pub(super) fn check_mesh(&self, mesh: MeshId) -> Result<()> {
        if self.is_live_mesh(mesh) {
            Ok(())
        } else {
            Err(Error::InvalidArgument(format!(
                "{mesh:?} is not a live mesh of this engine ({} added)",
                self.meshes.len()
            )))
        }
    }

    fn check_instance(&self, i: InstanceId) -> Result<()> {
        if self.is_live_instance(i) {
            Ok(())
        } else {
            Err(Error::InvalidArgument(format!(
                "{i:?} is not a live instance of this engine ({} added)",
                self.instances.len()
            )))
        }
    }

    /// Lists the top-level tree's primitives afresh (live instances of meshes with triangles),
    /// marks the tree for a rebuild and drops this frame's ray-work sample (its entries name
    /// the trees before the edit).
    fn relink(&mut self) {
        self.tlas_instances.clear();
        self.tlas_boxes.clear();
        for (k, inst) in self.instances.iter_mut().enumerate() {
            inst.tlas_prim = None;
            if inst.removed || self.meshes[inst.mesh as usize].indices.is_empty() {
                continue;
            }
            inst.tlas_prim = Some(self.tlas_boxes.len() as u32);
            inst.dirty = true;
            self.tlas_instances.push(k as u32);
            self.tlas_boxes.push(crate::geom::Aabb::EMPTY);
        }
        self.tlas_stale = true;
        self.sample = RaySample::new(u64::MAX);
        self.entries.clear();
        self.mesh_samples.fill(MeshSample::default());
    }
}
