//! InterpolationTest: each node's local transform at chosen times against values computed by
//! hand from the keyframes (read out of the file by inspection and written here).

mod anim_util;

use anim_util::assert_near;
use dynbvh::anim::{Interpolation, Sampler, Scene, TimeMode};
use glam::{Mat4, Quat, Vec3};

/// Hermite basis at `s`: (h00, h10, h01, h11).
fn hermite(s: f32) -> (f32, f32, f32, f32) {
    let (s2, s3) = (s * s, s * s * s);
    (
        2.0 * s3 - 3.0 * s2 + 1.0,
        s3 - 2.0 * s2 + s,
        -2.0 * s3 + 3.0 * s2,
        s3 - s2,
    )
}

struct Fixture {
    scene: Scene,
}

impl Fixture {
    fn load() -> Option<Fixture> {
        let path = anim_util::sample("InterpolationTest/InterpolationTest.glb")?;
        let (scene, _) = Scene::load(path).unwrap();
        Some(Fixture { scene })
    }

    /// Local (= world: all are roots) matrix of `node` under animation `name` at `t`.
    fn at(&self, name: &str, node: usize, t: f32, mode: TimeMode) -> Mat4 {
        let a = self.scene.find_animation(name).unwrap();
        let mut p = self.scene.poser(Some(a)).unwrap().with_time_mode(mode);
        p.pose(t);
        assert!(self.scene.nodes[node].parent.is_none());
        p.world_matrices()[node]
    }

    fn trs(&self, name: &str, node: usize, t: f32) -> (Vec3, Quat, Vec3) {
        let (s, r, tr) = self
            .at(name, node, t, TimeMode::Clamp)
            .to_scale_rotation_translation();
        (s, r, tr)
    }
}

fn assert_quat(a: Quat, b: Quat, what: &str) {
    assert!(a.dot(b).abs() > 1.0 - 1e-6, "{what}: got {a}, want {b}");
}

const SCALE_TIMES: [f32; 5] = [0.041_666_668, 0.416_666_66, 0.875, 1.25, 1.666_666_6];
const ROT_TIMES: [f32; 5] = [0.0, 0.416_666_66, 0.875, 1.25, 1.708_333_4];
const TRANS_TIMES: [f32; 5] = [0.0, 0.416_666_66, 0.833_333_3, 1.25, 1.666_666_6];

#[test]
fn step_scale() {
    let Some(f) = Fixture::load() else { return };
    // Keys: 1, 0.5, 1, 0.5, 1 (uniform scale); first key at 1/24 s.
    for (t, want) in [
        (0.0, 1.0),   // before the first key: first value
        (0.3, 1.0),   // holds key 0
        (0.42, 0.5),  // just after key 1
        (0.875, 1.0), // exactly at key 2
        (1.3, 0.5),
        (9.0, 1.0), // after the last key (clamp mode)
    ] {
        let (s, _, tr) = f.trs("Step Scale", 0, t);
        assert_near(s, Vec3::splat(want), 1e-6, &format!("step scale t={t}"));
        assert_near(tr, Vec3::ZERO, 1e-6, "untouched translation");
    }
}

#[test]
fn linear_scale() {
    let Some(f) = Fixture::load() else { return };
    let t = 0.6;
    let s = (t - SCALE_TIMES[1]) / (SCALE_TIMES[2] - SCALE_TIMES[1]);
    let want = 0.5 + s * (1.0 - 0.5);
    let (sc, _, tr) = f.trs("Linear Scale", 3, t);
    assert_near(sc, Vec3::splat(want), 1e-5, "linear scale");
    // The node's rest translation stays.
    assert_near(
        tr,
        Vec3::new(-3.296_329_7, 0.0, 6.461_143_5e-5),
        1e-6,
        "rest t",
    );
    let (sc, _, _) = f.trs("Linear Scale", 3, 0.01);
    assert_near(sc, Vec3::ONE, 1e-6, "before first key");
}

#[test]
fn cubic_scale() {
    let Some(f) = Fixture::load() else { return };
    // Values 1, 0.5, 1, 0.5, 1 with all tangents zero.
    let t = 0.2;
    let s = (t - SCALE_TIMES[0]) / (SCALE_TIMES[1] - SCALE_TIMES[0]);
    let (h00, _, h01, _) = hermite(s);
    let want = h00 * 1.0 + h01 * 0.5;
    let (sc, _, _) = f.trs("CubicSpline Scale", 4, t);
    assert_near(sc, Vec3::splat(want), 1e-5, "cubic scale");
    let (sc, _, _) = f.trs("CubicSpline Scale", 4, 5.0);
    assert_near(sc, Vec3::ONE, 1e-6, "after last key");
    // Before the first key (1/24 s): key 0's value 1, not its in-tangent (0, which would
    // flatten the cube).
    for t in [0.0, 0.02] {
        let (sc, _, _) = f.trs("CubicSpline Scale", 4, t);
        assert_near(sc, Vec3::ONE, 1e-6, &format!("before first key t={t}"));
    }
}

/// A CUBICSPLINE sampler whose keys start at 1 s, with in-tangents, values and out-tangents
/// all different: before the first key it gives key 0's value, after the last the last value,
/// and between keys the Hermite curve with tangents scaled by the key interval.
#[test]
fn cubic_sampler_clamps_to_values_not_tangents() {
    let s = Sampler {
        interpolation: Interpolation::CubicSpline,
        times: vec![1.0, 3.0],
        // (in, value, out) per key, width 2.
        values: vec![
            7.0, -7.0, 2.0, -2.0, 5.0, -5.0, 11.0, -11.0, 4.0, -4.0, 13.0, -13.0,
        ],
        width: 2,
    };
    let mut out = [0.0; 2];
    for t in [-5.0, 0.0, 0.999, 1.0] {
        s.sample(t, false, &mut out);
        assert_eq!(out, [2.0, -2.0], "t={t}");
    }
    for t in [3.0, 3.5, 100.0] {
        s.sample(t, false, &mut out);
        assert_eq!(out, [4.0, -4.0], "t={t}");
    }
    // t = 1.5: s = 0.25 over an interval of 2 s; out-tangent of key 0 is 5, in-tangent of
    // key 1 is 11.
    let (h00, h10, h01, h11) = hermite(0.25);
    let want = h00 * 2.0 + h10 * 2.0 * 5.0 + h01 * 4.0 + h11 * 2.0 * 11.0;
    s.sample(1.5, false, &mut out);
    assert!((out[0] - want).abs() < 1e-5, "{} vs {want}", out[0]);
    assert!((out[1] + want).abs() < 1e-5, "{} vs {}", out[1], -want);
}

#[test]
fn step_rotation() {
    let Some(f) = Fixture::load() else { return };
    let (_, r, _) = f.trs("Step Rotation", 5, 0.5);
    assert_quat(
        r,
        Quat::from_xyzw(0.0, 0.0, -0.382_683_46, 0.923_879_56),
        "step rotation",
    );
    let (_, r, _) = f.trs("Step Rotation", 5, 2.0);
    assert_quat(r, Quat::from_xyzw(0.0, 0.0, -1.0, 0.0), "after last key");
}

#[test]
fn linear_rotation_is_slerp() {
    let Some(f) = Fixture::load() else { return };
    // Keys are rotations of 0, -45, -90, -135, -180 degrees about z.
    for (t, k) in [(0.2f32, 0usize), (1.5, 3)] {
        let s = (t - ROT_TIMES[k]) / (ROT_TIMES[k + 1] - ROT_TIMES[k]);
        let angle = -(k as f32 + s) * 45f32.to_radians();
        let want = Quat::from_xyzw(0.0, 0.0, (angle / 2.0).sin(), (angle / 2.0).cos());
        let (_, r, _) = f.trs("Linear Rotation", 7, t);
        assert_quat(r, want, &format!("slerp t={t}"));
    }
}

#[test]
fn cubic_rotation() {
    let Some(f) = Fixture::load() else { return };
    // Key 0: value (0,0,0,1), out-tangent (0,0,0,1).
    // Key 1: in-tangent (0,0,-0.047890902,0.99885267), value (0,0,-0.38268346,0.92387956).
    let t = 0.2;
    let dt = ROT_TIMES[1] - ROT_TIMES[0];
    let s = t / dt;
    let (h00, h10, h01, h11) = hermite(s);
    let tan = [-0.047_890_9_f32, 0.998_852_7];
    // Key 0's value and out-tangent have z = 0 and w = 1.
    let z = h01 * -0.382_683_46 + h11 * dt * tan[0];
    let w = h00 + h10 * dt + h01 * 0.923_879_56 + h11 * dt * tan[1];
    let want = Quat::from_xyzw(0.0, 0.0, z, w).normalize();
    let (_, r, _) = f.trs("CubicSpline Rotation", 6, t);
    assert_quat(r, want, "cubic rotation");
}

#[test]
fn translations() {
    let Some(f) = Fixture::load() else { return };
    // Step: y keys 6.665226, 10, 6, 10, 6.
    let (_, _, tr) = f.trs("Step Translation", 8, 0.45);
    assert_near(
        tr,
        Vec3::new(0.0, 6.665_226_5, 0.0),
        1e-6,
        "step before key 1",
    );
    let (_, _, tr) = f.trs("Step Translation", 8, 0.46);
    assert_near(tr, Vec3::new(0.0, 10.0, 0.0), 1e-6, "step after key 1");
    // Cubic, zero tangents: halfway between keys 1 (y 10) and 2 (y 6) is the average.
    let t = (TRANS_TIMES[1] + TRANS_TIMES[2]) / 2.0;
    let (_, _, tr) = f.trs("CubicSpline Translation", 9, t);
    assert_near(tr, Vec3::new(3.305_18, 8.0, 0.0), 1e-5, "cubic halfway");
    // Linear: x stays, y goes 10 -> 6.
    let t = 1.0;
    let s = (t - TRANS_TIMES[2]) / (TRANS_TIMES[3] - TRANS_TIMES[2]);
    let (_, _, tr) = f.trs("Linear Translation", 10, t);
    assert_near(
        tr,
        Vec3::new(-3.297_580_7, 6.0 + s * 4.0, 0.0),
        1e-5,
        "linear",
    );
}

#[test]
fn looping_wraps_beyond_the_duration() {
    let Some(f) = Fixture::load() else { return };
    let a = f.scene.find_animation("Linear Translation").unwrap();
    let d = f.scene.animations[a].duration;
    assert_eq!(d, TRANS_TIMES[4]);
    // Looping: d + 1 s is t = 1 s, between key 2 (y 6 at 0.8333 s) and key 3 (y 10 at 1.25 s).
    let looped = f.at("Linear Translation", 10, d + 1.0, TimeMode::Loop);
    let s = (1.0 - TRANS_TIMES[2]) / (TRANS_TIMES[3] - TRANS_TIMES[2]);
    assert_near(
        looped.w_axis.truncate(),
        Vec3::new(-3.297_580_7, 6.0 + s * 4.0, 0.0),
        1e-4,
        "looped",
    );
    // Clamping after the last key: the last key's value (-3.2975807, 6, 0), by hand.
    for t in [d, d + 1.0, 50.0] {
        let clamped = f.at("Linear Translation", 10, t, TimeMode::Clamp);
        assert_near(
            clamped.w_axis.truncate(),
            Vec3::new(-3.297_580_7, 6.0, 0.0),
            1e-6,
            &format!("clamped t={t}"),
        );
    }
}

#[test]
fn linear_after_the_last_key_holds_the_last_value() {
    let Some(f) = Fixture::load() else { return };
    // Linear Rotation's last key (1.7083 s): -180 degrees about z, (0, 0, -1, ~0).
    let (_, r, _) = f.trs("Linear Rotation", 7, 9.0);
    assert_quat(
        r,
        Quat::from_xyzw(0.0, 0.0, -1.0, 0.0),
        "rotation after last key",
    );
    // Linear Scale's last key (1.6667 s) is 1; just before it the scale is still below 1.
    let (sc, _, _) = f.trs("Linear Scale", 3, 9.0);
    assert_near(sc, Vec3::ONE, 1e-6, "scale after last key");
    let t = 1.5;
    let s = (t - SCALE_TIMES[3]) / (SCALE_TIMES[4] - SCALE_TIMES[3]);
    let (sc, _, _) = f.trs("Linear Scale", 3, t);
    assert_near(
        sc,
        Vec3::splat(0.5 + s * 0.5),
        1e-5,
        "scale between the last keys",
    );
    // Linear Translation before its first key is not reachable (key 0 is at 0 s); after its
    // last key see `looping_wraps_beyond_the_duration`.
}

#[test]
fn animated_node_moves_its_triangles_in_the_flattened_mesh() {
    let Some(f) = Fixture::load() else { return };
    let a = f.scene.find_animation("Linear Translation").unwrap();
    let inst = f.scene.instances.iter().position(|i| i.node == 10).unwrap();
    let range = f.scene.instances[inst].triangles.clone();
    assert_eq!(f.scene.instance_of_triangle(range.start), Some(inst));
    assert_eq!(f.scene.instance_of_triangle(range.end - 1), Some(inst));
    let m0 = f.scene.flatten_at(Some(a), 0.4166).unwrap();
    let m1 = f.scene.flatten_at(Some(a), 0.8333).unwrap();
    let dy = m1.triangle(range.start)[0] - m0.triangle(range.start)[0];
    assert!((dy.y - -4.0).abs() < 1e-2, "{dy}");
    // Other instances did not move.
    let other = f.scene.instances.iter().position(|i| i.node == 0).unwrap();
    let r = f.scene.instances[other].triangles.start;
    assert_eq!(m0.triangle(r), m1.triangle(r));
}
