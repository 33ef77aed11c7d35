//! The oracle over refit, rebuild and the rungs (optimise, partial rebuild): every schedule of
//! a short clip within its moves run for real on the engine (each frame's action scripted with
//! `Engine::force_next`), its modelled cost counted on the same sampled rays: the oracle's
//! table gives each run's cost, its total is the least of them, and the bench reports it.

mod common;

use dynbvh::anim::Scene;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::oracle::Move;
use dynbvh::engine::policy::{LADDER_OPTIMIZE, LADDER_PARTIAL};
use dynbvh::engine::source::FrameSource;
use dynbvh::engine::{Decision, EngineConfig, Policy, Prices, Timing};
use dynbvh::report::all_pairs;
use dynbvh::report::frame_bench::{self, Options, RaySpec};
use dynbvh::report::rays::camera_rays;
use std::path::PathBuf;

/// Rays each sampled ray stands for: many, so that tracing weighs enough against the updates
/// for the best schedule to use a rung on these small meshes.
const SCALE: f64 = 1000.0;

fn scene(file: &str) -> Scene {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("animations")
        .join(file);
    Scene::load(&path).unwrap().0
}

/// Every schedule of `n` frames over refit, rebuild and `rungs` rungs with at most one rung
/// between two rebuilds (frame 0: the build).
fn schedules(n: usize, rungs: usize) -> Vec<Vec<Move>> {
    let mut all = vec![(vec![Move::Rebuild], false)];
    for _ in 0..n {
        let mut next = Vec::new();
        for (s, restructured) in all {
            let mut push = |m: Move, r: bool| {
                let mut t = s.clone();
                t.push(m);
                next.push((t, r));
            };
            push(Move::Refit, restructured);
            push(Move::Rebuild, false);
            if !restructured {
                for k in 0..rungs {
                    push(Move::Rung(k), true);
                }
            }
        }
        all = next;
    }
    all.into_iter().map(|(s, _)| s).collect()
}

#[test]
fn the_rung_oracle_is_the_best_of_every_schedule_run() {
    for file in ["explode.glb", "swap.glb"] {
        let s = scene(file);
        let frames = 5;
        let prices = Prices::default();
        let config = EngineConfig {
            timing: Timing::Priced,
            prices,
            policy: Policy::Ladder,
            ..EngineConfig::default()
        };
        let mut src = GltfSource::new(&s, Some(0), FrameTimes::Count(frames)).unwrap();
        let rays = camera_rays(&src.build(0, config).bounds(), 40, 40);
        let m = src.deforming()[0];
        let sampled = common::shared_sample(&mut src, config, &rays, frames, SCALE);
        let rungs = [
            Decision::Optimize(LADDER_OPTIMIZE),
            Decision::Partial(LADDER_PARTIAL),
        ];
        let work = &all_pairs::measure(&mut src, config, &sampled, &prices, frames).work[0];
        let rung_costs =
            &all_pairs::measure_rungs(&mut src, config, &sampled, &prices, frames, &rungs)[0];
        let best = work.best_with_rungs(rung_costs);
        let mut least = f64::INFINITY;
        let mut runs = 0;
        for schedule in schedules(frames, rungs.len()) {
            let mut e = src.build(0, config);
            let mut total = 0.0;
            for (f, frame) in sampled.iter().enumerate().skip(1) {
                e.force_next(match schedule[f] {
                    Move::Refit => Decision::Refit,
                    Move::Rebuild => Decision::Rebuild,
                    Move::Rung(k) => rungs[k],
                });
                src.advance(&mut e, f);
                e.update();
                total += e.mesh_stats(m).model_ms;
                total += frame.replay_ms(&e, m, &prices);
            }
            let table = work
                .cost_with_rungs(rung_costs, &schedule)
                .expect("within the moves");
            assert!(
                (table - total).abs() <= 1e-9 * total,
                "{file} {schedule:?}: table {table} against the run's {total}"
            );
            least = least.min(total);
            runs += 1;
        }
        // Of the 4^5 schedules, those with at most one rung between rebuilds.
        assert_eq!(runs, 324);
        assert!(
            (best.cost_ms - least).abs() <= 1e-9 * least,
            "{file}: oracle {} against the best run {least}",
            best.cost_ms
        );
        // Here a rung pays: the best schedule takes one and beats refit-or-rebuild.
        assert!(
            best.moves.iter().any(|m| matches!(m, Move::Rung(_))),
            "{file}: {:?}",
            best.moves
        );
        assert!(best.cost_ms < work.best().cost_ms, "{file}");
    }
}

/// `bench --oracle-rungs`: the rung oracle is at or below the refit-or-rebuild one, and the
/// policies that make only its moves are at or above it.
#[test]
fn the_bench_reports_the_rung_oracle() {
    let s = scene("swap.glb");
    let mut src = GltfSource::new(&s, Some(0), FrameTimes::Count(8)).unwrap();
    let opts = Options {
        rays: RaySpec::Size(48, 48),
        builders: Vec::new(),
        tlas_compare: false,
        trace_repeats: 1,
        prices: Prices::default(),
        oracle_rungs: true,
        policies: vec![Policy::DEFAULT, Policy::Ladder, Policy::Partial(0.1)],
        ..Options::default()
    };
    let r = frame_bench::run(&mut src, &opts, |_| {});
    let o = &r.oracle_modelled;
    assert!(o.rungs_total_ms > 0.0);
    assert!(o.rungs_total_ms <= o.total_ms * (1.0 + 1e-12));
    assert_eq!(o.rungs, ["optimize:0.01", "partial:0.25", "partial:0.1"]);
    assert!(r.below_oracle.is_empty(), "{:?}", r.below_oracle);
    for p in &r.policies {
        assert!(p.oracle_rungs_ratio_modelled > 0.0, "{}", p.policy);
    }
    let d = r.policies.iter().find(|p| p.default).unwrap();
    assert!(d.oracle_rungs_ratio_modelled >= 1.0 - 1e-9);
}
