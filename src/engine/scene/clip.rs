//! A deforming mesh's tree built for its whole clip ([`MeshBvh::rebuild_clip_aware`]): the
//! topology chosen for sampled poses, the boxes those of the mesh's current positions. Later
//! rebuilds by the policy are plain builds of the pose they happen at (a clip-aware build
//! costs several plain ones, which the policy's prices do not know).

use super::{Engine, MeshEntry, MeshId, tree_sah};
use crate::bvh::build::clip::ClipPoses;
use crate::bvh::{MeshBvh, MeshBvh8};
use crate::error::{Error, Result};
use glam::Vec3;

impl Engine {
    /// Rebuilds `mesh`'s trees now for the clip sampled by `poses` (its vertex positions at
    /// several times, e.g. from [`crate::engine::gltf::GltfSource::with_clip_aware`]); the
    /// mesh's policy state starts from the new tree. Allocates.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `mesh` is not a live mesh of this engine or a pose has
    /// another vertex count than the mesh.
    pub fn build_for_clip(&mut self, mesh: MeshId, poses: &[&[Vec3]]) -> Result<()> {
        self.check_mesh(mesh)?;
        let m = &mut self.meshes[mesh.0 as usize];
        if let Some((k, p)) = poses
            .iter()
            .enumerate()
            .find(|(_, p)| p.len() != m.positions.len())
        {
            return Err(Error::InvalidArgument(format!(
                "build_for_clip({mesh:?}): pose {k} has {} vertices, the mesh {}",
                p.len(),
                m.positions.len()
            )));
        }
        let mut tree = MeshBvh::default();
        tree.rebuild_clip_aware(
            &m.positions,
            &m.indices,
            poses,
            &self.config.build,
            &mut self.workspace,
            &mut ClipPoses::default(),
        );
        m.sah = tree_sah(tree.bvh());
        m.stats.sah = m.sah;
        if m.wide.is_some() {
            m.wide = Some(MeshBvh8::from_mesh_bvh(&tree));
        }
        if MeshEntry::wants_cut(self.config.policy) {
            m.cut.reset(&tree, &mut self.restructure.partial);
        }
        m.bvh = tree;
        // A new tree in fresh storage: room for any tree is taken again at the next update.
        m.any_shape = false;
        m.probe = None;
        let (rebuild_ms, estimate) = (m.state.rebuild_ms, m.state.build_estimate);
        m.state.rebuilt(m.sah, estimate, rebuild_ms);
        m.degradation.reset();
        for inst in &mut self.instances {
            if inst.mesh == mesh.0 {
                inst.dirty = true;
            }
        }
        Ok(())
    }
}
