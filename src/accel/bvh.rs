//! The binary BVH behind the same interface, so that tests and benchmarks can put it beside
//! the other structures.

use super::Accel;
use crate::bvh::{MeshBvh, TraversalStats};
use crate::geom::{Hit, Ray, TriMesh};

impl Accel for MeshBvh {
    fn name(&self) -> String {
        "bvh".into()
    }

    fn closest_hit(&self, ray: &Ray) -> Option<Hit> {
        MeshBvh::closest_hit(self, ray)
    }

    fn any_hit(&self, ray: &Ray) -> bool {
        MeshBvh::any_hit(self, ray)
    }

    fn closest_hit_counted(&self, ray: &Ray, stats: &mut TraversalStats) -> Option<Hit> {
        MeshBvh::closest_hit_counted(self, ray, stats)
    }

    fn any_hit_counted(&self, ray: &Ray, stats: &mut TraversalStats) -> bool {
        MeshBvh::any_hit_counted(self, ray, stats)
    }

    fn validate(&self, mesh: &TriMesh) -> Result<(), String> {
        MeshBvh::validate(self, mesh)
    }

    fn memory_bytes(&self) -> usize {
        MeshBvh::memory_bytes(self)
    }

    fn nodes(&self) -> usize {
        self.bvh().nodes().len()
    }

    fn depth(&self) -> usize {
        self.bvh().depth()
    }

    fn sah(&self) -> Option<f32> {
        Some(self.bvh().sah_cost())
    }

    fn refit(&mut self, mesh: &TriMesh) -> bool {
        MeshBvh::refit(self, mesh);
        true
    }
}
