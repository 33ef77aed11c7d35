//! Rendering animated scenes: frames traced through the engine's trees (or brute force, as a
//! reference), shaded with smooth or flat normals, a key light with shadow rays, ambient light
//! and a ground; or coloured by the traversal work each pixel cost (heat maps), so that refitted
//! and rebuilt trees can be compared at a glance.
//!
//! ```no_run
//! use dynbvh::anim::Scene;
//! use dynbvh::engine::EngineConfig;
//! use dynbvh::engine::gltf::{FrameTimes, GltfSource};
//! use dynbvh::engine::source::FrameSource;
//! use dynbvh::render::{Camera, EngineShading, Renderer, Settings, Stage, animation_bounds};
//!
//! let (scene, _) = Scene::load("animations/explode.glb")?;
//! let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(30))?;
//! let bounds = animation_bounds(&scene, Some(0), src.times())?;
//! let settings = Settings::default();
//! let camera = Camera::framing(&bounds, settings.width as f32 / settings.height as f32);
//! let stage = Stage::new(camera, &bounds, true);
//! let mut engine = src.build(0, EngineConfig::default());
//! let mut shading = EngineShading::new();
//! shading.refresh_all(&engine);
//! let mut renderer = Renderer::new(settings);
//! let mut img = image::RgbImage::new(1, 1);
//! for f in 0..30 {
//!     if f > 0 {
//!         src.advance(&mut engine, f);
//!         engine.update();
//!         shading.refresh(&engine, src.deforming());
//!     }
//!     renderer.render(&shading.tracer(&engine), &stage, &mut img);
//!     img.save(format!("frame_{f:04}.png")).unwrap();
//! }
//! # Ok::<(), dynbvh::Error>(())
//! ```

mod camera;
pub mod font;
mod frame;
mod shade;
mod trace;

pub use camera::{
    AUTO_VIEW_DIR, AUTO_YFOV_DEGREES, Camera, GltfCamera, Projection, RayGen, gltf_cameras,
};
pub use frame::{
    FrameCounts, HEAT_BACKGROUND, Renderer, Settings, TILE, draw_heat_legend, heat_pixel,
    work_quantile,
};
pub use shade::{Ground, Stage, heat_color, srgb_to_linear, to_srgb};
pub use trace::{
    BruteForce, EngineShading, EngineTracer, PacketUse, Surface, Tracer, vertex_normals,
};

use crate::anim::Scene;
use crate::error::Result;
use crate::geom::Aabb;
use glam::Affine3A;

/// Box of every instance's triangles over the poses of animation `anim` at `times` (the
/// rest pose when `times` is empty): the automatic camera frames it, so that it does not
/// move from frame to frame, and every process rendering a part of the sequence frames the
/// same view. Far outliers are left out ([`animation_view`]).
pub fn animation_bounds(scene: &Scene, anim: Option<usize>, times: &[f32]) -> Result<Aabb> {
    Ok(animation_view(scene, anim, times)?.0)
}

/// [`animation_bounds`] and the most vertex uses one pose left out of it as far outliers
/// ([`crate::geom::framing_bounds`], pose by pose): a stray vertex at 1e30 does not put the
/// camera 1e30 away.
pub fn animation_view(scene: &Scene, anim: Option<usize>, times: &[f32]) -> Result<(Aabb, u64)> {
    let mut poser = scene.poser(anim)?;
    let mut b = Aabb::EMPTY;
    let mut most_left_out = 0;
    let rest = [0.0];
    let times = if times.is_empty() { &rest[..] } else { times };
    for &t in times {
        poser.pose(t);
        let (pose_box, left_out) = crate::geom::framing_bounds(|f| {
            for i in 0..scene.instances.len() {
                let m = Affine3A::from_mat4(poser.transform(i));
                let pos = poser.positions(i);
                for &v in poser.indices(i).iter().flatten() {
                    f(m.transform_point3(pos[v as usize]));
                }
            }
        });
        b = b.union(pose_box);
        most_left_out = most_left_out.max(left_out);
    }
    Ok((b, most_left_out))
}
