//! One glTF mesh to a [`Mesh`]: surface primitives merged into triangles, morph target deltas
//! and skinning attributes.

use super::accessor::Reader;
use super::scene::{Mesh, SkinAttributes, Warning};
use super::source::{MESHOPT, meshopt_extension};
use crate::error::Result;
use glam::Vec3;
use gltf_json::accessor::{ComponentType, Type};
use gltf_json::mesh::{Mode, Primitive, Semantic};
use gltf_json::validation::Checked;

/// A loaded mesh and what was skipped or repaired.
pub(crate) struct LoadedMesh {
    /// The mesh.
    pub mesh: Mesh,
    /// Some primitives were points or lines.
    pub skipped_modes: bool,
    /// Vertices whose skin weights were renormalized noticeably.
    pub renormalized: usize,
    /// Vertices whose skin weights are all zero (not renormalized: skinning leaves them to
    /// the mesh node's transform).
    pub unweighted: usize,
    /// Surface primitives skipped because their data is compressed.
    pub compressed: usize,
    /// Other warnings.
    pub warnings: Vec<Warning>,
}

/// Mesh compression whose primitives carry their geometry in a form the engine does not
/// decode (the file may still give uncompressed fallback data, which is then read).
pub(crate) const DRACO: &str = "KHR_draco_mesh_compression";

/// The compression extension that keeps primitive `p` from being read, if any: Draco when an
/// accessor it reads has neither a buffer view nor sparse data (the data lives only in the
/// Draco stream), meshopt when an accessor's buffer view points into a buffer without data.
fn compressed(rd: &Reader, p: &Primitive) -> Option<&'static str> {
    let accessors = p
        .attributes
        .values()
        .chain(p.indices.as_ref())
        .chain(
            p.targets
                .iter()
                .flatten()
                .filter_map(|t| t.positions.as_ref()),
        )
        .filter_map(|a| rd.src.root.accessors.get(a.value()));
    let draco = p
        .extensions
        .as_ref()
        .is_some_and(|e| e.others.contains_key(DRACO));
    for acc in accessors {
        match acc.buffer_view {
            None if draco && acc.sparse.is_none() => return Some(DRACO),
            None => {}
            Some(v) => {
                let Some(view) = rd.src.root.buffer_views.get(v.value()) else {
                    continue;
                };
                if rd.src.absent.get(view.buffer.value()) == Some(&true) {
                    return Some(
                        meshopt_extension(view.extensions.as_ref().map(|e| &e.others))
                            .unwrap_or(MESHOPT[0]),
                    );
                }
            }
        }
    }
    None
}

/// One primitive's data before merging.
struct Prim {
    positions: Vec<Vec3>,
    indices: Vec<[u32; 3]>,
    targets: Vec<Vec<Vec3>>,
    joints: Vec<Vec<u32>>,
    weights: Vec<Vec<f32>>,
}

/// Turns a vertex index list into triangles per the spec's rules for `mode`.
fn triangulate(mode: Mode, idx: &[u32]) -> Vec<[u32; 3]> {
    let n = idx.len();
    match mode {
        Mode::Triangles => idx.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        Mode::TriangleStrip => (0..n.saturating_sub(2))
            .map(|i| {
                let odd = i % 2;
                [idx[i], idx[i + 1 + odd], idx[i + 2 - odd]]
            })
            .collect(),
        Mode::TriangleFan => (0..n.saturating_sub(2))
            .map(|i| [idx[i + 1], idx[i + 2], idx[0]])
            .collect(),
        _ => Vec::new(),
    }
}

/// Reads one surface primitive; `None` when it has no POSITION.
fn load_primitive(rd: &Reader, obj: &str, mode: Mode, p: &Primitive) -> Result<Option<Prim>> {
    let attr = |s: Semantic| p.attributes.get(&Checked::Valid(s)).map(|a| a.value());
    let Some(pos) = attr(Semantic::Positions) else {
        return Ok(None);
    };
    let positions: Vec<Vec3> = rd
        .floats(pos, obj, "POSITION", &[Type::Vec3])?
        .values
        .chunks_exact(3)
        .map(Vec3::from_slice)
        .collect();
    let n = positions.len();
    if n >= u32::MAX as usize {
        return Err(rd.err(obj, "fewer than 2^32 vertices"));
    }
    let same_count = |a: usize, role: &str, len: usize| {
        if len == n {
            Ok(())
        } else {
            Err(rd.err(
                format!("{obj} accessor {a} ({role})"),
                format!("{n} elements like POSITION, found {len}"),
            ))
        }
    };
    let idx: Vec<u32> = match p.indices {
        Some(a) => {
            let d = rd.uints(a.value(), obj, "indices", Type::Scalar)?;
            if let Some(k) = d.values.iter().position(|&i| i as usize >= n) {
                return Err(rd.err(
                    format!("{obj} accessor {} (indices)", a.value()),
                    format!(
                        "vertex indices below the vertex count {n}, found {} at index {k}",
                        d.values[k]
                    ),
                ));
            }
            d.values
        }
        None => (0..n as u32).collect(),
    };
    let indices = triangulate(mode, &idx);
    let mut targets = Vec::new();
    for (k, t) in p.targets.iter().flatten().enumerate() {
        let deltas = match t.positions {
            Some(a) => {
                let tobj = format!("{obj} target {k}");
                let d: Vec<Vec3> = rd
                    .floats(a.value(), &tobj, "POSITION", &[Type::Vec3])?
                    .values
                    .chunks_exact(3)
                    .map(Vec3::from_slice)
                    .collect();
                same_count(a.value(), "target POSITION", d.len())?;
                d
            }
            None => vec![Vec3::ZERO; n],
        };
        targets.push(deltas);
    }
    let (mut joints, mut weights) = (Vec::new(), Vec::new());
    for set in 0u32.. {
        let (Some(j), Some(w)) = (attr(Semantic::Joints(set)), attr(Semantic::Weights(set))) else {
            break;
        };
        let jd = rd.uints(j, obj, &format!("JOINTS_{set}"), Type::Vec4)?;
        same_count(j, &format!("JOINTS_{set}"), jd.values.len() / 4)?;
        let wd = rd.floats(w, obj, &format!("WEIGHTS_{set}"), &[Type::Vec4])?;
        same_count(w, &format!("WEIGHTS_{set}"), wd.values.len() / 4)?;
        let float_or_norm = wd.comp == ComponentType::F32
            || rd.src.root.accessors.get(w).is_some_and(|a| a.normalized);
        if !float_or_norm {
            return Err(rd.err(
                format!("{obj} accessor {w} (WEIGHTS_{set})"),
                "float or normalized unsigned weights",
            ));
        }
        joints.push(jd.values);
        weights.push(wd.values);
    }
    Ok(Some(Prim {
        positions,
        indices,
        targets,
        joints,
        weights,
    }))
}

/// Checks, from the accessor counts alone and before anything is decoded, that mesh `m` has
/// fewer than 2^32 vertices over its surface primitives and that its merged data (positions,
/// triangles, morph deltas and skin attributes, each primitive padded to the mesh's most
/// targets and weight sets) fits the reader's remaining decode bound.
fn check_size(rd: &Reader, m: usize) -> Result<()> {
    let jm = &rd.src.root.meshes[m];
    let count = |a: &gltf_json::Index<gltf_json::Accessor>| {
        rd.src
            .root
            .accessors
            .get(a.value())
            .map_or(0, |a| a.count.0)
    };
    let surface = jm.primitives.iter().filter(|p| {
        matches!(
            p.mode,
            Checked::Valid(Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan)
        )
    });
    let (mut verts, mut index_count) = (0u64, 0u64);
    let (mut targets, mut sets) = (0u64, 0u64);
    for p in surface {
        let Some(pos) = p.attributes.get(&Checked::Valid(Semantic::Positions)) else {
            continue;
        };
        let n = count(pos);
        verts = verts.saturating_add(n);
        index_count = index_count.saturating_add(p.indices.as_ref().map_or(n, count));
        targets = targets.max(p.targets.as_ref().map_or(0, |t| t.len() as u64));
        let s = (0u32..)
            .take_while(|&s| {
                p.attributes
                    .contains_key(&Checked::Valid(Semantic::Joints(s)))
                    && p.attributes
                        .contains_key(&Checked::Valid(Semantic::Weights(s)))
            })
            .count();
        sets = sets.max(s as u64);
    }
    if verts >= u64::from(u32::MAX) {
        return Err(rd.err(
            format!("mesh {m}"),
            format!("fewer than 2^32 vertices over its primitives, found {verts}"),
        ));
    }
    // Per vertex: position and one delta per target (12 bytes each), 4 joints (u16) and
    // 4 weights (f32) per set; per index at most one triangle of 12 bytes (strips).
    let per_vertex = 12 * (1 + targets) + 24 * sets;
    let bytes = verts
        .saturating_mul(per_vertex)
        .saturating_add(index_count.saturating_mul(12));
    if bytes > rd.remaining() {
        return Err(rd.too_big(
            format!("mesh {m} ({verts} vertices, {targets} morph targets, {sets} weight sets)"),
            bytes,
        ));
    }
    Ok(())
}

/// Loads glTF mesh `m` (the index must be in range).
pub(crate) fn load_mesh(rd: &Reader, m: usize) -> Result<LoadedMesh> {
    let jm = &rd.src.root.meshes[m];
    let mut warnings = Vec::new();
    let mut skipped_modes = false;
    let mut prims = Vec::new();
    // glTF index of each entry of `prims`.
    let mut prim_index = Vec::new();
    let mut compressed_prims: Vec<(usize, &str)> = Vec::new();
    check_size(rd, m)?;
    for (p, jp) in jm.primitives.iter().enumerate() {
        let obj = format!("mesh {m} primitive {p}");
        let mode = match jp.mode {
            Checked::Valid(m @ (Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan)) => m,
            Checked::Valid(_) => {
                skipped_modes = true;
                continue;
            }
            Checked::Invalid => return Err(rd.err(obj, "a primitive mode between 0 and 6")),
        };
        if let Some(ext) = compressed(rd, jp) {
            compressed_prims.push((p, ext));
            continue;
        }
        match load_primitive(rd, &obj, mode, jp)? {
            Some(prim) => {
                prims.push(prim);
                prim_index.push(p);
            }
            None => warnings.push(Warning(format!(
                "{}: {obj}: no POSITION attribute; skipped",
                rd.path.display()
            ))),
        }
    }
    if !compressed_prims.is_empty() {
        let mut exts: Vec<&str> = compressed_prims.iter().map(|c| c.1).collect();
        exts.sort_unstable();
        exts.dedup();
        let list: Vec<String> = compressed_prims.iter().map(|c| c.0.to_string()).collect();
        warnings.push(Warning(format!(
            "{}: mesh {m}{} primitive{} {} of {}: compressed with {}, which the engine does not decode; skipped",
            rd.path.display(),
            jm.name.as_deref().map(|n| format!(" \"{n}\"")).unwrap_or_default(),
            if list.len() == 1 { "" } else { "s" },
            list.join(", "),
            jm.primitives.len(),
            exts.join(" and ")
        )));
    }
    let n_targets = prims.iter().map(|p| p.targets.len()).max().unwrap_or(0);
    let n_sets = prims.iter().map(|p| p.joints.len()).max().unwrap_or(0);
    let total: usize = prims.iter().map(|p| p.positions.len()).sum();
    if total >= u32::MAX as usize {
        return Err(rd.err(format!("mesh {m}"), "fewer than 2^32 vertices"));
    }
    let mut mesh = Mesh {
        name: jm.name.clone(),
        gltf_index: m,
        targets: vec![Vec::with_capacity(total); n_targets],
        ..Mesh::default()
    };
    let influences = 4 * n_sets;
    let mut attrs = SkinAttributes {
        influences,
        joints: Vec::with_capacity(total * influences),
        weights: Vec::with_capacity(total * influences),
    };
    let (mut renormalized, mut unweighted) = (0, 0);
    for (pi, p) in prims.into_iter().enumerate() {
        let base = mesh.positions.len() as u32;
        let t0 = mesh.indices.len();
        mesh.indices
            .extend(p.indices.iter().map(|t| t.map(|i| i + base)));
        mesh.primitives.push(t0..mesh.indices.len());
        let n = p.positions.len();
        for (k, target) in mesh.targets.iter_mut().enumerate() {
            match p.targets.get(k) {
                Some(d) => target.extend_from_slice(d),
                None => target.extend(std::iter::repeat_n(Vec3::ZERO, n)),
            }
        }
        mesh.positions.extend_from_slice(&p.positions);
        if influences == 0 {
            continue;
        }
        for v in 0..n {
            let start = attrs.weights.len();
            for s in 0..n_sets {
                for c in 0..4 {
                    let j = p.joints.get(s).and_then(|js| js.get(4 * v + c)).copied();
                    let w = p.weights.get(s).and_then(|ws| ws.get(4 * v + c)).copied();
                    let w = w.unwrap_or(0.0).max(0.0);
                    // A joint with zero weight never matters: park it on joint 0.
                    let j = if w > 0.0 { j.unwrap_or(0) } else { 0 };
                    // Skins have at most 65536 joints (JOINTS_n are u8 or u16 by the spec;
                    // the loader also reads u32): a larger index can name no joint.
                    let Ok(j) = u16::try_from(j) else {
                        return Err(rd.err(
                            format!("mesh {m} primitive {} JOINTS_{s}", prim_index[pi]),
                            format!(
                                "joint indices below 65536 (a skin has at most 65536 joints), \
                                 found {j} with weight {w} at vertex {v}"
                            ),
                        ));
                    };
                    attrs.joints.push(j);
                    attrs.weights.push(w);
                }
            }
            let ws = &mut attrs.weights[start..];
            let sum: f32 = ws.iter().sum();
            if sum > 0.0 && (sum - 1.0).abs() > 1e-6 {
                if (sum - 1.0).abs() > 1e-3 {
                    renormalized += 1;
                }
                ws.iter_mut().for_each(|w| *w /= sum);
            } else if sum == 0.0 {
                unweighted += 1;
            }
        }
    }
    if n_targets > 0 {
        mesh.weights = jm.weights.clone().unwrap_or_default();
        if !mesh.weights.iter().all(|w| w.is_finite()) {
            return Err(rd.err(format!("mesh {m}"), "finite default weights"));
        }
        mesh.weights.resize(n_targets, 0.0);
    }
    if influences > 0 {
        mesh.skin = Some(attrs);
    }
    Ok(LoadedMesh {
        mesh,
        skipped_modes,
        renormalized,
        unweighted,
        compressed: compressed_prims.len(),
        warnings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strips_and_fans_keep_winding() {
        let idx = [0, 1, 2, 3, 4];
        assert_eq!(
            triangulate(Mode::TriangleStrip, &idx),
            vec![[0, 1, 2], [1, 3, 2], [2, 3, 4]]
        );
        assert_eq!(
            triangulate(Mode::TriangleFan, &idx),
            vec![[1, 2, 0], [2, 3, 0], [3, 4, 0]]
        );
        assert_eq!(triangulate(Mode::Triangles, &idx), vec![[0, 1, 2]]);
        assert!(triangulate(Mode::TriangleStrip, &idx[..2]).is_empty());
    }
}
