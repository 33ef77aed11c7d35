//! The sensor scene moves enough to degrade a refitted tree, and the lidar fan sees it: over the
//! clip, the tree built on the first frame and refitted costs clearly more than a fresh build,
//! in SAH and in the work the lidar's own rays do, and is as good again once the clip loops.

use dynbvh::anim::generate::{Kind, generate};
use dynbvh::anim::{LoadOptions, Scene};
use dynbvh::bvh::{BuildParams, MeshBvh, TraversalStats};
use dynbvh::geom::{Ray, TriMesh};
use dynbvh::report::rays::lidar_rays;
use std::path::Path;

/// Nodes visited plus triangles tested by `rays` on `bvh`.
fn work(bvh: &MeshBvh, rays: &[Ray]) -> u64 {
    let mut stats = TraversalStats::default();
    for r in rays {
        let _ = bvh.closest_hit_counted(r, &mut stats);
    }
    stats.nodes + stats.prims
}

#[test]
fn refitting_the_cloth_degrades_in_sah_and_in_lidar_ray_work() {
    let g = generate(Kind::LidarCloth, 20_000, 1);
    let (scene, _) =
        Scene::from_slice(Path::new("cloth.glb"), &g.glb, &LoadOptions::default()).unwrap();
    let mut poser = scene.poser(Some(0)).unwrap();
    let mut mesh = TriMesh::default();
    poser.pose(0.0);
    poser.flatten_into(&mut mesh);
    let bounds = mesh.bounds();
    let mut refitted = MeshBvh::build(&mesh, &BuildParams::BINNED);
    let mut rays = Vec::new();
    let frames = 16;
    let mut ratios = Vec::new();
    for f in 0..=frames {
        let t = g.duration * f as f32 / frames as f32;
        poser.pose(t);
        poser.flatten_into(&mut mesh);
        refitted.refit(&mesh);
        let fresh = MeshBvh::build(&mesh, &BuildParams::BINNED);
        lidar_rays(&bounds, 20_000, f, &mut rays);
        let sah = refitted.bvh().sah_cost() / fresh.bvh().sah_cost();
        let rays = work(&refitted, &rays) as f64 / work(&fresh, &rays) as f64;
        ratios.push((t, sah, rays));
    }
    let peak = |pick: fn(&(f32, f32, f64)) -> f64| ratios.iter().map(pick).fold(0.0, f64::max);
    let (sah_peak, rays_peak) = (peak(|r| f64::from(r.1)), peak(|r| r.2));
    assert!(sah_peak > 1.2, "SAH ratio peaked at {sah_peak}: {ratios:?}");
    assert!(
        rays_peak > 1.5,
        "ray-work ratio peaked at {rays_peak}: {ratios:?}"
    );
    // A quarter of the way through the clip the swirl has already cost the refitted tree.
    assert!(ratios[4].2 > 1.2, "{ratios:?}");
    // The clip loops: at its end the refitted tree is the first frame's tree again.
    let (_, sah_end, rays_end) = ratios[frames];
    assert!(
        (sah_end - 1.0).abs() < 0.02 && (rays_end - 1.0).abs() < 0.02,
        "{ratios:?}"
    );
}
