//! A mutation fuzzer over the glTF loader and the posing path, run for a fixed time budget:
//! every sample file (`../shared/gltf-samples/`, `animations/`) and the committed corpus
//! (`tests/fuzz_corpus/`) is loaded as it is, then mutated (truncations, byte flips, inserted
//! and deleted runs, JSON numbers replaced by hostile values, GLB chunk lengths changed) with a
//! seeded generator, and each mutant is loaded, every animation posed at a few times, the
//! scene flattened, a tree built over it, validated and traced, and the engine driven through
//! a few frames of the first animations as `render` and `bench` drive it.
//!
//! A case may fail to load (a clean error) but must not panic, and must finish in bounded
//! time: a case still running after [`HANG`] fails the test. The mutant of a failed case is
//! written to `target/fuzz-crashes/` (commit it to `tests/fuzz_corpus/` once fixed, so it is
//! replayed by every run).
//!
//! `DYNBVH_FUZZ_SECONDS` sets the budget (default [`DEFAULT_SECONDS`]; every seed is loaded
//! unmutated whatever the budget), `DYNBVH_FUZZ_SEED` the generator's seed (default: fixed, so
//! a run repeats the last one's cases up to the budget).

mod anim_util;

use dynbvh::anim::{LoadOptions, Scene};
use dynbvh::bvh::{BuildParams, MeshBvh};
use dynbvh::engine::EngineConfig;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::geom::{Ray, TriMesh};
use glam::Vec3;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Budget of a run without `DYNBVH_FUZZ_SECONDS`.
const DEFAULT_SECONDS: u64 = 60;

/// A case running longer than this is a hang.
const HANG: Duration = Duration::from_secs(20);

/// Decoded accessor bytes a case may load (the CLI allows more; the fuzzer keeps its memory
/// small).
const MAX_DECODED: u64 = 256 << 20;

/// Most flattened vertices posed and built over per case.
const MAX_VERTICES: usize = 1 << 20;

/// splitmix64: a small deterministic generator.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `0..n` (`n > 0`).
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

/// A seed file: its path (external buffers resolve next to it) and bytes.
struct Seed {
    path: PathBuf,
    bytes: Vec<u8>,
}

fn seeds() -> Vec<Seed> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut dirs = vec![root.join("animations"), root.join("tests/fuzz_corpus")];
    if let Some(s) = anim_util::samples() {
        dirs.push(s);
    }
    let mut files = Vec::new();
    while let Some(d) = dirs.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                dirs.push(p);
            } else if p
                .extension()
                .is_some_and(|x| x.eq_ignore_ascii_case("glb") || x.eq_ignore_ascii_case("gltf"))
            {
                files.push(p);
            }
        }
    }
    files.sort();
    files
        .into_iter()
        .map(|path| Seed {
            bytes: std::fs::read(&path).unwrap(),
            path,
        })
        .collect()
}

/// Values a JSON number is replaced by: zero, signs, the edges of the integer types the
/// loader reads, counts around its bounds, and floats at and past f32's range.
const HOSTILE_NUMBERS: &[&str] = &[
    "0",
    "-1",
    "1",
    "2",
    "3",
    "4",
    "7",
    "255",
    "65535",
    "65536",
    "2147483647",
    "2147483648",
    "4294967295",
    "4294967296",
    "18446744073709551615",
    "16777216",
    "5592405",
    "1e30",
    "-1e30",
    "3e38",
    "3.5e38",
    "1e300",
    "-0.0",
    "0.5",
    "1e-45",
    "5125",
    "5126",
    "5123",
    "5121",
    "34962",
];

/// Byte ranges of the numbers in `json`.
fn numbers(json: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < json.len() {
        let c = json[i];
        let starts =
            c.is_ascii_digit() || (c == b'-' && json.get(i + 1).is_some_and(u8::is_ascii_digit));
        // Not inside a word (names such as "TEXCOORD_0").
        let after_word = i > 0 && (json[i - 1].is_ascii_alphanumeric() || json[i - 1] == b'_');
        if starts && !after_word {
            let s = i;
            i += 1;
            while i < json.len()
                && matches!(json[i], b'0'..=b'9' | b'.' | b'e' | b'E' | b'+' | b'-')
            {
                i += 1;
            }
            out.push((s, i));
        } else {
            i += 1;
        }
    }
    out
}

/// The JSON part of a file: the whole of a `.gltf`, the JSON chunk of a GLB (its range).
fn json_range(bytes: &[u8]) -> Option<(usize, usize)> {
    if bytes.starts_with(b"glTF") {
        let len = u32::from_le_bytes(bytes.get(12..16)?.try_into().ok()?) as usize;
        let end = 20usize.checked_add(len)?;
        (end <= bytes.len()).then_some((20, end))
    } else {
        Some((0, bytes.len()))
    }
}

/// `bytes` with a new JSON part, GLB lengths kept consistent.
fn replace_json(bytes: &[u8], (s, e): (usize, usize), json: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(bytes.len() + json.len());
    out.extend_from_slice(&bytes[..s]);
    out.extend_from_slice(json);
    if bytes.starts_with(b"glTF") {
        while (out.len() - s) % 4 != 0 {
            out.push(b' ');
        }
        let len = (out.len() - s) as u32;
        out[12..16].copy_from_slice(&len.to_le_bytes());
    }
    out.extend_from_slice(&bytes[e..]);
    if out.starts_with(b"glTF") && out.len() >= 12 {
        let total = out.len() as u32;
        out[8..12].copy_from_slice(&total.to_le_bytes());
    }
    out
}

/// One mutation of `bytes`.
fn mutate(rng: &mut Rng, bytes: &mut Vec<u8>) {
    if bytes.is_empty() {
        bytes.extend(b"{}");
    }
    match rng.below(10) {
        // Truncation.
        0 => {
            let at = rng.below(bytes.len());
            bytes.truncate(at);
        }
        // Byte flips.
        1 => {
            for _ in 0..1 + rng.below(8) {
                let at = rng.below(bytes.len());
                bytes[at] ^= 1 << rng.below(8);
            }
        }
        // A run of random or repeated bytes inserted.
        2 => {
            let at = rng.below(bytes.len() + 1);
            let n = 1 + rng.below(64);
            let run: Vec<u8> = if rng.below(2) == 0 {
                (0..n).map(|_| rng.next() as u8).collect()
            } else {
                vec![bytes[rng.below(bytes.len())]; n]
            };
            bytes.splice(at..at, run);
        }
        // A run deleted.
        3 => {
            let at = rng.below(bytes.len());
            let n = (1 + rng.below(256)).min(bytes.len() - at);
            bytes.drain(at..at + n);
        }
        // A GLB length field (file, JSON chunk, BIN chunk) set to a hostile value.
        4 if bytes.starts_with(b"glTF") && bytes.len() >= 20 => {
            let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
            let fields = [8usize, 12, 20 + json_len];
            let at = fields[rng.below(fields.len())];
            let v = [0u32, 1, 3, 0x7FFF_FFFF, u32::MAX, bytes.len() as u32 * 2][rng.below(6)];
            if at + 4 <= bytes.len() {
                bytes[at..at + 4].copy_from_slice(&v.to_le_bytes());
            }
        }
        // Floats of the binary chunk (of a GLB; anywhere in other files) set to NaN,
        // infinities, 1e30, denormals, zero, or integers' bit patterns: keys, positions,
        // weights, matrices and indices gone wrong in a file that still parses.
        5 | 6 => {
            let json_end = json_range(bytes).map_or(0, |r| r.1);
            let start = if bytes.starts_with(b"glTF") {
                json_end + 8
            } else {
                0
            };
            if bytes.len() >= start + 4 {
                for _ in 0..1 + rng.below(4) {
                    let at = start + rng.below((bytes.len() - start) / 4) * 4;
                    let v: [u8; 4] = match rng.below(8) {
                        0 => f32::NAN.to_le_bytes(),
                        1 => f32::INFINITY.to_le_bytes(),
                        2 => 1e30f32.to_le_bytes(),
                        3 => (-3e38f32).to_le_bytes(),
                        4 => 1e-40f32.to_le_bytes(),
                        5 => 0f32.to_le_bytes(),
                        6 => u32::MAX.to_le_bytes(),
                        _ => (rng.next() as u32 & 0xFFFF).to_le_bytes(),
                    };
                    bytes[at..at + 4].copy_from_slice(&v);
                }
            }
        }
        // JSON numbers replaced by hostile ones (several at once, sometimes).
        _ => {
            let Some(range) = json_range(bytes) else {
                return;
            };
            let json = &bytes[range.0..range.1];
            let nums = numbers(json);
            if nums.is_empty() {
                return;
            }
            let mut edited = json.to_vec();
            let mut picks: Vec<usize> = (0..1 + rng.below(3))
                .map(|_| rng.below(nums.len()))
                .collect();
            picks.sort_unstable();
            picks.dedup();
            for &k in picks.iter().rev() {
                let (s, e) = nums[k];
                // A hostile value, or a near one (an index or count one off).
                let v = if rng.below(3) == 0 {
                    let old: f64 = std::str::from_utf8(&json[s..e])
                        .ok()
                        .and_then(|t| t.parse().ok())
                        .unwrap_or(0.0);
                    let near = [old + 1.0, old - 1.0, old * 2.0, old * 0.5, -old][rng.below(5)];
                    format!("{near}")
                } else {
                    HOSTILE_NUMBERS[rng.below(HOSTILE_NUMBERS.len())].to_string()
                };
                edited.splice(s..e, v.bytes());
            }
            *bytes = replace_json(bytes, range, &edited);
        }
    }
}

/// How far a case got.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Reached {
    /// A load error (clean).
    Refused,
    /// Loaded and posed, too big to flatten and build over here.
    Posed,
    /// Flattened, a tree built over it, validated and traced.
    Traced,
}

/// Loads, poses, flattens and builds over one case; an error is fine, a panic is not.
fn exercise(path: &Path, bytes: &[u8]) -> Reached {
    let opts = LoadOptions {
        max_decoded_bytes: Some(MAX_DECODED),
        ..LoadOptions::default()
    };
    let Ok((scene, _warnings)) = Scene::from_slice(path, bytes, &opts) else {
        return Reached::Refused;
    };
    if scene.vertex_count() > MAX_VERTICES {
        return Reached::Refused;
    }
    let mut mesh = TriMesh::default();
    let anims: Vec<Option<usize>> = std::iter::once(None)
        .chain((0..scene.animations.len().min(4)).map(Some))
        .collect();
    for anim in anims {
        let Ok(mut poser) = scene.poser(anim) else {
            continue;
        };
        let d = anim.map_or(0.0, |a| scene.animations[a].duration);
        for t in [0.0, 0.37 * d, d, 2.5 * d + 0.1, -1.0] {
            poser.pose(t);
        }
        poser.flatten_into(&mut mesh);
    }
    if mesh.check().is_err() || mesh.len() > MAX_VERTICES {
        return Reached::Posed;
    }
    let bvh = MeshBvh::build(&mesh, &BuildParams::BINNED);
    bvh.bvh().validate().unwrap();
    let b = mesh.bounds();
    let c = if b.is_finite() {
        b.center()
    } else {
        Vec3::ZERO
    };
    let rays: Vec<Ray> = [Vec3::X, Vec3::Y, Vec3::NEG_Z, Vec3::new(0.3, -0.5, 0.8)]
        .iter()
        .map(|&d| Ray::new(c - d * 10.0, d))
        .collect();
    for r in &rays {
        let _ = bvh.closest_hit(r);
    }
    // The frame loop render and bench run: the two-level engine built at the start of each
    // animation, moved through a few frames (refits, the policy's rebuilds), traced.
    for anim in (0..scene.animations.len().min(2)).map(Some).chain([None]) {
        let Ok(mut src) = GltfSource::new(&scene, anim, FrameTimes::Count(3)) else {
            continue;
        };
        let mut engine = src.engine(EngineConfig::default());
        let mut hits = vec![None; rays.len()];
        for step in 0..3 {
            if src.set_time(&mut engine, 0.41 * step as f32).is_err() {
                break;
            }
            engine.update();
            engine.trace_closest(&rays, &mut hits);
        }
    }
    Reached::Traced
}

/// Where a failing case is written.
fn crash_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("target/fuzz-crashes")
}

#[test]
fn loader_and_poser_survive_mutated_files() {
    let seeds = seeds();
    assert!(
        seeds.len() >= 6,
        "only {} seed files: animations/ and tests/fuzz_corpus/ at least",
        seeds.len()
    );
    let budget = Duration::from_secs(
        std::env::var("DYNBVH_FUZZ_SECONDS")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(DEFAULT_SECONDS),
    );
    let seed = std::env::var("DYNBVH_FUZZ_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0x16_F022u64);

    // The case under way, for the watchdog: its number and bytes.
    let current: Arc<Mutex<(PathBuf, Vec<u8>)>> = Arc::default();
    let started = Arc::new(AtomicU64::new(0));
    let done = Arc::new(AtomicU64::new(0));
    let worker = {
        let (current, started, done) = (current.clone(), started.clone(), done.clone());
        std::thread::spawn(move || {
            let mut rng = Rng(seed);
            let mut failures = Vec::new();
            let mut reached = [0u64; 3];
            let mut run = |path: &Path, bytes: Vec<u8>, failures: &mut Vec<String>| {
                *current.lock().unwrap() = (path.to_path_buf(), bytes.clone());
                started.fetch_add(1, Ordering::SeqCst);
                let r = catch_unwind(AssertUnwindSafe(|| exercise(path, &bytes)));
                if let Ok(how_far) = r {
                    reached[how_far as usize] += 1;
                } else {
                    let n = failures.len();
                    let name = path.file_name().unwrap().to_string_lossy();
                    let dir = crash_dir();
                    std::fs::create_dir_all(&dir).unwrap();
                    let out = dir.join(format!("panic_{n}_{name}"));
                    std::fs::write(&out, &bytes).unwrap();
                    failures.push(format!("{} (mutant of {})", out.display(), path.display()));
                }
                done.fetch_add(1, Ordering::SeqCst);
            };
            let t0 = Instant::now();
            for s in &seeds {
                run(&s.path, s.bytes.clone(), &mut failures);
            }
            let mut cases = 0u64;
            while t0.elapsed() < budget {
                let s = &seeds[rng.below(seeds.len())];
                let mut bytes = s.bytes.clone();
                for _ in 0..1 + rng.below(2) {
                    mutate(&mut rng, &mut bytes);
                }
                run(&s.path, bytes, &mut failures);
                cases += 1;
            }
            (failures, cases, seeds.len(), reached)
        })
    };
    // Watchdog: a case that does not finish within HANG fails the run (its bytes kept).
    let mut last = (0, Instant::now());
    while !worker.is_finished() {
        std::thread::sleep(Duration::from_millis(100));
        let d = done.load(Ordering::SeqCst);
        if d != last.0 {
            last = (d, Instant::now());
        } else if started.load(Ordering::SeqCst) > d && last.1.elapsed() > HANG {
            let (path, bytes) = current.lock().unwrap().clone();
            let dir = crash_dir();
            std::fs::create_dir_all(&dir).unwrap();
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            let out = dir.join(format!("hang_{name}"));
            std::fs::write(&out, &bytes).unwrap();
            panic!(
                "a mutant of {} still running after {HANG:?}: written to {}",
                path.display(),
                out.display()
            );
        }
    }
    let (failures, cases, seeds, [refused, posed, traced]) = worker.join().unwrap();
    eprintln!(
        "fuzz: {seeds} seed files, {cases} mutants in {budget:?} (seed {seed:#x}): {refused} \
         refused, {posed} posed, {traced} posed, built over and traced"
    );
    // The mutants must reach the posing path, not only the parser.
    assert!(
        posed + traced > cases / 20,
        "only {} of {cases} mutants loaded",
        posed + traced
    );
    assert!(failures.is_empty(), "panics on:\n{}", failures.join("\n"));
}

#[test]
fn mutations_change_files_and_numbers_are_found() {
    let mut rng = Rng(1);
    let json = br#"{"accessors":[{"count":12,"min":[-1.5e3,0]}],"TEXCOORD_0":1}"#;
    let nums: Vec<&[u8]> = numbers(json).iter().map(|&(s, e)| &json[s..e]).collect();
    assert_eq!(nums, [&b"12"[..], b"-1.5e3", b"0", b"1"]);
    let base = json.to_vec();
    let changed = (0..200)
        .filter(|_| {
            let mut b = base.clone();
            mutate(&mut rng, &mut b);
            b != base
        })
        .count();
    assert!(changed > 150, "{changed} of 200 mutations changed the file");
}
