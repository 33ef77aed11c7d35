//! Rays over unusual ranges `[tmin, tmax)` against brute force: a negative `tmin` (hits behind
//! the origin count, as for a line through a point), ranges wholly behind the origin, empty
//! (`tmin == tmax`) and inverted ones, and the whole line; through every structure of
//! `AccelKind::ALL`, the binary BVH, and the engine ray by ray, in batches (the sampled pass
//! and the plain one), in packets, and for any hit.

mod common;
use common::{mesh_hit, same_closest};
use dynbvh::accel::{Accel, AccelKind};
use dynbvh::bvh::{BuildParams, MeshBvh, brute_force_any, brute_force_closest};
use dynbvh::engine::{Engine, EngineConfig};
use dynbvh::geom::{Ray, shapes};
use glam::{Affine3A, Vec3};

#[test]
fn unusual_ranges_match_brute_force_everywhere() {
    let mesh = shapes::bumpy_sphere(3000);
    let mut structs: Vec<Box<dyn Accel>> = AccelKind::ALL.iter().map(|k| k.build(&mesh)).collect();
    structs.push(Box::new(MeshBvh::build(&mesh, &BuildParams::BINNED)));
    let mut engine = Engine::new(EngineConfig::default());
    let id = engine.add_mesh(mesh.positions.clone(), mesh.indices.clone());
    engine.add_instance(id, Affine3A::IDENTITY);
    engine.update();
    let mut bad = Vec::new();
    let mut n = 0;
    for i in 0..300 {
        let a = i as f32 * 0.37;
        let o = Vec3::new(a.cos() * 0.3, a.sin() * 0.2, (a * 0.7).sin() * 0.1);
        let d = Vec3::new((a * 1.3).sin(), (a * 0.9).cos(), (a * 2.1).sin()).normalize();
        for (tmin, tmax) in [
            (-10.0, 10.0),
            (-10.0, 0.0),
            (-0.5, -0.1),
            (0.3, 0.3),
            (0.5, 0.2),
            (-f32::INFINITY, f32::INFINITY),
            (0.0, 0.0),
            (-0.0, 1e-30),
        ] {
            let r = Ray::with_range(o, d, tmin, tmax);
            let want = brute_force_closest(&mesh, &r);
            let any = brute_force_any(&mesh, &r);
            n += usize::from(want.is_some());
            for s in &structs {
                let got = s.closest_hit(&r);
                if !same_closest(&mesh, &r, want, got) || s.any_hit(&r) != any {
                    bad.push(format!(
                        "{} [{tmin},{tmax}) ray {i}: {want:?} vs {got:?}",
                        s.name()
                    ));
                }
            }
            let got = engine.closest_hit(&r).map(mesh_hit);
            if !same_closest(&mesh, &r, want, got) || engine.any_hit(&r) != any {
                bad.push(format!(
                    "engine [{tmin},{tmax}) ray {i}: {want:?} vs {got:?}"
                ));
            }
        }
    }
    // Batches and packets: a coherent set from one side (packets group neighbouring rays),
    // ranges scaled to the sphere's distance from it.
    let mut rays = Vec::new();
    for i in 0..256 {
        let a = i as f32 * 0.37;
        let o = Vec3::new(0.1 * (a * 0.1).cos(), 0.1 * (a * 0.1).sin(), 3.0);
        let d = Vec3::new(
            0.02 * ((i % 16) as f32 - 8.0),
            0.02 * ((i / 16) as f32 - 8.0),
            -1.0,
        )
        .normalize();
        let (tmin, tmax) = [
            (-10.0, 10.0),
            (-10.0, 0.0),
            (-3.5, -1.0),
            (2.5, 2.5),
            (3.0, 2.0),
            (-f32::INFINITY, f32::INFINITY),
            (0.0, 0.0),
            (2.0, 2.9),
        ][i % 8];
        rays.push(Ray::with_range(o, d, tmin, tmax));
    }
    let hitting = rays
        .iter()
        .filter(|r| brute_force_closest(&mesh, r).is_some())
        .count();
    assert!(hitting > 64, "{hitting} batch rays hit");
    let mut out = vec![None; rays.len()];
    for pass in 0..3 {
        match pass {
            0 => {
                engine.trace_closest(&rays, &mut out);
            }
            1 => {
                engine.trace_closest_packets(&rays, &mut out);
            }
            _ => engine.closest_hit_batch(&rays, &mut out),
        }
        for (i, r) in rays.iter().enumerate() {
            let want = brute_force_closest(&mesh, r);
            let got = out[i].map(mesh_hit);
            if !same_closest(&mesh, r, want, got) {
                bad.push(format!(
                    "batch pass {pass} ray {i} [{}, {}): {want:?} vs {got:?}",
                    r.tmin, r.tmax
                ));
            }
        }
    }
    let mut anys = vec![false; rays.len()];
    engine.any_hit_batch(&rays, &mut anys);
    for (i, r) in rays.iter().enumerate() {
        if anys[i] != brute_force_any(&mesh, r) {
            bad.push(format!("any batch ray {i}"));
        }
    }
    assert!(n > 300, "{n} single rays hit");
    assert!(
        bad.is_empty(),
        "{} failures:\n{}",
        bad.len(),
        bad[..bad.len().min(5)].join("\n")
    );
}
