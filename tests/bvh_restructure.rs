//! The rungs between refit and rebuild: insertion-based optimisation and partial rebuild.
//! On every frame of the shipped deforming animations (and the generated ones), a refitted
//! tree optimised or partly rebuilt must still pass every invariant, agree with brute force,
//! and keep working as a tree that is refitted, optimised and partly rebuilt again frame after
//! frame; and each must lower the SAH where refitting raised it.

mod common;

use dynbvh::anim::Scene;
use dynbvh::bvh::optimize::{OptimizeBudget, OptimizeScratch};
use dynbvh::bvh::partial::{PartialCut, PartialScratch};
use dynbvh::bvh::topology::RestructureWorkspace;
use dynbvh::bvh::{BuildParams, MeshBvh};
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::source::FrameSource;
use dynbvh::engine::{EngineConfig, Policy};
use dynbvh::geom::TriMesh;
use glam::Vec3;
use std::path::PathBuf;

fn scene(file: &str) -> Scene {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("animations")
        .join(file);
    Scene::load(&path).unwrap().0
}

/// Every frame's mesh of each deforming mesh of `file`'s first animation (`frames` frames).
fn frames_of(file: &str, frames: usize) -> Vec<Vec<TriMesh>> {
    let s = scene(file);
    let mut src = GltfSource::new(&s, Some(0), FrameTimes::Count(frames)).unwrap();
    let config = EngineConfig {
        policy: Policy::Refit,
        ..EngineConfig::default()
    };
    let mut e = src.build(0, config);
    let ids: Vec<_> = src.deforming().to_vec();
    assert!(!ids.is_empty(), "{file}: no deforming mesh");
    let mut out = vec![Vec::new(); ids.len()];
    for f in 0..=frames {
        if f > 0 {
            src.advance(&mut e, f);
            e.update();
        }
        for (k, &m) in ids.iter().enumerate() {
            out[k].push(TriMesh {
                positions: e.positions(m).to_vec(),
                indices: e.indices(m).to_vec(),
            });
        }
    }
    out
}

fn check(mesh: &TriMesh, bvh: &MeshBvh, what: &str) {
    common::check_tree(mesh, bvh, what);
}

/// Refits one tree through every frame; on each frame a copy is optimised and another partly
/// rebuilt, and a third tree goes through all three operations in turn for the whole clip.
fn run_clip(file: &str, frames: usize) -> (f64, f64, f64, f64) {
    let params = BuildParams::BINNED;
    let mut ws = RestructureWorkspace::default();
    let mut os = OptimizeScratch::default();
    let mut ps = PartialScratch::default();
    let budget = OptimizeBudget {
        share: 0.05,
        ..OptimizeBudget::default()
    };
    let (mut refit_sah, mut opt_sah, mut partial_sah, mut fresh_sah) = (0.0, 0.0, 0.0, 0.0);
    for (k, meshes) in frames_of(file, frames).iter().enumerate() {
        let mut refitted = MeshBvh::build(&meshes[0], &params);
        let mut cut = PartialCut::default();
        cut.reset(&refitted, &mut ps);
        let mut chain = refitted.clone();
        let mut chain_cut = cut.clone();
        for (f, mesh) in meshes.iter().enumerate().skip(1) {
            let what = format!("{file} mesh {k} frame {f}");
            refitted.refit(mesh);
            let mut o = refitted.clone();
            let st = o.optimize(budget, &mut ws, &mut os);
            check(mesh, &o, &format!("{what}, optimised"));
            // Moves that do not pay are undone: the SAH never grows, and goes down when
            // anything moved.
            let (before, after) = (refitted.bvh().sah_cost(), o.bvh().sah_cost());
            assert!(
                after <= before * (1.0 + 1e-5),
                "{what}: SAH {before} -> {after}"
            );
            assert!(
                st.moved == 0 || after < before,
                "{what}: {st:?}, SAH {before} -> {after}"
            );
            let mut p = refitted.clone();
            let mut c = cut.clone();
            let st = p.partial_rebuild(&mut c, 0.25, &params, &mut ws, &mut ps);
            check(mesh, &p, &format!("{what}, partly rebuilt"));
            assert!(
                st.rebuilt_tris <= (0.25 * mesh.len() as f32) as u32,
                "{what}: {st:?} rebuilt more than its share"
            );
            refit_sah += f64::from(refitted.bvh().sah_cost());
            opt_sah += f64::from(o.bvh().sah_cost());
            partial_sah += f64::from(p.bvh().sah_cost());
            fresh_sah += f64::from(MeshBvh::build(mesh, &params).bvh().sah_cost());

            chain.refit(mesh);
            check(mesh, &chain, &format!("{what}, chain refitted"));
            match f % 3 {
                0 => {
                    // The cut is kept only through refits and partial rebuilds; the partial
                    // rebuild after this one sees it no longer fits and takes a new one.
                    chain.optimize(budget, &mut ws, &mut os);
                }
                1 => {
                    chain.partial_rebuild(&mut chain_cut, 0.25, &params, &mut ws, &mut ps);
                }
                _ => {}
            }
            check(mesh, &chain, &format!("{what}, chain"));
        }
    }
    (refit_sah, opt_sah, partial_sah, fresh_sah)
}

#[test]
fn optimised_and_partly_rebuilt_trees_are_exact_on_every_frame() {
    for file in [
        "explode.glb",
        "swap.glb",
        "tube.glb",
        "wave.glb",
        "lidar_cloth.glb",
    ] {
        let (refit, opt, partial, fresh) = run_clip(file, 24);
        eprintln!(
            "{file}: summed SAH refit {refit:.1}, optimised {opt:.1}, partial {partial:.1}, \
             fresh {fresh:.1}"
        );
        assert!(opt < refit, "{file}: optimising did not lower the SAH");
        assert!(
            partial <= refit * 1.001,
            "{file}: partial rebuild raised the SAH"
        );
    }
}

#[test]
fn partial_rebuild_recovers_what_moving_parts_cost() {
    // Swap's halves and wave's crest move as wholes: the upper levels degrade, the subtrees
    // inside each part do not, and the partial rebuild wins back most of what refitting lost.
    for file in ["swap.glb", "wave.glb"] {
        let (refit, _, partial, fresh) = run_clip(file, 24);
        let recovered = (refit - partial) / (refit - fresh);
        assert!(
            recovered >= 0.5,
            "{file}: partial rebuild won back {recovered:.2} of the lost SAH"
        );
    }
}

#[test]
fn optimise_lowers_the_sah_of_a_fresh_build() {
    let mesh = dynbvh::geom::shapes::bumpy_sphere(20_000);
    let mut bvh = MeshBvh::build(&mesh, &BuildParams::BINNED);
    let before = bvh.bvh().sah_cost();
    let st = bvh.optimize(
        OptimizeBudget {
            share: 0.2,
            passes: 3,
            ..OptimizeBudget::default()
        },
        &mut RestructureWorkspace::default(),
        &mut OptimizeScratch::default(),
    );
    check(&mesh, &bvh, "bumpy sphere");
    let after = bvh.bvh().sah_cost();
    eprintln!(
        "fresh binned16 SAH {before} -> {after} ({} moved)",
        st.moved
    );
    assert!(after < before, "{before} -> {after}");
    assert!(st.gain > 0.0);
}

#[test]
fn degenerate_inputs_survive_both_operations() {
    let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
    let cases: Vec<(&str, TriMesh)> = vec![
        ("one triangle", TriMesh::from_soup(&[tri])),
        (
            "two triangles",
            TriMesh::from_soup(&[tri, tri.map(|v| v + Vec3::Z)]),
        ),
        ("coincident centroids", TriMesh::from_soup(&vec![tri; 500])),
        (
            "coplanar",
            TriMesh::from_soup(
                &(0..800)
                    .map(|i| {
                        tri.map(|v| v * 0.1 + Vec3::new((i % 40) as f32, (i / 40) as f32, 0.0))
                    })
                    .collect::<Vec<_>>(),
            ),
        ),
        ("with NaN and inf", common::soup_with_nan_and_inf()),
    ];
    let params = BuildParams::BINNED;
    for (what, mesh) in cases {
        let mut a = MeshBvh::build(&mesh, &params);
        a.optimize(
            OptimizeBudget {
                share: 1.0,
                passes: 2,
                ..OptimizeBudget::default()
            },
            &mut RestructureWorkspace::default(),
            &mut OptimizeScratch::default(),
        );
        a.validate(&mesh)
            .unwrap_or_else(|e| panic!("{what}, optimised: {e}"));
        let mut b = MeshBvh::build(&mesh, &params);
        let mut ps = PartialScratch::default();
        let mut cut = PartialCut::default();
        cut.reset(&b, &mut ps);
        b.partial_rebuild(
            &mut cut,
            1.0,
            &params,
            &mut RestructureWorkspace::default(),
            &mut ps,
        );
        b.validate(&mesh)
            .unwrap_or_else(|e| panic!("{what}, partly rebuilt: {e}"));
        for ray in common::rays_around(Vec3::splat(0.5), 2.0, 100, 3) {
            for (t, name) in [(&a, "optimised"), (&b, "partly rebuilt")] {
                common::check_ray(&mesh, t, &ray).unwrap_or_else(|e| panic!("{what}, {name}: {e}"));
            }
        }
    }
}
