//! Frames traced with packets (camera rays, shadow rays, both) equal frames traced ray by ray,
//! pixel for pixel and count for count, on the shipped animations: deforming meshes after
//! refits, and rigid instances placed by transforms (packets moved into instance space). The
//! engine walking 8-wide mesh trees renders the same frames as the binary one, pixel for pixel,
//! ray by ray and as packets.

use dynbvh::anim::Scene;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::source::FrameSource;
use dynbvh::engine::{EngineConfig, Policy, Traversal};
use dynbvh::render::{
    Camera, EngineShading, PacketUse, Renderer, Settings, Stage, animation_bounds,
};
use image::RgbImage;
use std::path::PathBuf;

#[test]
fn packets_render_the_same_pixels_as_single_rays() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("animations");
    for (file, frame) in [
        ("explode.glb", 7),
        ("orbit.glb", 5),
        ("swap.glb", 9),
        ("wave.glb", 3),
    ] {
        let (scene, _) = Scene::load(dir.join(file)).unwrap();
        let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(12)).unwrap();
        let bounds = animation_bounds(&scene, Some(0), src.times()).unwrap();
        // An image whose sides are not multiples of the 16-pixel tile.
        let (w, h) = (83, 61);
        let stage = Stage::new(Camera::framing(&bounds, w as f32 / h as f32), &bounds, true);
        // The traversal is set on both sides: the default is one of them.
        let config = EngineConfig {
            policy: Policy::Refit,
            traversal: Traversal::Binary,
            ..EngineConfig::default()
        };
        let mut engine = src.build(0, config);
        let mut wide = src.build(
            0,
            EngineConfig {
                traversal: Traversal::Wide,
                ..config
            },
        );
        assert_eq!(engine.config().traversal, Traversal::Binary);
        assert_eq!(wide.config().traversal, Traversal::Wide);
        for f in 1..=frame {
            for e in [&mut engine, &mut wide] {
                src.advance(e, f);
                e.update();
            }
        }
        let mut shading = EngineShading::new();
        shading.refresh_all(&engine);
        let mut wide_shading = EngineShading::new();
        wide_shading.refresh_all(&wide);
        for smooth in [true, false] {
            let mut r = Renderer::new(Settings {
                width: w,
                height: h,
                smooth,
                shadows: true,
                heatmap: None,
            });
            // The reference: the binary trees, ray by ray. Every other variant (packets, and
            // the wide trees ray by ray and as packets) must give its pixels and counts.
            let mut want = RgbImage::new(1, 1);
            let want_counts = r.render(
                &shading.tracer(&engine).with_packets(PacketUse::NONE),
                &stage,
                &mut want,
            );
            assert!(
                want_counts.hits > 50,
                "{file}: the camera sees the scene ({} hits)",
                want_counts.hits
            );
            for (packets, e, sh) in [
                (PacketUse::DEFAULT, &engine, &shading),
                (
                    PacketUse {
                        primary: true,
                        shadow: false,
                    },
                    &engine,
                    &shading,
                ),
                (
                    PacketUse {
                        primary: false,
                        shadow: true,
                    },
                    &engine,
                    &shading,
                ),
                (PacketUse::NONE, &wide, &wide_shading),
                (PacketUse::DEFAULT, &wide, &wide_shading),
            ] {
                let t = e.config().traversal;
                let mut got = RgbImage::new(1, 1);
                let counts = r.render(&sh.tracer(e).with_packets(packets), &stage, &mut got);
                assert_eq!(counts, want_counts, "{file} {t} {packets:?}");
                let differing = got
                    .pixels()
                    .zip(want.pixels())
                    .filter(|(a, b)| a != b)
                    .count();
                assert_eq!(differing, 0, "{file} {t} {packets:?} smooth {smooth}");
            }
        }
    }
}
