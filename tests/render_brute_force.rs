//! Frames traced through the engine's trees equal frames traced by brute force over the same
//! posed triangles, pixel for pixel: CesiumMan (skinned) at a chosen time, and a shipped
//! deforming animation after refits. Instances placed by transforms (rigid cubes) are traced in
//! their own space, where distances round differently, so those only have to agree on nearly
//! every pixel.

use dynbvh::anim::Scene;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::source::FrameSource;
use dynbvh::engine::{EngineConfig, Policy};
use dynbvh::geom::TriMesh;
use dynbvh::render::{
    BruteForce, Camera, EngineShading, FrameCounts, Renderer, Settings, Stage, animation_bounds,
};
use image::RgbImage;
use std::path::{Path, PathBuf};

const W: u32 = 96;
const H: u32 = 72;

fn samples_dir() -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/gltf-samples");
    if dir.is_dir() {
        return Some(dir);
    }
    let msg = format!(
        "!!!!! glTF samples folder {} is missing: CesiumMan render test SKIPPED !!!!!",
        dir.display()
    );
    assert!(std::env::var_os("CI").is_none(), "{msg} (CI is set)");
    eprintln!("{msg}");
    None
}

struct Pair {
    engine: RgbImage,
    brute: RgbImage,
    engine_counts: FrameCounts,
    brute_counts: FrameCounts,
}

/// Renders frame `frame` of a `frames`-frame loop of `path` through the engine (built at frame
/// 0 and refitted under `policy` up to `frame`) and by brute force.
fn render_both(
    path: &Path,
    frames: usize,
    frame: usize,
    policy: Policy,
    settings: Settings,
) -> Pair {
    let (scene, _) = Scene::load(path).unwrap();
    let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(frames)).unwrap();
    let bounds = animation_bounds(&scene, Some(0), src.times()).unwrap();
    let camera = Camera::framing(&bounds, W as f32 / H as f32);
    let stage = Stage::new(camera, &bounds, true);
    let mut engine = src.build(
        0,
        EngineConfig {
            policy,
            ..EngineConfig::default()
        },
    );
    for f in 1..=frame {
        src.advance(&mut engine, f);
        engine.update();
    }
    let mut shading = EngineShading::new();
    shading.refresh_all(&engine);
    let mut r = Renderer::new(settings);
    let mut img = RgbImage::new(1, 1);
    let engine_counts = r.render(&shading.tracer(&engine), &stage, &mut img);

    let mut flat = TriMesh::default();
    src.flatten_into(&mut flat);
    let brute = BruteForce::new(&flat, &scene.instance_triangle_ranges());
    let mut bimg = RgbImage::new(1, 1);
    let brute_counts = r.render(&brute, &stage, &mut bimg);
    Pair {
        engine: img,
        brute: bimg,
        engine_counts,
        brute_counts,
    }
}

fn differing(p: &Pair) -> Vec<(u32, u32, [u8; 3], [u8; 3])> {
    p.engine
        .enumerate_pixels()
        .zip(p.brute.pixels())
        .filter(|((_, _, a), b)| a.0 != b.0)
        .map(|((x, y, a), b)| (x, y, a.0, b.0))
        .collect()
}

fn settings(smooth: bool) -> Settings {
    Settings {
        width: W,
        height: H,
        smooth,
        shadows: true,
        heatmap: None,
    }
}

#[test]
fn cesium_man_matches_brute_force_pixel_for_pixel() {
    let Some(dir) = samples_dir() else { return };
    let path = dir.join("CesiumMan/CesiumMan.glb");
    // Frame 13 of 24 over the walk cycle, refitted from frame 0.
    for smooth in [true, false] {
        let p = render_both(&path, 24, 13, Policy::Refit, settings(smooth));
        let d = differing(&p);
        assert!(
            d.is_empty(),
            "smooth={smooth}: {} pixels differ, e.g. {:?}",
            d.len(),
            &d[..d.len().min(5)]
        );
        assert_eq!(p.engine_counts.hits, p.brute_counts.hits);
        assert_eq!(p.engine_counts.shadow, p.brute_counts.shadow);
        assert!(
            p.engine_counts.hits > 200,
            "CesiumMan covers part of the frame ({} pixels)",
            p.engine_counts.hits
        );
        assert!(p.engine_counts.shadow > 0);
    }
}

#[test]
fn explode_after_refits_matches_brute_force_pixel_for_pixel() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("animations/explode.glb");
    let p = render_both(&path, 20, 7, Policy::Refit, settings(true));
    let d = differing(&p);
    assert!(
        d.is_empty(),
        "{} pixels differ: {:?}",
        d.len(),
        &d[..d.len().min(5)]
    );
    assert!(p.engine_counts.hits > 100);
}

#[test]
fn orbit_instances_match_brute_force_on_nearly_every_pixel() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("animations/orbit.glb");
    let p = render_both(&path, 16, 5, Policy::Amortized, settings(false));
    let d = differing(&p);
    // Rays carried into each cube's space round differently: a few edge pixels may change
    // which face (or which cube) they see, never more than a handful.
    assert!(
        d.len() <= (W * H / 200) as usize,
        "{} pixels differ: {:?}",
        d.len(),
        &d[..d.len().min(5)]
    );
    assert!(
        p.engine_counts.hits > 50,
        "the cubes cover part of the frame ({} pixels)",
        p.engine_counts.hits
    );
    let small = d
        .iter()
        .filter(|(_, _, a, b)| (0..3).all(|k| a[k].abs_diff(b[k]) <= 2))
        .count();
    eprintln!(
        "orbit: {} of {} pixels differ ({} by at most 2 levels)",
        d.len(),
        W * H,
        small
    );
}
