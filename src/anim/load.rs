//! glTF document to [`Scene`]: node forest, chosen scene, instances, skins and animations.
//! Mesh geometry is read by [`super::mesh_load`].

use super::accessor::{Reader, decoded_limit};
use super::mesh_load::load_mesh;
use super::scene::{
    Animation, Channel, Instance, Interpolation, Node, Property, Sampler, Scene, Skin, Trs, Warning,
};
use super::source::Source;
use crate::error::{Error, Result};
use glam::{Mat4, Quat, Vec3};
use gltf_json::accessor::Type;
use gltf_json::animation::{Interpolation as JInterp, Property as JProp};
use gltf_json::validation::Checked;
use std::collections::HashMap;
use std::path::Path;

/// Options for [`Scene::load_with`].
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// glTF scene to use instead of the file's default scene.
    pub scene: Option<usize>,
    /// Bound on the bytes of decoded accessor data (`None`: [`decoded_limit`] of the input's
    /// size, 4 GiB plus 16 bytes per byte of file and buffers). A file asking for more is an
    /// error naming it and the mesh or accessor that went over, raised before the memory is
    /// allocated.
    pub max_decoded_bytes: Option<u64>,
    /// Read external buffers whose URI is absolute or leaves the glTF file's folder (through
    /// `..`). Off by default, so that a file cannot make the loader read what its user did
    /// not hand it.
    pub allow_outside_files: bool,
}

/// What the engine ignores of an extension listed in `extensionsUsed`, or `None` when it
/// handles the extension or the extension cannot change positions or animation.
///
/// Handled: `KHR_mesh_quantization` (decoded), and the mesh compressions
/// (`KHR_draco_mesh_compression`, `EXT_meshopt_compression`, `KHR_meshopt_compression`): their
/// uncompressed fallback data is read when the file has it, and primitives without it are
/// skipped with a warning naming them (see `mesh_load`). Appearance and metadata extensions
/// (materials, textures, lights, XMP) lose nothing: the engine reads geometry only and never
/// reads any material, texture or light. Everything else is named in a warning.
fn extension_ignored(ext: &str) -> Option<String> {
    const HANDLED: &[&str] = &[
        "KHR_mesh_quantization",
        "KHR_draco_mesh_compression",
        "EXT_meshopt_compression",
        "KHR_meshopt_compression",
    ];
    const APPEARANCE: &[&str] = &[
        "KHR_materials_",
        "KHR_texture_",
        "EXT_texture_",
        "KHR_lights_",
        "EXT_lights_",
        "KHR_xmp",
    ];
    if HANDLED.contains(&ext) || APPEARANCE.iter().any(|p| ext.starts_with(p)) {
        return None;
    }
    Some(match ext {
        "EXT_mesh_gpu_instancing" => {
            "instances beyond the node's own are skipped (each node places its mesh once)".into()
        }
        "KHR_animation_pointer" => "animation channels that target a pointer are skipped".into(),
        "KHR_node_visibility" => "node visibility is ignored: hidden nodes are loaded".into(),
        _ => "not known to the engine and ignored: anything it changes is not applied".into(),
    })
}

impl Scene {
    /// Loads the default scene of a `.gltf` or `.glb` file, with warnings about what was skipped.
    pub fn load(path: impl AsRef<Path>) -> Result<(Scene, Vec<Warning>)> {
        Self::load_with(path, &LoadOptions::default())
    }

    /// Loads a `.gltf` or `.glb` file with options.
    pub fn load_with(path: impl AsRef<Path>, opts: &LoadOptions) -> Result<(Scene, Vec<Warning>)> {
        let path = path.as_ref();
        let bytes = crate::io::read_file(path, None)?;
        Self::from_slice(path, &bytes, opts)
    }

    /// Loads from the bytes of a file; `path` names it in errors and locates external buffers.
    pub fn from_slice(
        path: &Path,
        bytes: &[u8],
        opts: &LoadOptions,
    ) -> Result<(Scene, Vec<Warning>)> {
        let src = Source::parse(path, bytes, opts.allow_outside_files)?;
        let input = bytes.len() as u64 + src.buffers.iter().map(|b| b.len() as u64).sum::<u64>();
        let limit = opts
            .max_decoded_bytes
            .unwrap_or_else(|| decoded_limit(input));
        let rd = Reader::new(path, &src, limit);
        let mut warnings = Vec::new();
        let mut used: Vec<&String> = src
            .root
            .extensions_used
            .iter()
            .chain(&src.root.extensions_required)
            .collect();
        used.sort_unstable();
        used.dedup();
        for ext in used {
            if let Some(what) = extension_ignored(ext) {
                warnings.push(Warning(format!(
                    "{}: extension {ext}: {what}",
                    path.display()
                )));
            }
        }
        let (nodes, order) = load_nodes(&rd)?;
        let (scene_index, roots) = choose_scene(&rd, &nodes, opts, &mut warnings)?;
        let skins = load_skins(&rd, nodes.len())?;
        let animations = load_animations(&rd, nodes.len(), &mut warnings)?;
        let mut scene = Scene {
            path: path.into(),
            scene_index,
            scene_names: src.root.scenes.iter().map(|s| s.name.clone()).collect(),
            nodes,
            order,
            roots,
            meshes: Vec::new(),
            skins,
            animations,
            instances: Vec::new(),
        };
        let compressed = build_instances(&rd, &mut scene, &mut warnings)?;
        if compressed > 0 && scene.triangle_count() == 0 {
            return Err(Error::Unsupported {
                path: path.into(),
                object: "meshes".into(),
                what: format!(
                    "nothing left to load: all {compressed} surface primitives of the scene are \
                     compressed (KHR_draco_mesh_compression or EXT_meshopt_compression without \
                     uncompressed fallback data), which the engine does not decode"
                ),
            });
        }
        check_weight_channels(&rd, &scene, &mut warnings)?;
        Ok((scene, warnings))
    }
}

/// Checks a float array is finite.
fn finite(v: &[f32]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// Reads all nodes, checks the hierarchy is a forest, and orders nodes parents first.
fn load_nodes(rd: &Reader) -> Result<(Vec<Node>, Vec<usize>)> {
    let jnodes = &rd.src.root.nodes;
    let n = jnodes.len();
    let mut nodes = Vec::with_capacity(n);
    for (i, j) in jnodes.iter().enumerate() {
        let obj = || format!("node {i}");
        let t = j.translation.unwrap_or([0.0; 3]);
        let r = j.rotation.map_or([0.0, 0.0, 0.0, 1.0], |q| q.0);
        let s = j.scale.unwrap_or([1.0; 3]);
        if !(finite(&t) && finite(&r) && finite(&s)) {
            return Err(rd.err(obj(), "finite translation, rotation and scale"));
        }
        let q = Quat::from_array(r);
        if q.length() < 1e-6 {
            return Err(rd.err(obj(), "a non-zero rotation quaternion"));
        }
        let mut trs = Trs {
            translation: Vec3::from_array(t),
            rotation: q.normalize(),
            scale: Vec3::from_array(s),
        };
        let matrix = match j.matrix {
            Some(m) if !finite(&m) => return Err(rd.err(obj(), "a finite matrix")),
            Some(m) => {
                let m = Mat4::from_cols_array(&m);
                if m != Mat4::IDENTITY {
                    let (s, r, t) = m.to_scale_rotation_translation();
                    if s.is_finite() && r.is_finite() && t.is_finite() {
                        trs = Trs {
                            translation: t,
                            rotation: r.normalize(),
                            scale: s,
                        };
                    }
                    Some(m)
                } else {
                    None
                }
            }
            None => None,
        };
        let weights = j.weights.clone();
        if weights.as_deref().is_some_and(|w| !finite(w)) {
            return Err(rd.err(obj(), "finite morph weights"));
        }
        nodes.push(Node {
            name: j.name.clone(),
            parent: None,
            children: Vec::new(),
            trs,
            matrix,
            mesh: j.mesh.map(|m| m.value()),
            skin: j.skin.map(|s| s.value()),
            weights,
        });
    }
    for (i, j) in jnodes.iter().enumerate() {
        for c in j.children.iter().flatten() {
            let c = c.value();
            let child = nodes.get_mut(c).ok_or_else(|| {
                rd.err(
                    format!("node {i}"),
                    format!("child {c} to be a node index below {n}"),
                )
            })?;
            if child.parent.is_some() || c == i {
                return Err(rd.err(
                    format!("node {c}"),
                    "at most one parent (nodes must form a forest)",
                ));
            }
            child.parent = Some(i);
            nodes[i].children.push(c);
        }
    }
    let mut order: Vec<usize> = (0..n).filter(|&i| nodes[i].parent.is_none()).collect();
    let mut k = 0;
    while k < order.len() {
        order.extend(nodes[order[k]].children.iter().copied());
        k += 1;
    }
    if order.len() != n {
        let mut seen = vec![false; n];
        order.iter().for_each(|&i| seen[i] = true);
        let in_cycle = seen.iter().position(|&s| !s).unwrap_or(0);
        return Err(rd.err(
            format!("node {in_cycle}"),
            "to be reachable from a root (the hierarchy has a cycle)",
        ));
    }
    Ok((nodes, order))
}

/// Picks the scene to use and returns its index and root nodes.
fn choose_scene(
    rd: &Reader,
    nodes: &[Node],
    opts: &LoadOptions,
    warnings: &mut Vec<Warning>,
) -> Result<(Option<usize>, Vec<usize>)> {
    let scenes = &rd.src.root.scenes;
    let index = match (opts.scene, rd.src.root.scene) {
        (Some(s), _) if s >= scenes.len() => {
            return Err(Error::InvalidArgument(format!(
                "{}: scene {s} requested but the file has {} scenes",
                rd.path.display(),
                scenes.len()
            )));
        }
        (Some(s), _) => s,
        (None, Some(s)) if scenes.is_empty() => {
            return Err(rd.err(
                "scene",
                format!(
                    "a scene to refer to, found scene {} but the file's scenes list is empty",
                    s.value()
                ),
            ));
        }
        (None, Some(s)) if s.value() >= scenes.len() => {
            return Err(rd.err(
                "scene",
                format!("a scene index below {}, found {}", scenes.len(), s.value()),
            ));
        }
        (None, Some(s)) => s.value(),
        (None, None) if scenes.is_empty() => {
            warnings.push(Warning(format!(
                "{}: no scenes; using every root node",
                rd.path.display()
            )));
            let roots = (0..nodes.len())
                .filter(|&i| nodes[i].parent.is_none())
                .collect();
            return Ok((None, roots));
        }
        (None, None) => 0,
    };
    let mut roots = Vec::new();
    for r in &scenes[index].nodes {
        let r = r.value();
        let node = nodes.get(r).ok_or_else(|| {
            rd.err(
                format!("scene {index}"),
                format!("node {r} to be below {}", nodes.len()),
            )
        })?;
        if node.parent.is_some() || roots.contains(&r) {
            return Err(rd.err(
                format!("scene {index}"),
                format!("node {r} to be a root listed once"),
            ));
        }
        roots.push(r);
    }
    Ok((Some(index), roots))
}

/// Reads all skins.
fn load_skins(rd: &Reader, node_count: usize) -> Result<Vec<Skin>> {
    let mut skins = Vec::new();
    for (s, js) in rd.src.root.skins.iter().enumerate() {
        let obj = format!("skin {s}");
        let joints: Vec<usize> = js.joints.iter().map(|j| j.value()).collect();
        if let Some(&bad) = joints.iter().find(|&&j| j >= node_count) {
            return Err(rd.err(obj, format!("joint node {bad} below {node_count}")));
        }
        if joints.is_empty() || joints.len() > usize::from(u16::MAX) + 1 {
            return Err(rd.err(obj, "between 1 and 65536 joints"));
        }
        let inverse_bind = match js.inverse_bind_matrices {
            None => vec![Mat4::IDENTITY; joints.len()],
            Some(a) => {
                let d = rd.floats(a.value(), &obj, "inverseBindMatrices", &[Type::Mat4])?;
                if d.values.len() / 16 < joints.len() {
                    return Err(rd.err(
                        format!("{obj} accessor {} (inverseBindMatrices)", a.value()),
                        format!(
                            "{} matrices, one per joint, found {}",
                            joints.len(),
                            d.values.len() / 16
                        ),
                    ));
                }
                d.values
                    .chunks_exact(16)
                    .take(joints.len())
                    .map(|c| {
                        let mut a = [0.0; 16];
                        a.copy_from_slice(c);
                        Mat4::from_cols_array(&a)
                    })
                    .collect()
            }
        };
        skins.push(Skin {
            name: js.name.clone(),
            joints,
            inverse_bind,
        });
    }
    Ok(skins)
}

/// Reads one sampler's keys.
fn load_sampler(rd: &Reader, obj: &str, js: &gltf_json::animation::Sampler) -> Result<Sampler> {
    let interpolation = match js.interpolation {
        Checked::Valid(JInterp::Step) => Interpolation::Step,
        Checked::Valid(JInterp::Linear) => Interpolation::Linear,
        Checked::Valid(JInterp::CubicSpline) => Interpolation::CubicSpline,
        Checked::Invalid => {
            return Err(rd.err(obj, "interpolation STEP, LINEAR or CUBICSPLINE"));
        }
    };
    let times = rd
        .floats(js.input.value(), obj, "input", &[Type::Scalar])?
        .values;
    if times.is_empty() {
        return Err(rd.err(obj, "at least one key"));
    }
    if let Some(k) = times.windows(2).position(|w| w[1] <= w[0]) {
        return Err(rd.err(
            format!("{obj} accessor {} (input)", js.input.value()),
            format!(
                "strictly increasing key times, found {} then {} at key {}",
                times[k],
                times[k + 1],
                k + 1
            ),
        ));
    }
    let out = rd.floats(
        js.output.value(),
        obj,
        "output",
        &[Type::Scalar, Type::Vec3, Type::Vec4],
    )?;
    let groups = if interpolation == Interpolation::CubicSpline {
        3
    } else {
        1
    };
    let per_key = times.len() * groups;
    let width = if out.width == 1 {
        out.values.len() / per_key
    } else {
        out.width
    };
    if width == 0 || out.values.len() != per_key * width {
        return Err(rd.err(
            format!("{obj} accessor {} (output)", js.output.value()),
            format!(
                "{per_key} values of {} components for {} keys, found {} components",
                if out.width == 1 {
                    "n".to_string()
                } else {
                    width.to_string()
                },
                times.len(),
                out.values.len()
            ),
        ));
    }
    Ok(Sampler {
        interpolation,
        times,
        values: out.values,
        width: if out.width == 1 { width } else { out.width },
    })
}

/// Reads all animations; channels the engine cannot use are dropped with a warning.
fn load_animations(
    rd: &Reader,
    node_count: usize,
    warnings: &mut Vec<Warning>,
) -> Result<Vec<Animation>> {
    let mut out = Vec::new();
    for (a, ja) in rd.src.root.animations.iter().enumerate() {
        let mut samplers = Vec::with_capacity(ja.samplers.len());
        for (s, js) in ja.samplers.iter().enumerate() {
            samplers.push(load_sampler(rd, &format!("animation {a} sampler {s}"), js)?);
        }
        let mut channels = Vec::new();
        let mut duration = 0.0f32;
        for (c, jc) in ja.channels.iter().enumerate() {
            let obj = format!("animation {a} channel {c}");
            let s = jc.sampler.value();
            let sampler = samplers
                .get(s)
                .ok_or_else(|| rd.err(&obj, format!("sampler {s} below {}", ja.samplers.len())))?;
            let node = jc.target.node.value();
            if node >= node_count {
                return Err(rd.err(&obj, format!("target node {node} below {node_count}")));
            }
            let (property, width) = match jc.target.path {
                Checked::Valid(JProp::Translation) => (Property::Translation, Some(3)),
                Checked::Valid(JProp::Rotation) => (Property::Rotation, Some(4)),
                Checked::Valid(JProp::Scale) => (Property::Scale, Some(3)),
                Checked::Valid(JProp::MorphTargetWeights) => (Property::Weights, None),
                Checked::Invalid => {
                    warnings.push(Warning(format!(
                        "{}: {obj}: target path not supported, channel skipped",
                        rd.path.display()
                    )));
                    continue;
                }
            };
            if width.is_some_and(|w| w != sampler.width) {
                return Err(rd.err(
                    &obj,
                    format!(
                        "sampler {s} output of {} components for {property:?}, found {}",
                        width.unwrap_or(0),
                        sampler.width
                    ),
                ));
            }
            if let Some(&last) = sampler.times.last() {
                duration = duration.max(last);
            }
            channels.push(Channel {
                node,
                property,
                sampler: s,
            });
        }
        // Rotation keys are unit quaternions by the spec; make rounding in the file harmless.
        for ch in &channels {
            let s = &mut samplers[ch.sampler];
            if ch.property == Property::Rotation && s.interpolation != Interpolation::CubicSpline {
                for q in s.values.chunks_exact_mut(4) {
                    let len = q.iter().map(|x| x * x).sum::<f32>().sqrt();
                    if len > 0.0 {
                        q.iter_mut().for_each(|x| *x /= len);
                    }
                }
            }
        }
        out.push(Animation {
            name: ja.name.clone(),
            channels,
            samplers,
            duration,
        });
    }
    Ok(out)
}

/// Walks the chosen scene depth first, loads the meshes it places and records the instances;
/// returns how many surface primitives were skipped as compressed.
fn build_instances(rd: &Reader, scene: &mut Scene, warnings: &mut Vec<Warning>) -> Result<usize> {
    let mut stack: Vec<usize> = scene.roots.iter().rev().copied().collect();
    let mut mesh_map: HashMap<usize, usize> = HashMap::new();
    let mut skipped_modes = Vec::new();
    let mut bad_weights = Vec::new();
    let mut no_weights = Vec::new();
    let (mut tris, mut verts) = (0usize, 0usize);
    let mut compressed = 0;
    while let Some(n) = stack.pop() {
        let node = &scene.nodes[n];
        stack.extend(node.children.iter().rev().copied());
        let Some(gm) = node.mesh else { continue };
        let obj = format!("node {n}");
        if gm >= rd.src.root.meshes.len() {
            return Err(rd.err(obj, format!("mesh {gm} below {}", rd.src.root.meshes.len())));
        }
        let mi = match mesh_map.get(&gm) {
            Some(&mi) => mi,
            None => {
                let loaded = load_mesh(rd, gm)?;
                if loaded.skipped_modes {
                    skipped_modes.push(format!("mesh {gm}"));
                }
                if loaded.renormalized > 0 {
                    bad_weights.push(format!("mesh {gm} ({} vertices)", loaded.renormalized));
                }
                if loaded.unweighted > 0 {
                    no_weights.push(format!("mesh {gm} ({} vertices)", loaded.unweighted));
                }
                compressed += loaded.compressed;
                warnings.extend(loaded.warnings);
                scene.meshes.push(loaded.mesh);
                mesh_map.insert(gm, scene.meshes.len() - 1);
                scene.meshes.len() - 1
            }
        };
        let mesh = &scene.meshes[mi];
        let node = &scene.nodes[n];
        let mut skin = None;
        if let Some(s) = node.skin {
            let sk = scene
                .skins
                .get(s)
                .ok_or_else(|| rd.err(&obj, format!("skin {s} below {}", scene.skins.len())))?;
            match &mesh.skin {
                None => warnings.push(Warning(format!(
                    "{}: {obj}: skin {s} but mesh {gm} has no JOINTS_0/WEIGHTS_0; drawn unskinned",
                    rd.path.display()
                ))),
                Some(attrs) => {
                    if let Some(&j) = attrs.joints.iter().max()
                        && usize::from(j) >= sk.joints.len()
                    {
                        return Err(rd.err(
                            format!("{obj} mesh {gm}"),
                            format!(
                                "joint indices below skin {s}'s {} joints, found {j}",
                                sk.joints.len()
                            ),
                        ));
                    }
                    skin = Some(s);
                }
            }
        }
        let nt = mesh.targets.len();
        let mut weights = node.weights.clone().unwrap_or_else(|| mesh.weights.clone());
        if weights.len() != nt {
            if node.weights.is_some() {
                warnings.push(Warning(format!(
                    "{}: {obj}: {} morph weights for {nt} targets; padded or cut",
                    rd.path.display(),
                    weights.len()
                )));
            }
            weights.resize(nt, 0.0);
        }
        let t0 = tris;
        let v0 = verts;
        tris += mesh.indices.len();
        verts += mesh.positions.len();
        scene.instances.push(Instance {
            node: n,
            mesh: mi,
            skin,
            weights,
            triangles: t0..tris,
            vertices: v0..verts,
        });
    }
    if !skipped_modes.is_empty() {
        warnings.push(Warning(format!(
            "{}: points and lines are not surfaces; skipped primitives in {}",
            rd.path.display(),
            skipped_modes.join(", ")
        )));
    }
    if !bad_weights.is_empty() {
        warnings.push(Warning(format!(
            "{}: skin weights not summing to 1 were renormalized in {}",
            rd.path.display(),
            bad_weights.join(", ")
        )));
    }
    if !no_weights.is_empty() {
        warnings.push(Warning(format!(
            "{}: vertices whose skin weights are all zero are not skinned (they keep their \
             morphed rest position, moved by the mesh node's own transform) in {}",
            rd.path.display(),
            no_weights.join(", ")
        )));
    }
    Ok(compressed)
}

/// Checks that morph weight channels driving placed meshes give one weight per target.
fn check_weight_channels(rd: &Reader, scene: &Scene, warnings: &mut Vec<Warning>) -> Result<()> {
    for (a, anim) in scene.animations.iter().enumerate() {
        for (c, ch) in anim.channels.iter().enumerate() {
            if ch.property != Property::Weights {
                continue;
            }
            let width = anim.samplers[ch.sampler].width;
            let targets = scene
                .instances
                .iter()
                .find(|i| i.node == ch.node)
                .map(|i| scene.meshes[i.mesh].targets.len());
            match targets {
                Some(0) => warnings.push(Warning(format!(
                    "{}: animation {a} channel {c}: node {}'s mesh has no morph targets; ignored",
                    rd.path.display(),
                    ch.node
                ))),
                Some(t) if t != width => {
                    return Err(rd.err(
                        format!("animation {a} channel {c}"),
                        format!(
                            "{t} weights per key for node {}'s {t} morph targets, found {width}",
                            ch.node
                        ),
                    ));
                }
                _ => {}
            }
        }
    }
    Ok(())
}
