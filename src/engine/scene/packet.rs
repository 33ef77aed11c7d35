//! Packets through the two-level scene: the top-level tree is walked by the world packet; each
//! instance leaf reached runs the packet's rays that reach it, moved into the instance's space
//! exactly as a single ray is, through the instance's mesh tree as a packet of their own.

use super::{Engine, InstanceId, SceneHit, local_ray};
use crate::bvh::{MAX_PACKET, PacketMode, RayPacket, with_packet};
use crate::geom::Ray;

impl Engine {
    /// Closest hits of `rays` (`out[i]` for `rays[i]`), traced as packets of up to
    /// [`MAX_PACKET`] consecutive rays on the calling thread; give coherent rays next to each
    /// other (e.g. 8x8 tiles of an image). Exactly the hits of [`Engine::closest_hit`];
    /// packets that are not coherent are traced ray by ray.
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn closest_hit_packet(&self, rays: &[Ray], out: &mut [Option<SceneHit>]) {
        self.closest_hit_packet_mode(rays, out, PacketMode::Auto);
    }

    /// [`Engine::closest_hit_packet`], choosing when to trace packets by `mode`.
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn closest_hit_packet_mode(
        &self,
        rays: &[Ray],
        out: &mut [Option<SceneHit>],
        mode: PacketMode,
    ) {
        assert_eq!(rays.len(), out.len(), "one output per ray");
        with_packet(|world| {
            with_packet(|local| self.closest_packets(rays, out, mode, world, local))
        });
    }

    fn closest_packets(
        &self,
        rays: &[Ray],
        out: &mut [Option<SceneHit>],
        mode: PacketMode,
        world: &mut RayPacket,
        local: &mut RayPacket,
    ) {
        let prims = self.tlas.prim_indices();
        for (r, o) in rays.chunks(MAX_PACKET).zip(out.chunks_mut(MAX_PACKET)) {
            world.load(r);
            if !mode.use_packet(world) {
                for (r, o) in r.iter().zip(o.iter_mut()) {
                    *o = self.closest_hit(r);
                }
                continue;
            }
            o.fill(None);
            self.tlas.traverse_packet::<false>(
                world,
                |_| {},
                |wp, slot, lanes| {
                    let k = self.tlas_instances[prims[slot] as usize];
                    let inst = &self.instances[k as usize];
                    if !inst.visible {
                        return false;
                    }
                    local.load_with(wp.len(), lanes, |i| local_ray(inst, wp.ray(i), wp.tmax(i)));
                    let m = &self.meshes[inst.mesh as usize];
                    match &m.wide {
                        Some(w) => w.closest_packet(local),
                        None => m.bvh.closest_packet(local),
                    }
                    let mut found = local.found();
                    let changed = found != 0;
                    while found != 0 {
                        let i = found.trailing_zeros() as usize;
                        found &= found - 1;
                        if let Some((t, u, v, s)) = local.closest(i) {
                            wp.set_tmax(i, t);
                            o[i] = Some(SceneHit {
                                t,
                                u,
                                v,
                                prim: match &m.wide {
                                    Some(w) => w.slot_prim(s),
                                    None => m.bvh.bvh().prim_indices()[s as usize],
                                },
                                instance: InstanceId(k),
                            });
                        }
                    }
                    changed
                },
            );
        }
    }

    /// Any-hit answers of `rays` (`out[i]` for `rays[i]`), as packets of up to [`MAX_PACKET`]
    /// consecutive rays; exactly the answers of [`Engine::any_hit`].
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn any_hit_packet(&self, rays: &[Ray], out: &mut [bool]) {
        self.any_hit_packet_mode(rays, out, PacketMode::Auto);
    }

    /// [`Engine::any_hit_packet`], choosing when to trace packets by `mode`.
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn any_hit_packet_mode(&self, rays: &[Ray], out: &mut [bool], mode: PacketMode) {
        assert_eq!(rays.len(), out.len(), "one output per ray");
        with_packet(|world| with_packet(|local| self.any_packets(rays, out, mode, world, local)));
    }

    fn any_packets(
        &self,
        rays: &[Ray],
        out: &mut [bool],
        mode: PacketMode,
        world: &mut RayPacket,
        local: &mut RayPacket,
    ) {
        let prims = self.tlas.prim_indices();
        for (r, o) in rays.chunks(MAX_PACKET).zip(out.chunks_mut(MAX_PACKET)) {
            world.load(r);
            if !mode.use_packet(world) {
                for (r, o) in r.iter().zip(o.iter_mut()) {
                    *o = self.any_hit(r);
                }
                continue;
            }
            self.tlas.traverse_packet::<true>(
                world,
                |_| {},
                |wp, slot, lanes| {
                    let k = self.tlas_instances[prims[slot] as usize];
                    let inst = &self.instances[k as usize];
                    if !inst.visible {
                        return false;
                    }
                    local.load_with(wp.len(), lanes, |i| local_ray(inst, wp.ray(i), wp.tmax(i)));
                    let m = &self.meshes[inst.mesh as usize];
                    match &m.wide {
                        Some(w) => w.any_packet(local),
                        None => m.bvh.any_packet(local),
                    }
                    let hit = lanes & !local.active();
                    wp.retire(hit);
                    hit != 0
                },
            );
            for (i, o) in o.iter_mut().enumerate() {
                *o = world.occluded(i);
            }
        }
    }
}
