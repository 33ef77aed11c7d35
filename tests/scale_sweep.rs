//! The same mesh at scales from 1e-15 to 1e15, rendered through `dynbvh render` as a user runs
//! it: the object must cover the same share of the picture, lit the same, at every scale,
//! whether the scale is in the vertices themselves (world coordinates of 1e15: the watertight
//! test's scaled distance overflows f32 there; at 1e-15 it underflows) or in the node's transform.

mod anim_util;
mod cli_util;

use cli_util::{dynbvh, ok, tmp_dir};
use dynbvh::geom::shapes;
use serde_json::json;
use std::path::Path;

const SCALES: [f32; 7] = [1e-15, 1e-10, 1e-5, 1.0, 1e5, 1e10, 1e15];

/// A glTF file of a sphere with a dent (so that shading shows its shape), of radius `scale`
/// in its vertices (`in_node` false) or of radius 1 under a node scaled by `scale`, with a
/// short rigid animation.
fn sphere_file(dir: &Path, scale: f32, in_node: bool) -> String {
    let m = shapes::icosphere(3);
    let k = if in_node { 1.0 } else { scale };
    let positions: Vec<f32> = m
        .positions
        .iter()
        .flat_map(|p| {
            let q = if p.z > 0.6 { *p * 0.8 } else { *p };
            (q * k).to_array()
        })
        .collect();
    let (lo, hi) =
        positions
            .chunks(3)
            .fold(([f32::MAX; 3], [f32::MIN; 3]), |(mut lo, mut hi), p| {
                for a in 0..3 {
                    lo[a] = lo[a].min(p[a]);
                    hi[a] = hi[a].max(p[a]);
                }
                (lo, hi)
            });
    let indices: Vec<u32> = m.indices.iter().flatten().copied().collect();
    let times = [0.0f32, 1.0];
    let node_scale = if in_node { scale } else { 1.0 };
    // The node turns a little about y.
    let (s, c) = (0.1f32.sin(), 0.1f32.cos());
    let rotations = [0.0f32, 0.0, 0.0, 1.0, 0.0, s, 0.0, c];
    let mut data: Vec<u8> = positions.iter().flat_map(|x| x.to_le_bytes()).collect();
    let idx_at = data.len();
    data.extend(indices.iter().flat_map(|x| x.to_le_bytes()));
    let times_at = data.len();
    data.extend(times.iter().flat_map(|x| x.to_le_bytes()));
    let rot_at = data.len();
    data.extend(rotations.iter().flat_map(|x| x.to_le_bytes()));
    let doc = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "scale": [node_scale, node_scale, node_scale]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"byteLength": data.len(), "uri": anim_util::data_uri(&data)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": idx_at},
            {"buffer": 0, "byteOffset": idx_at, "byteLength": times_at - idx_at},
            {"buffer": 0, "byteOffset": times_at, "byteLength": 8},
            {"buffer": 0, "byteOffset": rot_at, "byteLength": 32}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": positions.len() / 3,
             "type": "VEC3", "min": lo, "max": hi},
            {"bufferView": 1, "componentType": 5125, "count": indices.len(), "type": "SCALAR"},
            {"bufferView": 2, "componentType": 5126, "count": 2, "type": "SCALAR",
             "min": [0.0], "max": [1.0]},
            {"bufferView": 3, "componentType": 5126, "count": 2, "type": "VEC4"}
        ],
        "animations": [{
            "channels": [{"sampler": 0, "target": {"node": 0, "path": "rotation"}}],
            "samplers": [{"input": 2, "output": 3, "interpolation": "LINEAR"}]
        }]
    });
    let p = dir.join(format!(
        "sphere_{scale:e}_{}.gltf",
        if in_node { "node" } else { "vertices" }
    ));
    std::fs::write(&p, serde_json::to_vec(&doc).unwrap()).unwrap();
    p.to_string_lossy().into_owned()
}

/// Object pixels (the first instance's clay colour: red well above blue, which the grey
/// ground and the blue-grey sky never are) and their mean brightness, in frame 0 of `file`.
fn object_pixels(file: &str, out: &Path) -> (usize, f64) {
    ok(&dynbvh(&[
        "render",
        file,
        "--frames",
        "2",
        "--size",
        "96x72",
        "--out",
        &out.to_string_lossy(),
    ]));
    let img = image::open(out.join("frame_0000.png")).unwrap().to_rgb8();
    let object: Vec<f64> = img
        .pixels()
        .filter(|p| i32::from(p[0]) > i32::from(p[2]) + 40)
        .map(|p| f64::from(p[0]) + f64::from(p[1]) + f64::from(p[2]))
        .collect();
    let mean = object.iter().sum::<f64>() / object.len().max(1) as f64;
    (object.len(), mean)
}

#[test]
fn the_same_mesh_renders_alike_from_1e_minus_15_to_1e15() {
    let d = tmp_dir("scale", "sweep");
    for in_node in [false, true] {
        let (unit, unit_light) = object_pixels(&sphere_file(&d, 1.0, in_node), &d.join("unit"));
        assert!(unit > 96 * 72 / 10, "the unit sphere covers {unit} pixels");
        for s in SCALES {
            let out = d.join(format!("r_{s:e}_{in_node}"));
            let (n, light) = object_pixels(&sphere_file(&d, s, in_node), &out);
            let what = if in_node { "node" } else { "vertices" };
            assert!(
                n.abs_diff(unit) * 20 <= unit,
                "scale {s:e} in the {what}: {n} object pixels, {unit} at scale 1"
            );
            assert!(
                (light - unit_light).abs() <= 0.05 * unit_light,
                "scale {s:e} in the {what}: mean brightness {light:.1}, {unit_light:.1} at scale 1"
            );
        }
    }
}
