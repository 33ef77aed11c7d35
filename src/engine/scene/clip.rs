//! A deforming mesh's tree built for its clip ([`MeshBvh::rebuild_clip_aware`], after Bittner
//! & Meister 2015): the topology chosen for sampled poses, the boxes those of the mesh's
//! current positions. A mesh given the sampled poses still ahead of it
//! ([`Engine::set_clip_ahead`]) has every policy rebuild built so, for the pose it is made at
//! and the sampled poses after it, and priced as such
//! ([`crate::engine::Prices::clip_rebuild_ms`]): a tree that stays good for the rest of the
//! clip costs several plain builds.

use super::{Engine, MeshEntry, MeshId, tree_sah};
use crate::bvh::build::clip::{ClipPoses, MAX_POSES};
use crate::bvh::{MeshBvh, MeshBvh8};
use crate::error::{Error, Result};
use glam::Vec3;

/// The sampled poses of a mesh's clip still ahead of it, and the scratch its clip-aware
/// rebuilds reuse.
#[derive(Clone, Debug, Default)]
pub(super) struct ClipAhead {
    /// The engine frame ([`super::FrameStats::frame`]) each pose is taken in at, ascending.
    frames: Vec<u64>,
    poses: Vec<Vec<Vec3>>,
    scratch: ClipPoses,
}

impl ClipAhead {
    /// Bytes held.
    pub(super) fn memory_bytes(&self) -> usize {
        use crate::bvh::held;
        held(&self.frames)
            + held(&self.poses)
            + self.poses.iter().map(held).sum::<usize>()
            + self.scratch.memory_bytes()
    }
}

/// The first of `frames` (ascending) after `frame`.
fn ahead_from(frames: &[u64], frame: u64) -> usize {
    frames.partition_point(|&f| f <= frame)
}

/// Poses a rebuild at `frame` is made for with sampled poses at `frames`: its own and those
/// after it (at most [`MAX_POSES`]), 0 when none is after it (a plain build).
fn poses_at(frames: &[u64], frame: u64) -> usize {
    match frames.len() - ahead_from(frames, frame) {
        0 => 0,
        ahead => (1 + ahead).min(MAX_POSES),
    }
}

impl MeshEntry {
    /// Rebuilds the mesh's binary tree at its current positions: for them and the clip's
    /// sampled poses after `frame` when there are any ([`Engine::set_clip_ahead`]), else a
    /// plain build. Returns the poses the build was made for (0: plain), also kept in
    /// `build_poses`.
    pub(super) fn build_tree(
        &mut self,
        frame: u64,
        build: &crate::bvh::BuildParams,
        ws: &mut crate::bvh::BuildWorkspace,
    ) -> usize {
        let ClipAhead {
            frames,
            poses,
            scratch,
        } = &mut self.clip;
        let ahead = &poses[ahead_from(frames, frame)..];
        let k = poses_at(frames, frame);
        if k == 0 {
            self.bvh
                .rebuild_indexed(&self.positions, &self.indices, build, ws);
        } else {
            // This pose and those after it, as many as `poses_at` counts.
            let mut views: [&[Vec3]; MAX_POSES] = [&[]; MAX_POSES];
            views[0] = &self.positions;
            for (v, p) in views[1..k].iter_mut().zip(ahead) {
                *v = p;
            }
            self.bvh.rebuild_clip_aware(
                &self.positions,
                &self.indices,
                &views[..k],
                build,
                ws,
                scratch,
            );
        }
        self.build_poses = k;
        self.build_poses
    }
}

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
        m.build_poses = poses.len().min(MAX_POSES);
        // The policy weighs what its next rebuild costs: a plain one, unless the mesh is given
        // the clip ahead ([`Engine::set_clip_ahead`]).
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

impl Engine {
    /// Gives `mesh` the sampled poses of its clip still ahead, so that each later rebuild of
    /// its tree is built for the pose it is made at and the poses of `poses` after it
    /// ([`MeshBvh::rebuild_clip_aware`]; at most [`MAX_POSES`] in all: the nearest), and
    /// priced so ([`crate::engine::Prices::clip_rebuild_ms`]); once none is ahead, rebuilds
    /// are plain again. The policy's expected rebuild cost is scaled to the new price.
    /// `poses[i] = (updates, positions)`: the positions the mesh is to have at the `updates`-th
    /// [`Engine::update`] from now (1: the next). Replaces the clip given before; an empty one
    /// makes rebuilds plain. The background rebuilds of [`crate::engine::Policy::Async`] stay
    /// plain. Allocates (the poses are kept; the first clip-aware rebuild grows its scratch).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `mesh` is not a live mesh of this engine, a pose has
    /// another vertex count than the mesh, or `updates` is 0.
    pub fn set_clip_ahead(&mut self, mesh: MeshId, poses: Vec<(u64, Vec<Vec3>)>) -> Result<()> {
        self.check_mesh(mesh)?;
        let now = self.frame;
        let m = &mut self.meshes[mesh.0 as usize];
        for (k, (updates, p)) in poses.iter().enumerate() {
            if p.len() != m.positions.len() || *updates == 0 {
                return Err(Error::InvalidArgument(format!(
                    "set_clip_ahead({mesh:?}): pose {k} ({updates} updates ahead) has {} \
                     vertices, the mesh {}; updates ahead count from 1",
                    p.len(),
                    m.positions.len()
                )));
            }
        }
        let mut poses = poses;
        poses.sort_by_key(|&(u, _)| u);
        // The policy's expected rebuild: as dear as a clip-aware one for the poses ahead of the
        // next update, in the proportion the prices give it to a plain one.
        let prices = self.config.prices;
        let tris = m.indices.len();
        let was = prices.clip_rebuild_ms(tris, poses_at(&m.clip.frames, now));
        // The `u`-th update from now runs as frame `now + u - 1`.
        m.clip.frames = poses.iter().map(|&(u, _)| now + u - 1).collect();
        m.clip.poses = poses.into_iter().map(|(_, p)| p).collect();
        let will = prices.clip_rebuild_ms(tris, poses_at(&m.clip.frames, now));
        if was > 0.0 {
            m.state.rebuild_ms *= will / was;
        }
        Ok(())
    }

    /// Poses `mesh`'s last (re)build was made for: 0 for a plain build, else the sampled poses
    /// of a clip-aware one ([`Engine::build_for_clip`], [`Engine::set_clip_ahead`]). What
    /// the build is priced by: [`crate::engine::Prices::clip_rebuild_ms`].
    ///
    /// # Panics
    /// When `mesh` is not a mesh of this engine.
    #[must_use]
    pub fn mesh_build_poses(&self, mesh: MeshId) -> usize {
        self.meshes[mesh.0 as usize].build_poses
    }
}
