//! The `bench` command end to end: the per-frame CSV, the JSON report, the four charts (SVG and
//! PNG), and on the two animations where refitting fails (explode, swap) the refit policy's SAH
//! ratio climbing while the rebuild-capable policies rebuild. No timing is asserted: only what
//! the frames and the policies' rules decide.

mod cli_util;
use cli_util::{animation, dynbvh, ok};
use serde_json::Value;

/// Runs `bench` on an animation with `extra` arguments, `--out` a fresh folder and `--json`;
/// returns the printed report and the folder.
/// The per-frame fields the issue asks for, in the CSV header and in the JSON's `per_frame`.
const FRAME_FIELDS: [&str; 8] = [
    "policy",
    "frame",
    "action",
    "update_ms",
    "trace_ms",
    "sah",
    "sah_ratio",
    "mrays",
];

fn bench(file: &str, tag: &str, extra: &[&str]) -> (Value, cli_util::TmpDir) {
    let out = cli_util::tmp_dir("bench", tag);
    let path = animation(file);
    let out_s = out.to_string_lossy().into_owned();
    let mut args = vec!["bench", path.as_str(), "--out", out_s.as_str(), "--json"];
    args.extend(extra);
    let o = dynbvh(&args);
    assert!(
        o.status.success(),
        "dynbvh {args:?} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let json: Value = serde_json::from_slice(&o.stdout).expect("--json prints JSON");
    (json, out)
}

fn policy<'a>(report: &'a Value, name: &str) -> &'a Value {
    report["policies"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["policy"] == name)
        .unwrap_or_else(|| panic!("no policy {name}"))
}

/// Largest `max_sah_ratio` of a policy's frames.
fn max_sah_ratio(report: &Value, name: &str) -> f64 {
    report["per_frame"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["policy"] == name)
        .map(|r| r["max_sah_ratio"].as_f64().unwrap())
        .fold(0.0, f64::max)
}

#[test]
fn bench_writes_csv_json_and_charts() {
    let (json, out) = bench(
        "swap.glb",
        "outputs",
        &["--frames", "24", "--size", "48x48"],
    );

    // CSV: the header names the fields, every row has as many fields, and every
    // policy has one row per frame.
    let csv = std::fs::read_to_string(out.join("frames.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    for field in FRAME_FIELDS {
        assert!(
            header.contains(&field),
            "CSV header lacks {field}: {header:?}"
        );
    }
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert!(rows.iter().all(|r| r.len() == header.len()));
    let policies = json["policies"].as_array().unwrap();
    assert_eq!(rows.len(), 24 * policies.len());

    // JSON: per policy the totals, rebuild count and oracle ratio; one default.
    for p in policies {
        assert!(p["total_ms"].as_f64().unwrap() > 0.0, "{p}");
        assert!(p["rebuilds"].as_u64().is_some(), "{p}");
        assert!(p["oracle_ratio"].as_f64().unwrap() > 0.0, "{p}");
        assert!(p["default"].is_boolean());
    }
    assert_eq!(
        policies.iter().filter(|p| p["default"] == true).count(),
        1,
        "exactly one default policy"
    );
    let oracle = &json["oracle"];
    assert!(oracle["alpha"].as_f64().unwrap() >= 0.0);
    for k in [
        "model_refit_ms",
        "measured_refit_ms",
        "model_rebuild_ms",
        "measured_rebuild_ms",
    ] {
        assert!(oracle[k].as_f64().unwrap() > 0.0, "oracle.{k}");
    }
    // The written report is the printed one.
    let written: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(
        written["policies"].as_array().unwrap().len(),
        policies.len()
    );
    for f in FRAME_FIELDS {
        assert!(json["per_frame"][0].get(f).is_some(), "per_frame lacks {f}");
    }
    // The sample's share is over the passes it is taken in, each frame's first, which is
    // never faster than the fastest pass the trace time counts.
    for p in policies {
        let name = p["policy"].as_str().unwrap();
        let frames: Vec<&Value> = json["per_frame"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| r["policy"] == name)
            .collect();
        let sum = |k: &str| frames.iter().map(|r| r[k].as_f64().unwrap()).sum::<f64>();
        for r in &frames {
            let (first, best) = (
                r["first_pass_ms"].as_f64().unwrap(),
                r["trace_ms"].as_f64().unwrap(),
            );
            assert!(
                first >= best,
                "{name} frame {}: first pass {first} < fastest {best}",
                r["frame"]
            );
        }
        let (sample, first) = (sum("sample_ms"), sum("first_pass_ms"));
        let share = p["sample_share"].as_f64().unwrap();
        let want = if first > sample {
            sample / (first - sample)
        } else {
            0.0
        };
        assert!(
            (share - want).abs() <= 1e-9 * want.max(1.0),
            "{name}: {share} against {want}"
        );
    }
    assert!(
        policies
            .iter()
            .any(|p| p["sample_share"].as_f64().unwrap() > 0.0),
        "the default samples"
    );

    // The four charts, as SVG and as PNG that decodes to more than one colour.
    for stem in [
        "sah_ratio",
        "frame_time",
        "speed_accuracy",
        "predicted_vs_measured",
    ] {
        let svg = std::fs::read_to_string(out.join(format!("{stem}.svg"))).unwrap();
        assert!(svg.contains("<svg") && svg.len() > 1000, "{stem}.svg");
        let png = image::open(out.join(format!("{stem}.png")))
            .unwrap_or_else(|e| panic!("{stem}.png: {e}"))
            .to_rgb8();
        assert!(png.width() > 100 && png.height() > 100, "{stem}.png size");
        let first = *png.get_pixel(0, 0);
        let colours = png.pixels().filter(|&&p| p != first).count();
        assert!(colours > 1000, "{stem}.png is nearly one colour");
    }
    let _ = std::fs::remove_dir_all(&out);
}

/// `field` of a policy's frames, in frame order.
fn series(report: &Value, name: &str, field: &str) -> Vec<f64> {
    report["per_frame"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["policy"] == name)
        .map(|r| r[field].as_f64().unwrap())
        .collect()
}

fn rebuilds(report: &Value, name: &str) -> u64 {
    policy(report, name)["rebuilds"].as_u64().unwrap()
}

/// Where refitting fails, the report shows it: on `explode.glb` the refitted tree ends up 1.5
/// times worse than a fresh build (its ratio to its own first build stays near 1.17, because a
/// fresh tree of the scattered triangles costs less too), on `swap.glb` its ratio to its last
/// build reaches 3.9. Rebuild counts are asserted only for the policies whose rule does not
/// depend on timing (always-rebuild, periodic, threshold), and for amortized on explode, where
/// the degradation costs many times a rebuild at this ray count.
#[test]
fn refit_degrades_and_policies_rebuild_on_explode_and_swap() {
    let frames = ["--frames", "24", "--no-builders", "--no-tlas-compare"];

    let mut args = frames.to_vec();
    args.extend(["--size", "128x128"]);
    let (explode, out) = bench("explode.glb", "explode", &args);
    let fresh = series(&explode, "refit", "fresh_ratio");
    assert_eq!(fresh.len(), 24);
    assert!(
        fresh[0] < 1.1,
        "explode: refit starts near a fresh tree: {fresh:?}"
    );
    let peak = fresh.iter().copied().fold(0.0, f64::max);
    assert!(
        peak > 1.4,
        "explode: refit's ratio to a fresh build climbs: {fresh:?}"
    );
    assert!(max_sah_ratio(&explode, "refit") > 1.1);
    assert_eq!(rebuilds(&explode, "refit"), 0);
    assert_eq!(rebuilds(&explode, "rebuild"), 24);
    assert_eq!(rebuilds(&explode, "periodic:8"), 3);
    assert!(
        rebuilds(&explode, "amortized") >= 1,
        "explode: amortized never rebuilt"
    );
    let _ = std::fs::remove_dir_all(&out);

    // Under the SAH measure `threshold:R` compares the ratio to the last build (under the
    // ray-work measure, the estimated degradation against a fresh tree, which stays low on swap).
    let mut args = frames.to_vec();
    args.extend(["--size", "48x48", "--cost", "sah"]);
    let (swap, out) = bench("swap.glb", "swap", &args);
    let ratio = series(&swap, "refit", "max_sah_ratio");
    assert!(ratio[0] < 1.2, "swap: {ratio:?}");
    assert!(
        max_sah_ratio(&swap, "refit") > 2.5,
        "swap: refit's SAH ratio climbs: {ratio:?}"
    );
    assert_eq!(rebuilds(&swap, "refit"), 0);
    assert_eq!(rebuilds(&swap, "rebuild"), 24);
    assert_eq!(rebuilds(&swap, "periodic:8"), 3);
    assert!(rebuilds(&swap, "threshold:1.3") >= 1);
    // The rebuilds are marked on the SAH chart's frames.
    assert!(
        series(&swap, "threshold:1.3", "rebuilds")
            .iter()
            .any(|&r| r > 0.0)
    );
    let _ = std::fs::remove_dir_all(&out);
}

/// `bench --all` over the files of `dir`, no generated animations, with `extra` arguments.
fn sweep(dir: &str, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["bench", "--all", "--dir", dir, "--generated", "none"];
    args.extend_from_slice(extra);
    dynbvh(&args)
}

/// `bench --all` runs every animation of every file, lists a file that does not load with the
/// reason, prints a conclusion computed from its rows, and exits non-zero.
#[test]
fn sweep_lists_failures_and_exits_non_zero() {
    let dir = cli_util::tmp_dir("bench", "sweep");
    std::fs::write(dir.join("broken.glb"), b"glTF not really").unwrap();
    std::fs::copy(animation("swap.glb"), dir.join("swap.glb")).unwrap();
    let dir_s = dir.to_string_lossy().into_owned();
    let o = sweep(&dir_s, &["--frames", "4", "--size", "16x16"]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(!o.status.success(), "a failed file must fail the sweep");
    assert!(
        stdout.contains("FAILED") && stdout.contains("broken.glb"),
        "{stdout}"
    );
    // The name column fits the longest name: the whole path is printed, not cut.
    assert!(
        stdout.contains(&format!("{}/swap.glb [swap]", dir.display())),
        "{stdout}"
    );
    assert!(stdout.contains("Conclusion"), "{stdout}");
    assert!(stdout.contains("lowest worst ratio"), "{stdout}");
    assert!(stdout.contains("rows with a deforming mesh"), "{stdout}");
    assert!(stdout.contains("default amortized"), "{stdout}");
    assert!(!stdout.contains("Why amortized is the default"), "{stdout}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The sweep's conclusion judges by the modelled totals: its mean and worst per policy are
/// those of the rows' modelled ratios, and it reports the default's ray sample.
#[test]
fn the_sweep_concludes_on_the_modelled_totals() {
    let dir = cli_util::tmp_dir("bench", "sweep_modelled");
    std::fs::copy(animation("swap.glb"), dir.join("swap.glb")).unwrap();
    std::fs::copy(animation("tube.glb"), dir.join("tube.glb")).unwrap();
    let dir_s = dir.to_string_lossy().into_owned();
    let prices = concat!(env!("CARGO_MANIFEST_DIR"), "/docs/prices.json");
    let o = sweep(
        &dir_s,
        &[
            "--frames",
            "12",
            "--size",
            "48x48",
            "--prices",
            prices,
            "--no-tlas-compare",
            "--no-builders",
            "--json",
        ],
    );
    let json: Value = serde_json::from_slice(ok(&o).as_bytes()).expect("--json prints JSON");
    let c = &json["conclusion"];
    assert_eq!(c["modelled"], true, "{c}");
    let reports = json["reports"].as_array().unwrap();
    assert_eq!(reports.len(), 2);
    for v in c["policies"].as_array().unwrap() {
        let name = v["policy"].as_str().unwrap();
        let ratios: Vec<f64> = reports
            .iter()
            .map(|r| {
                let p = r["policies"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .find(|p| p["policy"] == name)
                    .unwrap();
                p["oracle_ratio_modelled"].as_f64().unwrap()
            })
            .collect();
        let mean = ratios.iter().sum::<f64>() / ratios.len() as f64;
        let worst = ratios.iter().copied().fold(0.0, f64::max);
        assert!(
            (v["mean_ratio"].as_f64().unwrap() - mean).abs() < 1e-12,
            "{name}: {v}"
        );
        assert_eq!(v["worst_ratio"].as_f64().unwrap(), worst, "{name}");
        let over = ratios.iter().filter(|&&r| r > 1.05).count();
        assert_eq!(v["over_margin"].as_array().unwrap().len(), over, "{name}");
    }
    let sample = &c["default_sample"];
    assert!(sample["rows"].as_u64().unwrap() >= 1, "{c}");
    assert!(sample["worst_share"].as_f64().unwrap() >= sample["mean_share"].as_f64().unwrap());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `bench --frames A..B` runs the frames of a range as `render --frames A..B` does (built at
/// A, updated through B - 1), numbers them as render does, and `--out` keeps the printed table
/// as summary.txt.
#[test]
fn a_frame_range_is_numbered_as_render_numbers_it_and_the_summary_is_written() {
    let out = cli_util::tmp_dir("bench", "range");
    let out_s = out.to_string_lossy().into_owned();
    let swap = animation("swap.glb");
    let args = [
        "bench",
        &swap,
        "--frames",
        "5..12",
        "--fps",
        "12",
        "--size",
        "16x16",
        "--no-builders",
        "--no-tlas-compare",
        "-p",
        "refit",
        "-p",
        "amortized",
        "--out",
        &out_s,
    ];
    let stdout = cli_util::ok(&dynbvh(&args));
    let summary = std::fs::read_to_string(out.join("summary.txt")).unwrap();
    assert_eq!(summary, stdout, "summary.txt is the printed summary");
    assert!(stdout.contains("frames 5..12"), "{stdout}");
    let csv = std::fs::read_to_string(out.join("frames.csv")).unwrap();
    for p in ["refit", "amortized"] {
        let frames: Vec<usize> = csv
            .lines()
            .skip(1)
            .map(|l| l.split(',').collect::<Vec<_>>())
            .filter(|c| c[0] == p)
            .map(|c| c[1].parse().unwrap())
            .collect();
        assert_eq!(frames, (6..12).collect::<Vec<_>>(), "{p}: {csv}");
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["frames"], 6);
    assert_eq!(report["per_frame"][0]["frame"], 6);

    // A range past the animation's end is refused with the frames it has; an empty one too.
    let o = dynbvh(&["bench", &swap, "--frames", "5..900", "--size", "8x8"]);
    assert!(!o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("frames 0.."),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        !dynbvh(&["bench", &swap, "--frames", "7..7"])
            .status
            .success()
    );
    let _ = std::fs::remove_dir_all(&out);
}

/// Without the oracle, the ratios to it were not computed: the tables print `–`, not 0.
#[test]
fn values_not_computed_print_as_a_dash() {
    let tube = animation("tube.glb");
    let stdout = cli_util::ok(&dynbvh(&[
        "bench",
        &tube,
        "--frames",
        "4",
        "--size",
        "16x16",
        "--no-builders",
        "--no-tlas-compare",
        "--no-oracle",
        "-p",
        "refit",
        "-p",
        "rebuild",
    ]));
    let wall = stdout
        .lines()
        .skip_while(|l| !l.starts_with("wall clock"))
        .nth(1)
        .unwrap_or_else(|| panic!("a wall-clock table:\n{stdout}"));
    assert!(wall.ends_with("/oracle"), "{wall}");
    for p in ["refit", "rebuild"] {
        let row = stdout
            .lines()
            .skip_while(|l| !l.starts_with("wall clock"))
            .find(|l| l.starts_with(&format!("{p} ")))
            .unwrap_or_else(|| panic!("a {p} row:\n{stdout}"));
        let cells: Vec<&str> = row.split_whitespace().collect();
        // max fresh and /oracle need the oracle's builds.
        assert_eq!(cells[cells.len() - 2..], ["\u{2013}", "\u{2013}"], "{row}");
    }
    assert!(!stdout.contains(" 0.000 "), "{stdout}");
}

/// `build-bench --methods clip-aware[K]` on an animation: a tree built over K poses of the
/// clip, exact at rest like every other builder, and a different tree from the plain build;
/// a file without an animation, or a bad pose count, is a clear error.
#[test]
fn build_bench_builds_clip_aware_trees_of_an_animation() {
    let path = animation("tube.glb");
    let args = [
        "build-bench",
        path.as_str(),
        "--methods",
        "binned16,clip-aware,clip-aware2",
        "--runs",
        "1",
        "--no-wide",
        "--ray-budget",
        "4096",
        "--json",
    ];
    let o = dynbvh(&args);
    let rows: Value = serde_json::from_slice(ok(&o).as_bytes()).expect("--json prints JSON");
    let rows = rows.as_array().unwrap();
    let sah = |method: &str| {
        let mine: Vec<&Value> = rows.iter().filter(|r| r["method"] == method).collect();
        assert_eq!(mine.len(), 2, "{method}: a row per ray set");
        for r in &mine {
            assert_eq!(r["mismatches"], 0, "{method}: {r}");
            assert!(r["checked"].as_u64().unwrap() > 0, "{method}: {r}");
        }
        mine[0]["sah"].as_f64().unwrap()
    };
    let plain = sah("binned16");
    assert_ne!(
        sah("clip-aware4"),
        plain,
        "the clip's poses change the tree"
    );
    sah("clip-aware2");
    let dir = cli_util::tmp_dir("bench", "clip_aware");
    let obj = dir.join("one.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    for (file, method, says) in [
        (
            obj.to_string_lossy().into_owned(),
            "clip-aware",
            "needs an animated glTF",
        ),
        (path.clone(), "clip-aware9", "from 1 to 8"),
    ] {
        let o = dynbvh(&["build-bench", file.as_str(), "--methods", method]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(says), "{method}: {err}");
    }
}

/// `--packets` traces each frame's rays as packets and says so; what the modelled measure
/// prices does not change with it (the judge counts every ray of a 1,024-ray frame, ray by
/// ray, on the same trees): always-refit and always-rebuild total the same as ray by ray,
/// and refitting still degrades on the explosion.
#[test]
fn bench_traces_packets_and_models_the_same_work() {
    let prices = concat!(env!("CARGO_MANIFEST_DIR"), "/docs/prices.json");
    #[rustfmt::skip]
    let common = [
        "--rays", "1024", "--frames", "6", "-p", "refit", "-p", "rebuild", "-p", "amortized",
        "--no-builders", "--no-tlas-compare", "--repeats", "1", "--prices", prices,
    ];
    let (single, _d1) = bench("explode.glb", "single", &common);
    let mut extra = common.to_vec();
    extra.push("--packets");
    let (packets, _d2) = bench("explode.glb", "packets", &extra);
    assert_eq!(single["packets"], false);
    assert_eq!(packets["packets"], true);
    for name in ["refit", "rebuild"] {
        let (a, b) = (
            policy(&single, name)["modelled_ms"].as_f64().unwrap(),
            policy(&packets, name)["modelled_ms"].as_f64().unwrap(),
        );
        assert!(a > 0.0 && a == b, "{name}: {a} ray by ray, {b} as packets");
    }
    assert!(max_sah_ratio(&packets, "refit") > 1.1);
    let t = packets["degradation"]["time_ratio"].as_f64().unwrap();
    assert!(t.is_finite() && t > 0.0, "time ratio {t}");
}
