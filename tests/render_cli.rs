//! The `render` command end to end: numbered PNGs and a GIF (decoded: its frames and size),
//! frame ranges that join up (each starts with a fresh build, the camera does not depend on the
//! range), heat maps of two policies side by side with their legends, errors for ranges beyond
//! the animation, and the file's own camera.

mod anim_util;
mod cli_util;
use cli_util::{animation, dynbvh, ok};
use dynbvh::anim::Scene;
use dynbvh::engine::EngineConfig;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::source::FrameSource;
use dynbvh::render::{
    Camera, EngineShading, Projection, Renderer, Settings, Stage, animation_bounds, gltf_cameras,
};
use glam::Vec3;
use image::codecs::gif::GifDecoder;
use image::{AnimationDecoder, RgbImage};
use std::path::{Path, PathBuf};

#[test]
fn split_ranges_join_up_and_gif_is_written() {
    let tube = animation("tube.glb");
    let (a, b) = (
        cli_util::tmp_dir("render", "range_a"),
        cli_util::tmp_dir("render", "range_b"),
    );
    let common = ["--size", "48x36", "--shadows", "--fps", "12"];
    let mut args = vec!["render", &tube, "--frames", "0..4", "--gif", "--out"];
    let a_s = a.to_string_lossy().into_owned();
    args.push(&a_s);
    args.extend(common);
    ok(&dynbvh(&args));
    let b_s = b.to_string_lossy().into_owned();
    let mut args = vec!["render", &tube, "--frames", "2..4", "--out", &b_s];
    args.extend(common);
    ok(&dynbvh(&args));
    for f in 0..4 {
        assert!(a.join(format!("frame_{f:04}.png")).is_file(), "frame {f}");
    }
    assert!(!b.join("frame_0001.png").exists());
    // Frames 2 and 3: refitted since frame 0 in one run, built fresh at 2 in the other; the
    // same picture either way.
    for f in 2..4 {
        let name = format!("frame_{f:04}.png");
        let x = image::open(a.join(&name)).unwrap().to_rgb8();
        let y = image::open(b.join(&name)).unwrap().to_rgb8();
        assert_eq!(x.dimensions(), (48, 36));
        assert!(x == y, "{name} differs between the runs");
    }
    // The GIF holds the four frames of the range at the frames' size.
    let gif = std::fs::File::open(a.join("frame_0000-0004.gif")).unwrap();
    let frames = GifDecoder::new(std::io::BufReader::new(gif))
        .unwrap()
        .into_frames()
        .collect_frames()
        .unwrap();
    assert_eq!(frames.len(), 4);
    for f in &frames {
        assert_eq!(f.buffer().dimensions(), (48, 36));
    }
    let _ = std::fs::remove_dir_all(&a);
    let _ = std::fs::remove_dir_all(&b);
}

/// One row of `render --bench`'s per-frame table.
#[derive(Debug)]
struct BenchRow {
    frame: usize,
    action: String,
    /// `None` where the table prints `–` (not computed: frames after a run's first).
    build_ms: Option<f64>,
    /// Pose time, `None` on a run's first frame (a fresh build).
    pose_ms: Option<f64>,
    primary: u64,
    shadow: u64,
    work_per_px: String,
    max_work: String,
}

/// A table cell: a number, or `None` for the dash of a value not computed.
fn cell(c: &str) -> Option<f64> {
    if c == "\u{2013}" {
        None
    } else {
        Some(
            c.parse()
                .unwrap_or_else(|_| panic!("{c:?} is neither a number nor –")),
        )
    }
}

/// The per-frame rows of policy `policy` in `render --bench` output.
fn bench_rows(out: &str, policy: &str) -> Vec<BenchRow> {
    let prefix = format!("policy {policy}: ");
    out.lines()
        .filter_map(|l| l.strip_prefix(&prefix))
        .filter(|l| !l.trim_start().starts_with("frame"))
        .map(|l| {
            let c: Vec<&str> = l.split_whitespace().collect();
            // frame action build pose update normals trace total primary shadow SAH work max
            assert_eq!(c.len(), 13, "{l}");
            BenchRow {
                frame: c[0].parse().unwrap(),
                action: c[1].to_string(),
                build_ms: cell(c[2]),
                pose_ms: cell(c[3]),
                primary: c[8].parse().unwrap(),
                shadow: c[9].parse().unwrap(),
                work_per_px: c[11].to_string(),
                max_work: c[12].to_string(),
            }
        })
        .collect()
}

#[test]
fn a_range_starts_with_a_fresh_build() {
    // Heat-map work tells the trees apart: a range's first frame costs what a tree built for
    // that frame costs, not what one refitted since frame 0 does.
    let tube = animation("tube.glb");
    let run = |frames: &str, policy: &str| {
        let out = ok(&dynbvh(&[
            "render",
            &tube,
            "--frames",
            frames,
            "--fps",
            "12",
            "--size",
            "48x36",
            "--heatmap",
            "--shadows",
            "--bench",
            "--policy",
            policy,
        ]));
        bench_rows(&out, policy)
    };
    let range = run("8..10", "refit");
    let refitted = run("0..10", "refit");
    let rebuilt = run("0..10", "rebuild");
    assert_eq!(range.len(), 2, "{range:?}");
    assert_eq!((range[0].frame, range[1].frame), (8, 9));
    assert_eq!(range[0].action, "rebuild", "{range:?}");
    assert!(range[0].build_ms.is_some_and(|b| b > 0.0), "{range:?}");
    assert_eq!(
        (range[0].pose_ms, range[1].build_ms),
        (None, None),
        "{range:?}"
    );
    assert!(range[1].pose_ms.is_some(), "{range:?}");
    assert_eq!(range[1].action, "refit", "{range:?}");
    assert!(refitted[1..].iter().all(|r| r.action == "refit"));
    let fresh = &rebuilt[8];
    assert_eq!((fresh.frame, refitted[8].frame), (8, 8));
    assert_eq!(
        (&range[0].work_per_px, &range[0].max_work),
        (&fresh.work_per_px, &fresh.max_work),
        "the range's first frame traces a freshly built tree"
    );
    assert_ne!(
        (&refitted[8].work_per_px, &refitted[8].max_work),
        (&fresh.work_per_px, &fresh.max_work),
        "refitting since frame 0 makes a different tree by frame 8"
    );
}

#[test]
fn heat_map_comparison_writes_side_by_side_frames() {
    let d = cli_util::tmp_dir("render", "compare");
    let d_s = d.to_string_lossy().into_owned();
    let out = ok(&dynbvh(&[
        "render",
        &animation("swap.glb"),
        "--frames",
        "3",
        "--size",
        "160x120",
        "--heatmap",
        "--compare",
        "refit,rebuild",
        "--out",
        &d_s,
    ]));
    assert!(out.contains("refit:") && out.contains("rebuild:"), "{out}");
    let (w, h) = (160, 120);
    let img = image::open(d.join("compare_0002.png")).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (2 * w + 4, h));
    // A dark gap between the halves.
    for x in w..w + 4 {
        for y in 0..h {
            assert_eq!(img.get_pixel(x, y).0, [20, 20, 24], "gap at {x},{y}");
        }
    }
    let left = image::imageops::crop_imm(&img, 0, 0, w, h).to_image();
    let right = image::imageops::crop_imm(&img, w + 4, 0, w, h).to_image();
    // The pictures differ below the labels and above the legends: the refitted tree costs
    // other work than the rebuilt one.
    let differing = (16..h - 40)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter(|&(x, y)| left.get_pixel(x, y) != right.get_pixel(x, y))
        .count();
    assert!(
        differing > 200,
        "{differing} pixels differ between refit and rebuild"
    );
    for (side, half) in [("refit", &left), ("rebuild", &right)] {
        // The legend along the bottom: a colour bar (a row of many colours) and its light grey
        // (antialiased) text.
        let bar = (h - 40..h).any(|y| {
            let row: std::collections::HashSet<[u8; 3]> =
                (0..w).map(|x| half.get_pixel(x, y).0).collect();
            row.len() > 30
        });
        assert!(bar, "{side}: legend bar");
        let text = (h - 40..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                let p = half.get_pixel(x, y).0;
                p.iter().all(|&c| c >= 200) && p[0].abs_diff(p[2]) < 12
            })
            .count();
        assert!(text > 10, "{side}: legend text ({text} pixels)");
    }
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn bad_ranges_and_policies_are_errors() {
    let tube = animation("tube.glb");
    let o = dynbvh(&["render", &tube, "--frames", "50..100", "--bench"]);
    assert!(!o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("frames 0..61"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let o = dynbvh(&["render", &tube, "--compare", "refit", "--bench"]);
    assert!(!o.status.success());
    let o = dynbvh(&["render", &tube, "--policy", "sometimes", "--bench"]);
    assert!(!o.status.success());
}

/// A glTF file with one animated triangle and a camera at (0, 0.5, 3) turned a quarter turn
/// to the left (so it looks along -x).
fn write_camera_scene(dir: &Path) -> PathBuf {
    let mut buf: Vec<u8> = Vec::new();
    let floats: [f32; 17] = [
        -1.0, -1.0, 0.0, 1.0, -1.0, 0.0, 0.0, 1.0, 0.0, // positions
        0.0, 1.0, // key times
        0.0, 0.0, 0.0, 0.1, 0.0, 0.0, // translations
    ];
    for f in floats {
        buf.extend_from_slice(&f.to_le_bytes());
    }
    let s = std::f32::consts::FRAC_1_SQRT_2;
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0,1]}}],
"nodes":[{{"mesh":0}},{{"name":"eye","children":[2],"translation":[0,0.5,3]}},
 {{"camera":0,"rotation":[0,{s},0,{s}]}}],
"cameras":[{{"name":"main","type":"perspective","perspective":{{"yfov":0.7,"znear":0.01}}}}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
"buffers":[{{"byteLength":68,"uri":"data:application/octet-stream;base64,{}"}}],
"bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":36}},
 {{"buffer":0,"byteOffset":36,"byteLength":8}},{{"buffer":0,"byteOffset":44,"byteLength":24}}],
"accessors":[
 {{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[-1,-1,0],"max":[1,1,0]}},
 {{"bufferView":1,"componentType":5126,"count":2,"type":"SCALAR","min":[0],"max":[1]}},
 {{"bufferView":2,"componentType":5126,"count":2,"type":"VEC3"}}],
"animations":[{{"channels":[{{"sampler":0,"target":{{"node":0,"path":"translation"}}}}],
 "samplers":[{{"input":1,"output":2}}]}}]}}"#,
        anim_util::base64(&buf)
    );
    let p = dir.join("camera.gltf");
    std::fs::write(&p, json).unwrap();
    p
}

#[test]
fn the_files_camera_is_found_and_used() {
    let d = cli_util::tmp_dir("render", "camera");
    let path = write_camera_scene(&d);
    let (scene, _) = Scene::load(&path).unwrap();
    let cams = gltf_cameras(&scene).unwrap();
    assert_eq!(cams.len(), 1);
    assert_eq!(cams[0].node, 2);
    assert_eq!(cams[0].name.as_deref(), Some("main"));
    assert_eq!(cams[0].projection, Projection::Perspective { yfov: 0.7 });
    let mut poser = scene.poser(Some(0)).unwrap();
    poser.pose(0.5);
    let cam = Camera::from_node(&poser.world_matrices()[2], cams[0].projection);
    assert!((cam.eye - Vec3::new(0.0, 0.5, 3.0)).length() < 1e-5);
    assert!(
        (cam.forward - Vec3::NEG_X).length() < 1e-5,
        "{:?}",
        cam.forward
    );
    assert!((cam.up - Vec3::Y).length() < 1e-5);

    let p = path.to_string_lossy().into_owned();
    let out = ok(&dynbvh(&[
        "render", &p, "--frames", "2", "--size", "32x24", "--bench",
    ]));
    assert!(out.contains("the file's camera main (node 2)"), "{out}");
    let out = ok(&dynbvh(&[
        "render",
        &p,
        "--frames",
        "2",
        "--size",
        "32x24",
        "--bench",
        "--auto-camera",
    ]));
    assert!(out.contains("framed on the animation's bounds"), "{out}");
    // Looking away from the triangle, no primary ray hits it: the whole picture is sky and
    // ground.
    let o = d.join("out");
    let o_s = o.to_string_lossy().into_owned();
    ok(&dynbvh(&[
        "render", &p, "--frames", "2", "--size", "32x24", "--out", &o_s,
    ]));
    ok(&dynbvh(&[
        "render",
        &p,
        "--frames",
        "2",
        "--size",
        "32x24",
        "--auto-camera",
        "--out",
        &d.join("auto").to_string_lossy(),
    ]));
    let own = image::open(o.join("frame_0000.png")).unwrap().to_rgb8();
    let auto = image::open(d.join("auto/frame_0000.png"))
        .unwrap()
        .to_rgb8();
    assert!(own != auto);
    // The same frame rendered here through the library, from the file's camera and from the
    // framed one: the command's pictures are these, and from the file's camera no primary ray
    // hits the triangle, while the framed camera sees it.
    let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(2)).unwrap();
    let bounds = animation_bounds(&scene, Some(0), src.times()).unwrap();
    let engine = src.build(0, EngineConfig::default());
    let mut shading = EngineShading::new();
    shading.refresh_all(&engine);
    let mut r = Renderer::new(Settings {
        width: 32,
        height: 24,
        smooth: true,
        shadows: false,
        heatmap: None,
    });
    let file_cam = Camera::from_node(&src.poser().world_matrices()[2], cams[0].projection);
    for (what, cam, cli, hit) in [
        ("file camera", file_cam, &own, false),
        (
            "framed camera",
            Camera::framing(&bounds, 32.0 / 24.0),
            &auto,
            true,
        ),
    ] {
        let mut img = RgbImage::new(1, 1);
        let c = r.render(
            &shading.tracer(&engine),
            &Stage::new(cam, &bounds, true),
            &mut img,
        );
        assert_eq!(c.primary, 32 * 24);
        assert_eq!(c.hits > 0, hit, "{what}: {} primary rays hit", c.hits);
        assert!(&img == cli, "{what}: the command rendered another picture");
    }
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn bench_prints_the_ray_counts_and_what_it_averaged() {
    let tube = animation("tube.glb");
    let args = [
        "render", &tube, "--frames", "3..8", "--fps", "12", "--size", "48x36", "--bench",
    ];
    for shadows in [true, false] {
        let mut a = args.to_vec();
        if shadows {
            a.push("--shadows");
        }
        let out = ok(&dynbvh(&a));
        let rows = bench_rows(&out, "amortized");
        assert_eq!(rows.len(), 5, "{out}");
        // Values not computed print as a dash: the build after the first frame, the pose and
        // update of the first (a fresh build), and the traversal work of shaded frames.
        assert!(
            rows[0].build_ms.is_some() && rows[0].pose_ms.is_none(),
            "{out}"
        );
        assert!(
            rows[1..]
                .iter()
                .all(|r| r.build_ms.is_none() && r.pose_ms.is_some())
        );
        assert!(
            rows.iter()
                .all(|r| r.work_per_px == "\u{2013}" && r.max_work == "\u{2013}"),
            "{out}"
        );
        for r in &rows {
            assert_eq!(r.primary, 48 * 36, "one primary ray per pixel: {r:?}");
            if shadows {
                // One from each lit point only: not from the sky or from surfaces turned away.
                assert!(r.shadow > 0 && r.shadow < r.primary, "{r:?}");
            } else {
                assert_eq!(r.shadow, 0, "{r:?}");
            }
        }
        let shadow_mean = rows[1..].iter().map(|r| r.shadow as f64).sum::<f64>() / 4.0;
        let summary = out
            .lines()
            .find(|l| l.starts_with("amortized: "))
            .unwrap_or_else(|| panic!("a summary line:\n{out}"));
        assert!(
            summary.contains(
                "mean of the 4 frames after the first (frame 3, a fresh build, excluded)"
            ),
            "{summary}"
        );
        assert!(
            summary.contains(&format!(
                "rays/frame: 1728 primary (one per pixel) + {shadow_mean:.0} shadow ("
            )),
            "{summary}"
        );
        assert_eq!(
            summary.contains("none without --shadows"),
            !shadows,
            "{summary}"
        );
    }
}
