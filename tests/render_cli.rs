//! The `render` command end to end: numbered PNGs and a GIF, frame ranges that join up (each
//! starts with a fresh build, the camera does not depend on the range), errors for ranges
//! beyond the animation, and the file's own camera.

use dynbvh::anim::Scene;
use dynbvh::render::{Camera, Projection, gltf_cameras};
use glam::Vec3;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn tmp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("dynbvh_render_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn dynbvh(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dynbvh"))
        .args(args)
        .output()
        .expect("run dynbvh")
}

fn animation(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("animations")
        .join(name)
        .to_string_lossy()
        .into_owned()
}

fn ok(o: &Output) -> String {
    assert!(
        o.status.success(),
        "dynbvh failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

#[test]
fn split_ranges_join_up_and_gif_is_written() {
    let tube = animation("tube.glb");
    let (a, b) = (tmp_dir("range_a"), tmp_dir("range_b"));
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
    let gif = std::fs::read(a.join("frame_0000-0004.gif")).unwrap();
    assert!(gif.starts_with(b"GIF89a"));
    let _ = std::fs::remove_dir_all(&a);
    let _ = std::fs::remove_dir_all(&b);
}

#[test]
fn heat_map_comparison_writes_side_by_side_frames() {
    let d = tmp_dir("compare");
    let d_s = d.to_string_lossy().into_owned();
    let out = ok(&dynbvh(&[
        "render",
        &animation("swap.glb"),
        "--frames",
        "3",
        "--size",
        "40x30",
        "--heatmap",
        "--compare",
        "refit,rebuild",
        "--out",
        &d_s,
    ]));
    assert!(out.contains("refit:") && out.contains("rebuild:"), "{out}");
    let img = image::open(d.join("compare_0002.png")).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (2 * 40 + 4, 30));
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

/// Standard base64 with padding.
fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in bytes.chunks(3) {
        let n = (u32::from(c[0]) << 16)
            | (u32::from(*c.get(1).unwrap_or(&0)) << 8)
            | u32::from(*c.get(2).unwrap_or(&0));
        for k in 0..4 {
            if k <= c.len() {
                s.push(char::from(A[(n >> (18 - 6 * k) & 63) as usize]));
            } else {
                s.push('=');
            }
        }
    }
    s
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
        base64(&buf)
    );
    let p = dir.join("camera.gltf");
    std::fs::write(&p, json).unwrap();
    p
}

#[test]
fn the_files_camera_is_found_and_used() {
    let d = tmp_dir("camera");
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
    let _ = std::fs::remove_dir_all(&d);
}
