//! The glTF commands end to end, through the built binary: `gen` (every kind), `info` (classes,
//! animations with durations, channels and interpolation modes), `pose --time` to `.obj` and
//! `.ply` (read back and compared with the library's own pose), and a bad file.

mod cli_util;
use cli_util::{dynbvh, ok};
use dynbvh::anim::Scene;
use dynbvh::anim::generate::Kind;
use glam::Vec3;
use std::path::{Path, PathBuf};

mod anim_util;

fn s(p: &Path) -> String {
    p.to_string_lossy().into_owned()
}

/// Generates `kind` with about `triangles` triangles into `dir`.
fn gen_file(dir: &Path, kind: Kind, triangles: usize) -> PathBuf {
    let out = dir.join(format!("{}.glb", kind.name()));
    let o = dynbvh(&[
        "gen",
        kind.name(),
        "--triangles",
        &triangles.to_string(),
        "--out",
        &s(&out),
    ]);
    ok(&o);
    out
}

/// Vertices and faces of an `.obj` written by `pose`.
fn read_obj(path: &Path) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let text = std::fs::read_to_string(path).unwrap();
    let (mut v, mut f) = (Vec::new(), Vec::new());
    for line in text.lines() {
        let mut w = line.split_whitespace();
        match w.next() {
            Some("v") => {
                let c: Vec<f32> = w.map(|x| x.parse().unwrap()).collect();
                assert_eq!(c.len(), 3, "{line}");
                v.push(Vec3::new(c[0], c[1], c[2]));
            }
            Some("f") => {
                let c: Vec<u32> = w.map(|x| x.parse().unwrap()).collect();
                assert_eq!(c.len(), 3, "{line}");
                assert!(c.iter().all(|&i| i >= 1 && i as usize <= v.len()));
                f.push([c[0] - 1, c[1] - 1, c[2] - 1]);
            }
            _ => panic!("unexpected line {line:?}"),
        }
    }
    (v, f)
}

/// Vertices and faces of a binary little-endian `.ply` written by `pose`.
fn read_ply(path: &Path) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let bytes = std::fs::read(path).unwrap();
    let end = b"end_header\n";
    let h = bytes
        .windows(end.len())
        .position(|w| w == end)
        .expect("a PLY header")
        + end.len();
    let header = std::str::from_utf8(&bytes[..h]).unwrap();
    assert!(header.starts_with("ply\nformat binary_little_endian 1.0\n"));
    let count = |el: &str| -> usize {
        header
            .lines()
            .find_map(|l| l.strip_prefix(&format!("element {el} ")))
            .expect("element count")
            .parse()
            .unwrap()
    };
    let (nv, nf) = (count("vertex"), count("face"));
    let mut body = &bytes[h..];
    let f32_at = |b: &mut &[u8]| {
        let x = f32::from_le_bytes(b[..4].try_into().unwrap());
        *b = &b[4..];
        x
    };
    let mut v = Vec::with_capacity(nv);
    for _ in 0..nv {
        v.push(Vec3::new(
            f32_at(&mut body),
            f32_at(&mut body),
            f32_at(&mut body),
        ));
    }
    let mut f = Vec::with_capacity(nf);
    for _ in 0..nf {
        assert_eq!(body[0], 3);
        let idx = |k: usize| u32::from_le_bytes(body[1 + 4 * k..5 + 4 * k].try_into().unwrap());
        let t = [idx(0), idx(1), idx(2)];
        assert!(t.iter().all(|&i| (i as usize) < nv));
        f.push(t);
        body = &body[13..];
    }
    assert!(body.is_empty(), "{} bytes after the faces", body.len());
    (v, f)
}

#[test]
fn gen_writes_every_kind_and_the_files_load() {
    let dir = cli_util::tmp_dir("cli_anim", "gen");
    for kind in Kind::ALL {
        let path = gen_file(&dir, kind, 300);
        let (scene, warnings) = Scene::load(&path).expect("the generated file loads");
        assert!(warnings.is_empty(), "{kind:?}: {warnings:?}");
        assert!(scene.triangle_count() > 0, "{kind:?}");
        assert_eq!(scene.animations.len(), 1, "{kind:?}");
    }
    let o = dynbvh(&["gen", "spiral", "--out", &s(&dir.join("x.glb"))]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("unknown kind"));
}

#[test]
fn info_lists_classes_animations_channels_and_modes() {
    let dir = cli_util::tmp_dir("cli_anim", "info");
    // The tube deforms (skin), the orbit's cubes are rigid (node animation, STEP and LINEAR).
    let tube = gen_file(&dir, Kind::Tube, 400);
    let text = ok(&dynbvh(&["info", &s(&tube)]));
    let scene = Scene::load(&tube).unwrap().0;
    assert!(
        text.contains(&format!("triangles: {}", scene.triangle_count())),
        "{text}"
    );
    let d = scene.animations[0].duration;
    assert!(
        text.contains(&format!("{d:.3} s")),
        "duration {d:.3} s missing:\n{text}"
    );
    assert!(
        text.contains("0 static, 0 rigid, 1 deforming instances"),
        "{text}"
    );
    assert!(text.contains("LINEAR"), "{text}");
    assert!(text.contains("skins: 1"), "{text}");
    let orbit = gen_file(&dir, Kind::Orbit, 400);
    let text = ok(&dynbvh(&["info", &s(&orbit)]));
    assert!(text.contains("LINEAR/STEP"), "{text}");
    assert!(text.contains(": rigid"), "{text}");
    let wave = gen_file(&dir, Kind::Wave, 400);
    let text = ok(&dynbvh(&["info", &s(&wave)]));
    assert!(text.contains("CUBICSPLINE"), "{text}");
    assert!(text.contains("weights 1"), "{text}");
    assert!(text.contains(": deforming"), "{text}");

    // A sample with all three classes and several animations.
    let Some(path) = anim_util::sample("InterpolationTest/InterpolationTest.glb") else {
        return;
    };
    let text = ok(&dynbvh(&["info", &s(&path)]));
    let scene = Scene::load(&path).unwrap().0;
    assert!(scene.animations.len() > 1);
    for (i, a) in scene.animations.iter().enumerate() {
        let line = text
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("animation {i} \"")))
            .unwrap_or_else(|| panic!("animation {i} missing:\n{text}"));
        assert!(line.contains(&format!("{:.3} s", a.duration)), "{line}");
        assert!(
            line.contains(&format!("{} channels", a.channels.len())),
            "{line}"
        );
    }
    for mode in ["STEP", "LINEAR", "CUBICSPLINE"] {
        assert!(text.contains(mode), "{mode} missing:\n{text}");
    }
    for class in [": static", "rigid"] {
        assert!(text.contains(class), "{class} missing:\n{text}");
    }
    let Some(path) = anim_util::sample("CesiumMan/CesiumMan.glb") else {
        return;
    };
    let text = ok(&dynbvh(&["info", &s(&path)]));
    assert!(text.contains("deforming"), "{text}");
    assert!(text.contains("skins: 1"), "{text}");
}

/// Poses `file` at `t` through the CLI into `out` (with `extra` arguments); returns stderr.
fn pose(file: &Path, t: f32, out: &Path, extra: &[&str]) -> String {
    let mut args = vec![
        "pose".to_string(),
        s(file),
        "--time".into(),
        t.to_string(),
        "--out".into(),
        s(out),
    ];
    args.extend(extra.iter().map(|x| x.to_string()));
    let o = dynbvh(&args);
    ok(&o);
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn max_diff(a: &[Vec3], b: &[Vec3]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (*x - *y).abs().max_element())
        .fold(0.0, f32::max)
}

/// Checks `pose --time` of `file` without `--animation` against the library's pose of its
/// first animation, in both formats, at two times.
fn check_pose(dir: &Path, file: &Path, times: [f32; 2]) {
    let (scene, _) = Scene::load(file).unwrap();
    assert!(!scene.animations.is_empty());
    let mut obj_at = Vec::new();
    for (k, &t) in times.iter().enumerate() {
        let obj = dir.join(format!("posed{k}.obj"));
        let ply = dir.join(format!("posed{k}.ply"));
        let msg = pose(file, t, &obj, &[]);
        assert!(msg.contains("animation 0"), "{msg}");
        pose(file, t, &ply, &[]);
        let want = scene.flatten_at(Some(0), t).unwrap();
        let (ov, of) = read_obj(&obj);
        let (pv, pf) = read_ply(&ply);
        assert_eq!(of.len(), scene.triangle_count(), "{}", file.display());
        assert_eq!(pf.len(), scene.triangle_count());
        assert_eq!(ov.len(), scene.vertex_count());
        assert_eq!(pv.len(), scene.vertex_count());
        assert_eq!(of, want.indices);
        assert_eq!(pf, want.indices);
        let scale = want
            .positions
            .iter()
            .map(|p| p.abs().max_element())
            .fold(1.0, f32::max);
        let d = max_diff(&ov, &want.positions);
        assert!(d <= 1e-5 * scale, "{}: obj off by {d}", file.display());
        // The PLY holds the very floats.
        assert_eq!(pv, want.positions);
        obj_at.push(ov);
    }
    assert!(
        max_diff(&obj_at[0], &obj_at[1]) > 1e-3,
        "{}: the poses at {times:?} do not differ",
        file.display()
    );
}

#[test]
fn pose_uses_the_first_animation_and_matches_the_library() {
    let dir = cli_util::tmp_dir("cli_anim", "pose");
    let tube = gen_file(&dir, Kind::Tube, 400);
    check_pose(&dir, &tube, [0.3, 1.1]);
    let wave = gen_file(&dir, Kind::Wave, 400);
    check_pose(&dir, &wave, [0.25, 0.9]);
    // --rest asks for the rest pose; a file without animations gives it with a note.
    let rest = dir.join("rest.obj");
    pose(&tube, 1.1, &rest, &["--rest"]);
    let scene = Scene::load(&tube).unwrap().0;
    let (v, _) = read_obj(&rest);
    assert!(max_diff(&v, &scene.flatten_rest().positions) <= 1e-5 * 10.0);
    if let Some(path) = anim_util::sample("CesiumMan/CesiumMan.glb") {
        check_pose(&dir, &path, [0.5, 1.5]);
    }
}

#[test]
fn pose_without_animations_writes_the_rest_pose() {
    let Some(path) = anim_util::sample("TransmissionTest/TransmissionTest.glb") else {
        return;
    };
    let dir = cli_util::tmp_dir("cli_anim", "rest");
    let out = dir.join("rest.ply");
    let msg = pose(&path, 2.0, &out, &[]);
    assert!(msg.contains("no animations"), "{msg}");
    let scene = Scene::load(&path).unwrap().0;
    let (v, f) = read_ply(&out);
    assert_eq!(f.len(), scene.triangle_count());
    assert_eq!(v, scene.flatten_rest().positions);
}

#[test]
fn bad_files_fail_with_an_error_naming_the_file() {
    let dir = cli_util::tmp_dir("cli_anim", "bad");
    let bad = dir.join("broken.glb");
    std::fs::write(&bad, b"glTF\x02\x00\x00\x00garbage").unwrap();
    let missing = dir.join("missing.gltf");
    for file in [&bad, &missing] {
        for cmd in [
            vec!["info".to_string(), s(file)],
            vec![
                "pose".to_string(),
                s(file),
                "--time".into(),
                "1".into(),
                "--out".into(),
                s(&dir.join("x.obj")),
            ],
        ] {
            let o = dynbvh(&cmd);
            assert!(!o.status.success(), "{cmd:?} succeeded");
            let err = String::from_utf8_lossy(&o.stderr);
            let name = file.file_name().unwrap().to_string_lossy();
            assert!(
                err.contains(&*name),
                "{cmd:?}: error does not name the file: {err}"
            );
        }
    }
    let tube = gen_file(&dir, Kind::Tube, 100);
    let o = dynbvh(&[
        "pose",
        &s(&tube),
        "--animation",
        "nope",
        "--out",
        &s(&dir.join("x.obj")),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("nope") && err.contains("tube.glb"), "{err}");
    // The error lists the animations there are.
    assert!(err.contains("it has: 0"), "{err}");
    // `-a` is `--animation` here as in render and bench.
    let o = dynbvh(&[
        "pose",
        &s(&tube),
        "-a",
        "0",
        "--out",
        &s(&dir.join("a.obj")),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // gen writes GLB only, and says so for another extension.
    let o = dynbvh(&["gen", "tube", "--out", &s(&dir.join("g.obj"))]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains(".glb"));
    assert!(!dir.join("g.obj").exists());
}
