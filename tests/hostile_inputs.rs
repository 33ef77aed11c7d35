//! Hostile files and arguments through the binary, as the fuzzing campaign of issue 16 found
//! them: every run ends with a clean error (non-zero exit, no panic, a message naming the
//! argument or object) or a bounded result. A run still going after `GUARD` is killed and
//! fails the test: a hang guard, far above the few seconds these runs take.

mod anim_util;
mod cli_util;

use cli_util::tmp_dir;
use serde_json::json;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Kill a run after this long.
const GUARD: Duration = Duration::from_secs(60);

/// What a run printed and how it ended.
struct Run {
    success: bool,
    stdout: String,
    stderr: String,
}

/// Runs `dynbvh args`, killing it after [`GUARD`].
fn run<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> Run {
    let mut child = Command::new(env!("CARGO_BIN_EXE_dynbvh"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run dynbvh");
    let start = Instant::now();
    let line: Vec<String> = args
        .iter()
        .map(|a| a.as_ref().to_string_lossy().into_owned())
        .collect();
    loop {
        if child.try_wait().expect("wait").is_some() {
            break;
        }
        if start.elapsed() > GUARD {
            let _ = child.kill();
            let _ = child.wait();
            panic!("dynbvh {} still running after {GUARD:?}", line.join(" "));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let o = child.wait_with_output().expect("output");
    let r = Run {
        success: o.status.success(),
        stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
    };
    assert!(
        !r.stderr.contains("panicked") && o.status.code().is_some(),
        "dynbvh {} crashed: {}",
        line.join(" "),
        r.stderr
    );
    r
}

/// A clean error whose message contains every one of `names`.
#[track_caller]
fn refused<S: AsRef<std::ffi::OsStr>>(args: &[S], names: &[&str]) -> String {
    let r = run(args);
    let line: Vec<_> = args.iter().map(|a| a.as_ref().to_string_lossy()).collect();
    assert!(
        !r.success,
        "dynbvh {} succeeded:\n{}",
        line.join(" "),
        r.stdout
    );
    for n in names {
        assert!(
            r.stderr.contains(n),
            "dynbvh {}: the error does not name {n:?}: {}",
            line.join(" "),
            r.stderr
        );
    }
    r.stderr
}

/// A successful run; returns its stdout and stderr.
#[track_caller]
fn bounded<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> (String, String) {
    let r = run(args);
    let line: Vec<_> = args.iter().map(|a| a.as_ref().to_string_lossy()).collect();
    assert!(r.success, "dynbvh {} failed: {}", line.join(" "), r.stderr);
    (r.stdout, r.stderr)
}

fn s(p: &Path) -> String {
    p.to_string_lossy().into_owned()
}

/// Little-endian bytes of floats.
fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// A glTF document of one triangle on one node, translated by a LINEAR channel through the
/// key `times` (the node moves up by 1 per key), all data in one data URI.
fn clip(times: &[f32]) -> serde_json::Value {
    clip_parts(times).0
}

/// [`clip`] and the bytes of its buffer.
fn clip_parts(times: &[f32]) -> (serde_json::Value, Vec<u8>) {
    let positions = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let keys: Vec<f32> = (0..times.len())
        .flat_map(|k| [0.0, k as f32, 0.0])
        .collect();
    let mut data = f32_bytes(&positions);
    let times_at = data.len();
    data.extend(f32_bytes(times));
    let keys_at = data.len();
    data.extend(f32_bytes(&keys));
    let n = times.len();
    let tmax = times.iter().copied().fold(f32::MIN, f32::max);
    let tmin = times.iter().copied().fold(f32::MAX, f32::min);
    let doc = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "buffers": [{"byteLength": data.len(), "uri": anim_util::data_uri(&data)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": times_at, "byteLength": 4 * n},
            {"buffer": 0, "byteOffset": keys_at, "byteLength": 12 * n}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
             "min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 0.0]},
            {"bufferView": 1, "componentType": 5126, "count": n, "type": "SCALAR",
             "min": [tmin], "max": [tmax]},
            {"bufferView": 2, "componentType": 5126, "count": n, "type": "VEC3"}
        ],
        "animations": [{
            "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}],
            "samplers": [{"input": 1, "output": 2, "interpolation": "LINEAR"}]
        }]
    });
    (doc, data)
}

/// Writes `doc` as `name` in `dir`.
fn write(dir: &Path, name: &str, doc: &serde_json::Value) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, serde_json::to_vec(doc).unwrap()).unwrap();
    p
}

/// A small animated file of a few hundred triangles, for the argument cases.
fn small_scene(dir: &Path) -> String {
    let p = dir.join("wave.glb");
    bounded(&["gen", "wave", "--triangles", "200", "--out", &s(&p)]);
    s(&p)
}

/// The bench's quick form: no oracle, builders or top-level comparison, few rays.
const QUICK: [&str; 3] = ["--no-oracle", "--no-builders", "--no-tlas-compare"];

fn bench(file: &str, extra: &[&str]) -> Vec<String> {
    let mut v: Vec<String> = vec![
        "bench".into(),
        file.into(),
        "--policy".into(),
        "refit".into(),
    ];
    v.extend(QUICK.iter().map(|s| (*s).to_string()));
    v.extend(extra.iter().map(|s| (*s).to_string()));
    v
}

#[test]
fn clips_with_key_times_up_to_3e38_render_and_bench_bounded() {
    let d = tmp_dir("hostile", "long_clip");
    let long = write(&d, "long.gltf", &clip(&[0.0, 1.0, 1e7, 3e38]));
    let corrupt = write(&d, "corrupt.gltf", &clip(&[0.0, 0.5, 1e30]));
    for f in [&long, &corrupt] {
        let out = d.join("frames");
        let (_, err) = bounded(&["render", &s(f), "--size", "16x12", "--out", &s(&out)]);
        assert!(err.contains("--max-frames"), "no note on the cut: {err}");
        let pngs = std::fs::read_dir(&out).unwrap().count();
        assert_eq!(pngs, 300, "the frames a long clip is cut to");
        std::fs::remove_dir_all(&out).unwrap();
        bounded(&bench(&s(f), &["--rays", "64", "--frames", "20"]));
        refused(
            &bench(&s(f), &["--rays", "64", "--fps", "30"]),
            &["--fps", "--max-frames"],
        );
        refused(
            &[
                "render",
                &s(f),
                "--fps",
                "30",
                "--frames",
                "0..2",
                "--bench",
            ],
            &["--fps 30", "timeline", "--frames N"],
        );
    }
}

#[test]
fn clips_of_1e7_and_1e9_seconds_render_a_bounded_number_of_frames_by_default() {
    let d = tmp_dir("hostile", "long_defaults");
    for (name, end) in [("1e7.gltf", 1e7f32), ("1e9.gltf", 1e9)] {
        let f = write(&d, name, &clip(&[0.0, end]));
        let out = d.join("frames");
        let (_, err) = bounded(&["render", &s(&f), "--size", "16x12", "--out", &s(&out)]);
        assert!(err.contains("rendering 300 frames"), "{name}: {err}");
        assert_eq!(std::fs::read_dir(&out).unwrap().count(), 300, "{name}");
        std::fs::remove_dir_all(&out).unwrap();
    }
}

#[test]
fn hostile_frame_counts_and_rates_are_refused() {
    let d = tmp_dir("hostile", "frames");
    let f = small_scene(&d);
    let out = s(&d.join("r"));
    refused(
        &bench(&f, &["--fps", "1e30"]),
        &["--fps", "e30 frames", "--max-frames"],
    );
    refused(
        &[
            "render", &f, "--fps", "1e30", "--frames", "0..2", "--out", &out,
        ],
        &["bound"],
    );
    for cmd in ["bench", "render"] {
        let mut a = vec![cmd, &f, "--frames", "18446744073709551615", "--out", &out];
        if cmd == "bench" {
            a.push("--no-oracle");
        }
        refused(&a, &["--frames", "18446744073709551615", "--max-frames"]);
    }
    refused(
        &["render", &f, "--frames", "1000000000", "--out", &out],
        &["--frames", "1000000000", "1000", "--max-frames"],
    );
    refused(
        &bench(&f, &["--frames", "1000000000"]),
        &["--frames", "1000000000", "--max-frames"],
    );
    refused(
        &["render", &f, "--frames", "0..1000000000", "--bench"],
        &["--frames", "--max-frames"],
    );
    refused(&bench(&f, &["--fps", "0"]), &["--fps", "positive"]);
    refused(&bench(&f, &["--fps", "inf"]), &["--fps"]);
    // Raising the bound lets a bigger request through (to the animation's own frames).
    refused(
        &[
            "render",
            &f,
            "--frames",
            "0..5000",
            "--max-frames",
            "5000",
            "--bench",
        ],
        &["--frames 0..5000", "the animation has frames"],
    );
}

#[test]
fn hostile_sizes_repeats_and_threads_are_refused_or_capped() {
    let d = tmp_dir("hostile", "sizes");
    let f = small_scene(&d);
    refused(
        &bench(&f, &["--repeats", "1000000000"]),
        &["--repeats", "1000000000", "1..=1000"],
    );
    refused(&bench(&f, &["--repeats", "0"]), &["--repeats"]);
    refused(
        &bench(&f, &["--size", "20000x20000"]),
        &["--size", "20000", "16384"],
    );
    refused(
        &bench(&f, &["--size", "100000x100000"]),
        &["--size", "100000"],
    );
    refused(
        &bench(&f, &["--size", "16384x16384"]),
        &["--size", "16384x16384", "--max-memory"],
    );
    refused(
        &bench(&f, &["--rays", "10000000000"]),
        &["--rays", "10000000000"],
    );
    refused(&bench(&f, &["--size", "32x"]), &["--size", "32x", "height"]);
    refused(
        &["render", &f, "--size", "32x", "--bench"],
        &["--size", "32x"],
    );
    refused(
        &["render", &f, "--size", "0x10", "--bench"],
        &["--size", "width"],
    );
    refused(
        &["render", &f, "--size", "16384x16384", "--bench"],
        &["--size", "--max-memory"],
    );
    refused(
        &["render", &f, "--threads", "0", "--bench"],
        &["--threads", "0"],
    );
    refused(&bench(&f, &["--threads", "0"]), &["--threads"]);
    let (_, err) = bounded(&[
        "render",
        &f,
        "--threads",
        "100000",
        "--frames",
        "2",
        "--size",
        "16x16",
        "--bench",
    ]);
    assert!(
        err.contains("--threads 100000") && err.contains("cores"),
        "{err}"
    );
    let (_, err) = bounded(&bench(
        &f,
        &["--threads", "1000", "--frames", "2", "--rays", "64"],
    ));
    assert!(err.contains("--threads 1000"), "{err}");
    bounded(&bench(
        &f,
        &["--frames", "2", "--rays", "64", "--repeats", "1"],
    ));
}

#[test]
fn hostile_triangle_and_joint_counts_are_refused() {
    let d = tmp_dir("hostile", "triangles");
    let out = s(&d.join("x.glb"));
    refused(
        &["gen", "tube", "--triangles", "1000000000000", "--out", &out],
        &["--triangles", "1000000000000"],
    );
    refused(
        &["gen", "orbit", "--triangles", "100000000", "--out", &out],
        &["--triangles 100000000", "--max-memory"],
    );
    refused(
        &["gen", "tube", "--four-weights", "1000000", "--out", &out],
        &["--four-weights", "1000000", "65536"],
    );
    refused(
        &["gen", "tube", "--four-weights", "3", "--out", &out],
        &["--four-weights"],
    );
    refused(
        &["build-bench", "--synthetic", "1000000000000"],
        &["--synthetic", "1000000000000"],
    );
    refused(
        &["build-bench", "--synthetic", "100000000"],
        &["--synthetic 100000000", "--max-memory"],
    );
    assert!(!Path::new(&out).exists());
}

/// `clip` with its buffer in a file named by `uri` (relative to the glTF file) instead of a
/// data URI.
fn clip_with_buffer_uri(uri: &str, byte_length: usize) -> serde_json::Value {
    let mut doc = clip(&[0.0, 1.0]);
    doc["buffers"][0] = json!({"byteLength": byte_length, "uri": uri});
    doc
}

#[test]
fn files_that_are_not_regular_are_refused_before_reading() {
    let d = tmp_dir("hostile", "not_regular");
    refused(&["info", &s(&d)], &[&s(&d), "directory"]);
    let fifo = d.join("pipe.glb");
    let made = Command::new("mkfifo").arg(&fifo).status();
    if made.is_ok_and(|st| st.success()) {
        refused(&["info", &s(&fifo)], &["pipe.glb", "not a regular file"]);
        refused(
            &["build-bench", &s(&fifo)],
            &["pipe.glb", "not a regular file"],
        );
    }
    if Path::new("/dev/zero").exists() {
        // A buffer on a device is refused even where outside files are allowed.
        let f = write(&d, "zero.gltf", &clip_with_buffer_uri("/dev/zero", 96));
        refused(&["info", &s(&f)], &["zero.gltf", "buffer 0", "/dev/zero"]);
        refused(
            &["--allow-outside-files", "info", &s(&f)],
            &["zero.gltf", "buffer 0", "not a regular file"],
        );
    }
}

#[test]
fn buffers_outside_the_folder_are_refused_unless_allowed() {
    let d = tmp_dir("hostile", "outside");
    let inner = d.join("inner");
    std::fs::create_dir_all(inner.join("sub")).unwrap();
    let (_, data) = clip_parts(&[0.0, 1.0]);
    // The buffer with trailing bytes beyond its byteLength, which are not read.
    let mut padded = data.clone();
    padded.extend([0xAB; 1000]);
    std::fs::write(d.join("outside.bin"), &padded).unwrap();
    std::fs::write(inner.join("inside.bin"), &padded).unwrap();
    let up = write(
        &inner,
        "up.gltf",
        &clip_with_buffer_uri("../outside.bin", data.len()),
    );
    refused(
        &["info", &s(&up)],
        &[
            "up.gltf",
            "buffer 0",
            "../outside.bin",
            "--allow-outside-files",
        ],
    );
    bounded(&["info", &s(&up), "--allow-outside-files"]);
    let abs = s(&d.join("outside.bin"));
    let absolute = write(&inner, "abs.gltf", &clip_with_buffer_uri(&abs, data.len()));
    refused(
        &["info", &s(&absolute)],
        &[
            "abs.gltf",
            "buffer 0",
            "inside the file's folder",
            "absolute",
        ],
    );
    let ok = write(
        &inner,
        "ok.gltf",
        &clip_with_buffer_uri("./sub/../inside.bin", data.len()),
    );
    bounded(&["info", &s(&ok)]);
}

#[test]
fn broken_containers_and_deep_json_are_clean_errors() {
    let d = tmp_dir("hostile", "containers");
    // A GLB whose JSON chunk claims more bytes than the file has.
    let json = br#"{"asset":{"version":"2.0"}}  "#;
    let mut glb = Vec::new();
    glb.extend(b"glTF");
    glb.extend(2u32.to_le_bytes());
    glb.extend((12 + 8 + json.len() as u32).to_le_bytes());
    glb.extend(0x7FFF_FFF0u32.to_le_bytes());
    glb.extend(0x4E4F_534Au32.to_le_bytes());
    glb.extend(json);
    let p = d.join("chunk.glb");
    std::fs::write(&p, &glb).unwrap();
    refused(&["info", &s(&p)], &["chunk.glb", "GLB container", "chunk"]);
    // JSON nested thousands deep: where the document is parsed, an error; in `extras`,
    // which are kept as raw text, a file that loads.
    let nest = |key: &str| {
        format!(
            r#"{{"asset":{{"version":"2.0"}},"{key}":{}{}}}"#,
            "[".repeat(5000),
            "]".repeat(5000)
        )
    };
    let p = d.join("deep.gltf");
    std::fs::write(&p, nest("nodes")).unwrap();
    refused(&["info", &s(&p)], &["deep.gltf", "JSON"]);
    std::fs::write(&p, nest("extras")).unwrap();
    bounded(&["info", &s(&p)]);
}

/// A file whose `nodes` nodes each place one mesh of `count` vertices read from an accessor
/// without a buffer view (all zeros, as the specification allows): `count / 3` degenerate
/// triangles per node, from a few hundred bytes of JSON.
fn zeros_placed(count: usize, nodes: usize) -> serde_json::Value {
    let node_list: Vec<_> = (0..nodes).map(|_| json!({"mesh": 0})).collect();
    let roots: Vec<usize> = (0..nodes).collect();
    json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": roots}],
        "nodes": node_list,
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "accessors": [{"componentType": 5126, "count": count, "type": "VEC3",
                       "min": [0.0, 0.0, 0.0], "max": [0.0, 0.0, 0.0]}]
    })
}

#[test]
fn accessors_without_data_and_instanced_huge_meshes_are_bounded() {
    let d = tmp_dir("hostile", "zeros");
    let obj = s(&d.join("p.obj"));
    // 5.6M vertices (the loader's bound on components without a buffer view), placed 100
    // times: the loader reads the accessor once, the flattening would make 559M vertices.
    let many = write(&d, "many.gltf", &zeros_placed(5_592_405, 100));
    refused(
        &["pose", &s(&many), "--out", &obj],
        &[
            "many.gltf",
            "pose",
            "100 mesh instances",
            "mesh 0",
            "placed by 100 node(s)",
            "--max-memory",
        ],
    );
    refused(
        &bench(&s(&many), &["--rays", "64"]),
        &["many.gltf", "bench", "--max-memory"],
    );
    refused(
        &["render", &s(&many), "--bench", "--frames", "1"],
        &["many.gltf", "render", "--max-memory"],
    );
    refused(
        &["build-bench", &s(&many)],
        &["many.gltf", "build-bench", "--max-memory"],
    );
    let (out, _) = bounded(&["info", &s(&many)]);
    assert!(out.contains("instances: 100"), "{out}");
    // Once: fine to pose (a few hundred MB), refused by the bench's own estimate.
    let one = write(&d, "one.gltf", &zeros_placed(5_592_405, 1));
    refused(
        &bench(&s(&one), &["--rays", "64"]),
        &["one.gltf", "1864135 triangles", "--max-memory"],
    );
    refused(
        &["pose", &s(&one), "--out", &obj, "--max-memory", "100M"],
        &["one.gltf", "100.0 MiB", "--max-memory"],
    );
    // Beyond the loader's bound on data without a buffer view: an error naming the accessor.
    let huge = write(&d, "huge.gltf", &zeros_placed(16_777_216, 1));
    refused(
        &["info", &s(&huge)],
        &["huge.gltf", "accessor 0", "without a buffer view"],
    );
    refused(
        &bench(&s(&huge), &["--rays", "64"]),
        &["huge.gltf", "accessor 0", "without a buffer view"],
    );
}

#[test]
fn millions_of_zero_indices_end_quickly() {
    // 16,777,215 indices without a buffer view (all zero): 5.6M triangles that are one point,
    // from a few hundred bytes.
    let d = tmp_dir("hostile", "zero_indices");
    let (_, data) = clip_parts(&[0.0, 1.0]);
    let mut doc = clip(&[0.0, 1.0]);
    doc["meshes"][0]["primitives"][0]["indices"] = json!(3);
    doc["accessors"]
        .as_array_mut()
        .unwrap()
        .push(json!({"componentType": 5125, "count": 16_777_215, "type": "SCALAR"}));
    assert!(!data.is_empty());
    let f = write(&d, "zidx.gltf", &doc);
    let f = s(&f);
    let start = Instant::now();
    refused(
        &["build-bench", &f],
        &["zidx.gltf", "5592405 triangles", "degenerate"],
    );
    refused(
        &bench(&f, &["--rays", "64"]),
        &["zidx.gltf", "5592405 triangles", "--max-memory"],
    );
    bounded(&["render", &f, "--bench", "--frames", "1", "--size", "64x48"]);
    bounded(&["info", &f]);
    assert!(
        start.elapsed() < Duration::from_secs(30),
        "{:?} for the four runs",
        start.elapsed()
    );
}

#[test]
fn flattening_past_32_bit_indices_is_refused_whatever_the_memory_bound() {
    let d = tmp_dir("hostile", "index_bound");
    let many = write(&d, "many.gltf", &zeros_placed(5_592_405, 1001));
    refused(
        &[
            "pose",
            &s(&many),
            "--out",
            &s(&d.join("p.obj")),
            "--max-memory",
            "1000T",
        ],
        &["many.gltf", "2^32"],
    );
}

#[test]
fn negative_times_parse_and_parse_errors_name_the_option() {
    let d = tmp_dir("hostile", "parse");
    let f = small_scene(&d);
    let obj = s(&d.join("p.obj"));
    bounded(&["pose", &f, "--time", "-0.5", "--out", &obj]);
    bounded(&["pose", &f, "--time=-0.5", "--out", &obj]);
    refused(
        &["pose", &f, "--time", "inf", "--out", &obj],
        &["--time", "inf", "finite"],
    );
    refused(
        &["pose", &f, "--time", "x", "--out", &obj],
        &["--time", "\"x\""],
    );
    refused(&["render", &f, "--fps", "-3", "--bench"], &["--fps", "-3"]);
    refused(&["bench", &f, "--frames", "-3"], &["--frames", "-3"]);
    refused(
        &["gen", "tube", "--triangles", "1e12", "--out", &obj],
        &["--triangles", "1e12"],
    );
    refused(
        &["bench", &f, "--max-memory", "4Q"],
        &["--max-memory", "4Q"],
    );
    // `scene: 0` with an empty `scenes` list.
    let mut doc = clip(&[0.0, 1.0]);
    doc["scenes"] = json!([]);
    let p = write(&d, "no_scenes.gltf", &doc);
    let err = refused(&["info", &s(&p)], &["no_scenes.gltf", "scene", "empty"]);
    assert!(!err.contains("below 0"), "{err}");
}

#[test]
fn overflowing_transforms_are_reported_naming_node_and_mesh() {
    let d = tmp_dir("hostile", "overflow");
    // Two nested nodes scaled by 1e30 each: finite transforms whose product is not.
    let mut doc = clip(&[0.0, 1.0]);
    doc["nodes"] = json!([
        {"name": "outer", "scale": [1e30, 1e30, 1e30], "children": [1]},
        {"name": "inner", "scale": [1e30, 1e30, 1e30], "mesh": 0}
    ]);
    doc["animations"][0]["channels"][0]["target"]["node"] = json!(1);
    let p = write(&d, "overflow.gltf", &doc);
    let (_, err) = bounded(&["pose", &s(&p), "--out", &s(&d.join("p.obj"))]);
    assert!(
        err.contains("node 1 \"inner\"") && err.contains("mesh 0") && err.contains("not finite"),
        "{err}"
    );
}

#[test]
fn a_far_vertex_does_not_collapse_the_tree() {
    use dynbvh::bvh::MeshBvh;
    use dynbvh::geom::TriMesh;
    use glam::Vec3;
    // A 100x100 grid (20k triangles) and the same with one vertex at 1e30: the far vertex's
    // triangle must not make the rest of the tree worse. Counted work per ray, not time.
    let n = 100u32;
    let mut positions = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            positions.push(Vec3::new(i as f32, j as f32, 0.0));
        }
    }
    let mut indices = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i;
            indices.push([a, a + 1, a + n + 1]);
            indices.push([a + 1, a + n + 2, a + n + 1]);
        }
    }
    let grid = TriMesh {
        positions: positions.clone(),
        indices: indices.clone(),
    };
    let far_at = |p: Vec3| {
        let mut far = grid.clone();
        far.positions[(n / 2 * (n + 1) + n / 2) as usize] = p;
        far
    };
    let work = |m: &TriMesh| {
        let bvh = MeshBvh::build(m, &dynbvh::bvh::BuildParams::BINNED);
        let mut stats = dynbvh::bvh::TraversalStats::default();
        for k in 0..400u32 {
            let (x, y) = ((k % 20) as f32 * 5.0 + 0.3, (k / 20) as f32 * 5.0 + 0.7);
            let ray = dynbvh::geom::Ray::new(Vec3::new(x, y, 5.0), Vec3::new(0.0, 0.0, -1.0));
            assert!(bvh.closest_hit_counted(&ray, &mut stats).is_some());
        }
        stats.nodes + stats.prims
    };
    let plain = work(&grid);
    for p in [
        Vec3::splat(1e30),
        Vec3::new(1e30, 0.0, 0.0),
        Vec3::new(50.0, 50.0, 1e30),
        Vec3::new(1e25, 1e25, 0.0),
        Vec3::new(-3e38, 3e38, 3e38),
    ] {
        let with_far = work(&far_at(p));
        assert!(
            with_far <= 3 * plain,
            "work with one vertex at {p}: {with_far}, without it {plain}"
        );
    }
}

/// `glb` with vertex `k` of mesh 0's positions moved to `p` (its accessor's bounds widened).
fn with_vertex_at(glb: &[u8], k: usize, p: [f32; 3]) -> Vec<u8> {
    let u32_at = |o: usize| u32::from_le_bytes(glb[o..o + 4].try_into().unwrap()) as usize;
    let json_len = u32_at(12);
    let mut doc: serde_json::Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    let mut bin = glb[20 + json_len + 8..].to_vec();
    let acc = doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]
        .as_u64()
        .unwrap() as usize;
    let view = doc["accessors"][acc]["bufferView"].as_u64().unwrap() as usize;
    let v = &doc["bufferViews"][view];
    let stride = v["byteStride"].as_u64().unwrap_or(12) as usize;
    let at = v["byteOffset"].as_u64().unwrap_or(0) as usize
        + doc["accessors"][acc]["byteOffset"].as_u64().unwrap_or(0) as usize
        + k * stride;
    for (a, x) in p.iter().enumerate() {
        bin[at + 4 * a..at + 4 * a + 4].copy_from_slice(&x.to_le_bytes());
        let lo = doc["accessors"][acc]["min"][a]
            .as_f64()
            .unwrap()
            .min(f64::from(*x));
        let hi = doc["accessors"][acc]["max"][a]
            .as_f64()
            .unwrap()
            .max(f64::from(*x));
        doc["accessors"][acc]["min"][a] = json!(lo);
        doc["accessors"][acc]["max"][a] = json!(hi);
    }
    let mut json = serde_json::to_vec(&doc).unwrap();
    json.resize(json.len().next_multiple_of(4), b' ');
    let mut out = Vec::new();
    out.extend(b"glTF");
    out.extend(2u32.to_le_bytes());
    out.extend(((12 + 8 + json.len() + 8 + bin.len()) as u32).to_le_bytes());
    out.extend((json.len() as u32).to_le_bytes());
    out.extend(0x4E4F_534Au32.to_le_bytes());
    out.extend(json);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(0x004E_4942u32.to_le_bytes());
    out.extend(bin);
    out
}

/// Mean counted work (nodes visited plus triangles tested) per ray of each policy's frames,
/// from `bench --json`.
fn bench_work(file: &str, traversal: &str) -> Vec<(String, f64)> {
    let prices = concat!(env!("CARGO_MANIFEST_DIR"), "/docs/prices.json");
    let args = [
        "bench",
        file,
        "-p",
        "refit",
        "-p",
        "rebuild",
        "--no-oracle",
        "--no-builders",
        "--no-tlas-compare",
        "--frames",
        "6",
        "--rays",
        "4096",
        "--repeats",
        "1",
        "--traversal",
        traversal,
        "--prices",
        prices,
        "--json",
    ];
    let (out, _) = bounded(&args);
    let report: serde_json::Value = serde_json::from_str(&out).unwrap();
    let mut sums: Vec<(String, f64, f64)> = Vec::new();
    for row in report["per_frame"].as_array().unwrap() {
        let policy = row["policy"].as_str().unwrap().to_string();
        let work = row["nodes_per_ray"].as_f64().unwrap() + row["tris_per_ray"].as_f64().unwrap();
        match sums.iter_mut().find(|s| s.0 == policy) {
            Some(s) => {
                s.1 += work;
                s.2 += 1.0;
            }
            None => sums.push((policy, work, 1.0)),
        }
    }
    sums.into_iter().map(|(p, w, n)| (p, w / n)).collect()
}

#[test]
fn a_far_vertex_costs_the_bench_and_render_little() {
    // A 44k-triangle morphing grid (150 x 150 vertices), and the same with its middle vertex
    // at 1e30: through `bench` (both traversals, refitted and rebuilt trees, the engine's two
    // levels) the rays' counted work stays within 3x, and `render` still shows the grid.
    let d = tmp_dir("hostile", "far_vertex");
    let plain = d.join("wave.glb");
    bounded(&["gen", "wave", "--triangles", "44000", "--out", &s(&plain)]);
    let glb = std::fs::read(&plain).unwrap();
    let far = d.join("far.glb");
    std::fs::write(&far, with_vertex_at(&glb, 75 * 150 + 75, [1e30; 3])).unwrap();
    for traversal in ["wide", "binary"] {
        let base = bench_work(&s(&plain), traversal);
        let with_far = bench_work(&s(&far), traversal);
        assert_eq!(base.len(), 2);
        for ((p, w), (q, wf)) in base.iter().zip(&with_far) {
            assert_eq!(p, q);
            assert!(
                *wf <= 3.0 * w,
                "{traversal} {p}: {wf:.1} nodes+triangles per ray with the far vertex, {w:.1} without"
            );
        }
    }
    let pixels = |f: &Path, name: &str| {
        let out = d.join(name);
        let (said, _) = bounded(&[
            "render",
            &s(f),
            "--frames",
            "1",
            "--size",
            "64x48",
            "--out",
            &s(&out),
        ]);
        let img = image::open(out.join("frame_0000.png")).unwrap().to_rgb8();
        let n = img
            .pixels()
            .filter(|p| i32::from(p[0]) > i32::from(p[2]) + 40)
            .count();
        (n, said)
    };
    let (n_plain, _) = pixels(&plain, "plain");
    let (n_far, note) = pixels(&far, "far");
    assert!(n_plain > 64 * 48 / 10, "{n_plain}");
    assert!(
        n_far.abs_diff(n_plain) * 10 <= n_plain,
        "the grid covers {n_far} pixels with the far vertex, {n_plain} without"
    );
    assert!(note.contains("far outside the rest"), "{note}");
}
