//! Golden pictures of small generated animations: block-averaged brightness, mean colour and
//! heat-map work counts of a few frames, compared with recorded values under tolerances wide
//! enough for float differences between machines and narrow enough to catch broken shading,
//! shadows, normals or traversal.
//!
//! After an intended change of the look, print the new values with
//! `DYNBVH_PRINT_GOLDEN=1 cargo test --release --test render_golden -- --nocapture` and paste
//! them below. Printing does not skip the checks: every value is printed and compared, and the
//! tests fail until the recorded values match.

use dynbvh::anim::Scene;
use dynbvh::anim::generate::{Kind, generate};
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::source::FrameSource;
use dynbvh::engine::{EngineConfig, Policy, Traversal};
use dynbvh::render::{
    Camera, EngineShading, FrameCounts, Renderer, Settings, Stage, animation_bounds,
};
use image::RgbImage;
use std::path::Path;

const W: u32 = 96;
const H: u32 = 72;
/// Blocks across and down of the brightness signature (6x6 pixels each).
const BX: u32 = 16;
const BY: u32 = 12;
/// Signature levels, one character each, darkest first.
const LEVELS: &[u8; 64] = b"0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz+/";

fn level(c: char) -> i32 {
    LEVELS
        .iter()
        .position(|&l| char::from(l) == c)
        .expect("signature character") as i32
}

fn scene(kind: Kind, triangles: usize) -> Scene {
    let g = generate(kind, triangles, 7);
    let name = format!("{}.glb", kind.name());
    Scene::from_slice(Path::new(&name), &g.glb, &Default::default())
        .expect("generated scenes load")
        .0
}

/// Renders frames `0..frames` of an 8-frame loop (always refitting, so the trees are the
/// same on every machine) and returns the image and counts of each frame in `keep`.
fn render(
    scene: &Scene,
    settings: Settings,
    ground: bool,
    keep: &[usize],
) -> Vec<(usize, RgbImage, FrameCounts)> {
    let mut src = GltfSource::new(scene, Some(0), FrameTimes::Count(8)).unwrap();
    let bounds = animation_bounds(scene, Some(0), src.times()).unwrap();
    let camera = Camera::framing(&bounds, W as f32 / H as f32);
    let stage = Stage::new(camera, &bounds, ground);
    // The golden work figures are the binary trees' (the wide ones visit other nodes; their
    // images are the same, `tests/render_packets.rs`).
    let config = EngineConfig {
        policy: Policy::Refit,
        traversal: Traversal::Binary,
        ..EngineConfig::default()
    };
    let mut engine = src.build(0, config);
    let mut shading = EngineShading::new();
    shading.refresh_all(&engine);
    let mut r = Renderer::new(settings);
    let mut img = RgbImage::new(1, 1);
    let mut out = Vec::new();
    let last = keep.iter().copied().max().unwrap_or(0);
    for f in 0..=last {
        if f > 0 {
            src.advance(&mut engine, f);
            engine.update();
            shading.refresh(&engine, src.deforming());
        }
        let c = r.render(&shading.tracer(&engine), &stage, &mut img);
        if keep.contains(&f) {
            out.push((f, img.clone(), c));
        }
    }
    out
}

/// Mean brightness of each block, quantised, one string per block row.
fn signature(img: &RgbImage) -> Vec<String> {
    let (bw, bh) = (img.width() / BX, img.height() / BY);
    (0..BY)
        .map(|by| {
            (0..BX)
                .map(|bx| {
                    let mut sum = 0u32;
                    for y in by * bh..(by + 1) * bh {
                        for x in bx * bw..(bx + 1) * bw {
                            let p = img.get_pixel(x, y).0;
                            sum +=
                                (u32::from(p[0]) * 3 + u32::from(p[1]) * 6 + u32::from(p[2])) / 10;
                        }
                    }
                    let mean = sum / (bw * bh);
                    char::from(LEVELS[(mean * 64 / 256) as usize])
                })
                .collect()
        })
        .collect()
}

fn mean_rgb(img: &RgbImage) -> [f64; 3] {
    let mut s = [0f64; 3];
    for p in img.pixels() {
        for (s, &c) in s.iter_mut().zip(&p.0) {
            *s += f64::from(c);
        }
    }
    let n = f64::from(img.width() * img.height());
    s.map(|v| v / n)
}

/// Sum of brightness steps between neighbouring pixels (edges, facets, noise), per pixel.
fn variation(img: &RgbImage) -> f64 {
    let lum = |x: u32, y: u32| {
        let p = img.get_pixel(x, y).0;
        0.3 * f64::from(p[0]) + 0.6 * f64::from(p[1]) + 0.1 * f64::from(p[2])
    };
    let mut s = 0.0;
    for y in 0..img.height() - 1 {
        for x in 0..img.width() - 1 {
            s += (lum(x + 1, y) - lum(x, y)).abs() + (lum(x, y + 1) - lum(x, y)).abs();
        }
    }
    s / f64::from(img.width() * img.height())
}

fn printing() -> bool {
    std::env::var_os("DYNBVH_PRINT_GOLDEN").is_some()
}

/// The golden comparisons of one test. Every check runs (and, with `DYNBVH_PRINT_GOLDEN`
/// set, prints its value) and records its failure; the failures are asserted when the checks
/// go out of scope, so a test prints all of its new values and still fails until they are
/// recorded.
#[derive(Default)]
struct Golden {
    failures: Vec<String>,
}

impl Golden {
    /// Compares a signature with the golden one: every block within `tol` levels.
    fn signature(&mut self, what: &str, got: &[String], want: &[&str], tol: i32) {
        if printing() {
            println!("{what} signature:");
            for row in got {
                println!("    \"{row}\",");
            }
        }
        if got.len() != want.len() {
            self.failures.push(format!(
                "{what}: {} signature rows, expected {}",
                got.len(),
                want.len()
            ));
            return;
        }
        let mut worst = 0;
        for (g, w) in got.iter().zip(want) {
            for (a, b) in g.chars().zip(w.chars()) {
                worst = worst.max((level(a) - level(b)).abs());
            }
        }
        if worst > tol {
            self.failures.push(format!(
                "{what}: a block's brightness moved by {worst} levels (tolerance {tol});\n got {got:#?}\nwant {want:#?}"
            ));
        }
    }

    /// Compares a value with the golden one within `rel` of it.
    fn close(&mut self, what: &str, got: f64, want: f64, rel: f64) {
        if printing() {
            println!("{what}: {got:.3}");
        }
        if (got - want).abs() > rel * want.abs().max(1.0) {
            self.failures.push(format!(
                "{what}: {got:.3}, expected {want:.3} within {:.1}%",
                rel * 100.0
            ));
        }
    }
}

impl Drop for Golden {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            assert!(
                self.failures.is_empty(),
                "golden values differ:\n{}",
                self.failures.join("\n")
            );
        }
    }
}

const TUBE_SHADED_4: [&str; 12] = [
    "pppppppppppppppp",
    "oooooooooooooooo",
    "mmmmmmmmmmmmmmmm",
    "lllllllllljgclll",
    "kkkkkkkkjfXQckkk",
    "jjjjjjjjaQXijjjj",
    "jijjjjjfPijjjjij",
    "jjkkkkkbUlkkkkji",
    "jlkklmlVbljhkkkk",
    "kllllklYTXabbYek",
    "kmkllkmhgllllllk",
    "kmkmkmkllllkmllk",
];
const TUBE_MEAN_RGB_4: [f64; 3] = [185.303, 183.462, 186.371];
const TUBE_VARIATION_4: f64 = 7.980;

#[test]
fn tube_shaded_frame_matches_golden() {
    let mut g = Golden::default();
    let s = scene(Kind::Tube, 800);
    let settings = Settings {
        width: W,
        height: H,
        smooth: true,
        shadows: true,
        heatmap: None,
    };
    let frames = render(&s, settings, true, &[4]);
    let (_, img, counts) = &frames[0];
    if printing() {
        img.save("/tmp/golden_tube.png").unwrap();
    }
    assert_eq!(counts.primary, u64::from(W * H));
    assert!(counts.hits > 200, "the tube covers part of the picture");
    assert!(
        counts.shadow > counts.hits / 2,
        "lit points cast shadow rays"
    );
    // The sky is not black.
    let top = img.get_pixel(0, 0).0;
    assert!(top.iter().all(|&c| c > 40), "background {top:?}");
    g.signature("tube shaded frame 4", &signature(img), &TUBE_SHADED_4, 2);
    g.close("tube variation", variation(img), TUBE_VARIATION_4, 0.01);
    let m = mean_rgb(img);
    for k in 0..3 {
        g.close(
            &format!("tube mean channel {k}"),
            m[k],
            TUBE_MEAN_RGB_4[k],
            0.01,
        );
    }
}

const WAVE_SMOOTH_3: [&str; 12] = [
    "pppppppppppppppp",
    "oooooooooooooooo",
    "mmmmmmmmmmmmmmmm",
    "llllllllllllllll",
    "kkkkieekhgkkjjkk",
    "jjfaXYbbYXegdhjj",
    "iYXYZcZXXbddeiij",
    "igcbgfXYbdecgiii",
    "hhhhhhebeghghhhh",
    "hhgggggggggggghh",
    "gggggggggggggggg",
    "ggffffffffffffgg",
];
/// Flat normals give 2.89: 3% more.
const WAVE_VARIATION_3: f64 = 2.805;

#[test]
fn wave_smooth_frame_matches_golden() {
    let mut g = Golden::default();
    // A big morphing surface with no ground: smooth and flat normals look clearly different.
    let s = scene(Kind::Wave, 800);
    let settings = Settings {
        width: W,
        height: H,
        smooth: true,
        shadows: true,
        heatmap: None,
    };
    let frames = render(&s, settings, false, &[3]);
    let (_, img, _) = &frames[0];
    if printing() {
        img.save("/tmp/golden_wave.png").unwrap();
    }
    g.signature("wave smooth frame 3", &signature(img), &WAVE_SMOOTH_3, 2);
    g.close("wave variation", variation(img), WAVE_VARIATION_3, 0.01);
}

const ORBIT_FLAT_6: [&str; 12] = [
    "pppppppppppppppp",
    "oooooooooooooooo",
    "mmmmmmmmmmmmmmmm",
    "llllllllllllllll",
    "mkllklllljklkkll",
    "mkmkkhkkjijklkll",
    "ljkhllkjhkikklll",
    "limjjmlimjklhkml",
    "lknmjkmkknlkkljj",
    "jjmnllmmjjllkmnn",
    "ljlmjjknmkmnnjjk",
    "jjlnnkmnnkjjlkkj",
];
const ORBIT_MEAN_RGB_6: [f64; 3] = [190.388, 191.295, 194.082];
const ORBIT_VARIATION_6: f64 = 8.131;

#[test]
fn orbit_flat_frame_matches_golden() {
    let mut g = Golden::default();
    // Rigid instances: normals go through each instance's transform.
    let s = scene(Kind::Orbit, 600);
    let settings = Settings {
        width: W,
        height: H,
        smooth: false,
        shadows: true,
        heatmap: None,
    };
    let frames = render(&s, settings, true, &[6]);
    let (_, img, _) = &frames[0];
    if printing() {
        img.save("/tmp/golden_orbit.png").unwrap();
    }
    g.signature("orbit flat frame 6", &signature(img), &ORBIT_FLAT_6, 2);
    g.close("orbit variation", variation(img), ORBIT_VARIATION_6, 0.01);
    let m = mean_rgb(img);
    for k in 0..3 {
        g.close(
            &format!("orbit mean channel {k}"),
            m[k],
            ORBIT_MEAN_RGB_6[k],
            0.01,
        );
    }
}

const SWAP_WORK: [(usize, f64, f64); 3] = [
    (0, 13266.0, 2483.0),
    (2, 7306.0, 1500.0),
    (4, 13556.0, 2619.0),
];

#[test]
fn swap_heat_map_work_matches_golden() {
    let mut g = Golden::default();
    let s = scene(Kind::Swap, 600);
    let settings = Settings {
        width: W,
        height: H,
        smooth: true,
        shadows: true,
        heatmap: Some(150),
    };
    let frames = render(&s, settings, true, &[0, 2, 4]);
    for ((f, img, c), (gf, nodes, prims)) in frames.iter().zip(SWAP_WORK) {
        assert_eq!(*f, gf);
        g.close(
            &format!("swap frame {f} nodes"),
            c.work.nodes as f64,
            nodes,
            0.01,
        );
        g.close(
            &format!("swap frame {f} triangles"),
            c.work.prims as f64,
            prims,
            0.01,
        );
        // The legend is drawn: its bar spans the scale's colours along a row near the bottom.
        let bar = (H - 32..H).any(|y| {
            let row: std::collections::HashSet<[u8; 3]> =
                (0..W).map(|x| img.get_pixel(x, y).0).collect();
            row.len() > 30
        });
        assert!(bar, "legend bar expected near the bottom");
        if printing() {
            img.save(format!("/tmp/golden_swap_{f}.png")).unwrap();
        }
    }
}
