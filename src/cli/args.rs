//! Argument types and bounds shared by the subcommands: image sizes, thread counts, byte sizes,
//! and the limits (`--max-frames`, `--max-memory`) that every size coming from an argument or
//! a file is checked against before it is allocated or looped over.

use anyhow::{Result, bail};
use clap::Args;
use dynbvh::anim::Scene;
use dynbvh::engine::gltf::FrameTimes;
use std::fmt;
use std::str::FromStr;

/// Longest side of an image (`--size`).
pub const MAX_SIDE: u32 = 16384;

/// Default `--max-frames`: the most frames a run may ask for.
pub const DEFAULT_MAX_FRAMES: u64 = 1000;

/// Frames `render` spreads over a clip whose frames at `--fps` would be more than
/// `--max-frames`, when no `--frames` are given.
pub const LONG_CLIP_FRAMES: u64 = 300;

/// Most frames `--max-frames` may allow: the frame sources' own bound on a timeline.
pub const MAX_TIMELINE: u64 = dynbvh::engine::gltf::MAX_FRAMES as u64;

/// Default `--max-memory`: 4 GiB.
pub const DEFAULT_MAX_MEMORY: u64 = 4 << 30;

/// Most trace passes per frame (`bench --repeats`) and builds per method (`build-bench --runs`).
pub const MAX_REPEATS: u64 = 1000;

/// Peak bytes per triangle of `build-bench` (the mesh, a tree under construction and the
/// trees kept for comparison).
pub const BUILD_BYTES_PER_TRIANGLE: u64 = 400;

/// An image size `WxH`, both sides within `1..=MAX_SIDE`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Size {
    /// Width in pixels.
    pub w: u32,
    /// Height in pixels.
    pub h: u32,
}

impl Size {
    /// Pixels of the image.
    #[must_use]
    pub fn pixels(self) -> u64 {
        u64::from(self.w) * u64::from(self.h)
    }
}

impl FromStr for Size {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let (w, h) = s
            .split_once(['x', 'X'])
            .ok_or_else(|| format!("expected WxH (e.g. 640x480), found {s:?}"))?;
        let side = |v: &str, name: &str| -> std::result::Result<u32, String> {
            let v = v.trim();
            match v.parse::<u64>() {
                Ok(n) if (1..=u64::from(MAX_SIDE)).contains(&n) => Ok(n as u32),
                Ok(n) => Err(format!(
                    "{name} {n} is outside 1..={MAX_SIDE} pixels (in {s:?})"
                )),
                Err(_) => Err(format!(
                    "{name} {v:?} is not a whole number of pixels (in {s:?}, expected WxH)"
                )),
            }
        };
        Ok(Size {
            w: side(w, "width")?,
            h: side(h, "height")?,
        })
    }
}

impl fmt::Display for Size {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}x{}", self.w, self.h)
    }
}

/// A byte size: a whole number with an optional suffix K, M, G or T (powers of 1024).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Bytes(pub u64);

impl FromStr for Bytes {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let t = s.trim();
        let (digits, shift) = match t.char_indices().last() {
            Some((i, c)) if c.is_ascii_alphabetic() => {
                let shift = match c.to_ascii_uppercase() {
                    'K' => 10,
                    'M' => 20,
                    'G' => 30,
                    'T' => 40,
                    _ => return Err(format!("{s:?}: expected a byte count with K, M, G or T")),
                };
                (&t[..i], shift)
            }
            _ => (t, 0),
        };
        let n: u64 = digits
            .trim()
            .parse()
            .map_err(|_| format!("{s:?}: expected a byte count such as 4G or 512M"))?;
        n.checked_mul(1 << shift)
            .map(Bytes)
            .ok_or_else(|| format!("{s:?}: too large"))
    }
}

impl fmt::Display for Bytes {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let b = self.0 as f64;
        if b >= f64::from(1u32 << 30) {
            write!(f, "{:.1} GiB", b / f64::from(1u32 << 30))
        } else if b >= f64::from(1u32 << 20) {
            write!(f, "{:.1} MiB", b / f64::from(1u32 << 20))
        } else {
            write!(f, "{} bytes", self.0)
        }
    }
}

/// Parses a thread count: at least 1 (`--threads 0` is an error, not "all cores").
pub fn thread_count(s: &str) -> std::result::Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(0) => Err("0 threads: give at least 1 (leave --threads out for all cores)".into()),
        Ok(n) => Ok(n),
        Err(_) => Err(format!("{s:?} is not a whole number of threads")),
    }
}

/// Sets up the global thread pool: `threads` workers (default: all cores), capped at the
/// machine's cores with a warning, since more only adds scheduling and memory.
pub fn init_threads(threads: Option<usize>) -> Result<()> {
    let Some(t) = threads else { return Ok(()) };
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get);
    let t = if t > cores {
        eprintln!("warning: --threads {t}: this machine has {cores} cores; using {cores}");
        cores
    } else {
        t
    };
    rayon::ThreadPoolBuilder::new()
        .num_threads(t)
        .build_global()
        .map_err(|e| anyhow::anyhow!("setting up the thread pool of {t} threads: {e}"))
}

/// `--max-memory`: the bound on a job's estimated big allocations.
#[derive(Args, Debug, Clone, Copy)]
pub struct MemoryLimit {
    /// Bound on the estimated memory of the job's big allocations (flattened triangles,
    /// trees, rays, images, tables), e.g. 512M or 16G; a job estimated above it is refused.
    #[arg(long, value_name = "BYTES", default_value = "4G")]
    pub max_memory: Bytes,
}

impl Default for MemoryLimit {
    fn default() -> Self {
        Self {
            max_memory: Bytes(DEFAULT_MAX_MEMORY),
        }
    }
}

impl MemoryLimit {
    /// Refuses `what` (a phrase naming the argument or object and its size) when `estimate`
    /// bytes exceed `--max-memory`.
    pub fn check_memory(&self, what: &str, estimate: u64) -> Result<()> {
        if estimate > self.max_memory.0 {
            bail!(
                "{what} needs about {} of memory, above the bound of {} (--max-memory raises it)",
                Bytes(estimate),
                self.max_memory
            );
        }
        Ok(())
    }
}

/// What a job keeps per flattened triangle and vertex of a scene (with a margin over what was
/// measured), for [`MemoryLimit::check_scene`].
#[derive(Clone, Copy, Debug)]
pub struct PerElement {
    /// The job, for the message (e.g. `bench`).
    pub job: &'static str,
    /// Bytes per flattened triangle.
    pub triangle: u64,
    /// Bytes per flattened vertex.
    pub vertex: u64,
}

/// `pose`: the flattened mesh and the OBJ or PLY text of it.
pub const POSE_MEMORY: PerElement = PerElement {
    job: "pose",
    triangle: 48,
    vertex: 48,
};

/// `render`, per policy: an engine's trees and its shading normals.
pub const RENDER_MEMORY: PerElement = PerElement {
    job: "render",
    triangle: 500,
    vertex: 48,
};

/// `bench`: every configuration's engine, run in lockstep, and the reference copies.
pub const BENCH_MEMORY: PerElement = PerElement {
    job: "bench",
    triangle: 2500,
    vertex: 100,
};

/// `build-bench` on a glTF file: the flattened mesh and its trees.
pub const BUILD_MEMORY: PerElement = PerElement {
    job: "build-bench",
    triangle: BUILD_BYTES_PER_TRIANGLE,
    vertex: 12,
};

impl MemoryLimit {
    /// Refuses a job on `scene` (repeated `copies` times, e.g. once per policy) whose
    /// flattened triangles and vertices, every mesh instance counted, would need more than
    /// `--max-memory`; the message names the file, the counts and the most repeated mesh.
    pub fn check_scene(&self, scene: &Scene, per: PerElement, copies: u64) -> Result<()> {
        let tris = scene.triangle_count() as u64;
        let verts = scene.vertex_count() as u64;
        let estimate = tris
            .saturating_mul(per.triangle)
            .saturating_add(verts.saturating_mul(per.vertex))
            .saturating_mul(copies.max(1));
        if verts > u64::from(u32::MAX) {
            bail!(
                "{}: {}: {verts} vertices over {} mesh instances, more than the 2^32 a \
                 flattened mesh can index",
                scene.path.display(),
                per.job,
                scene.instances.len()
            );
        }
        if estimate <= self.max_memory.0 {
            return Ok(());
        }
        let mut placed = vec![0u64; scene.meshes.len()];
        for i in &scene.instances {
            placed[i.mesh] += 1;
        }
        let heaviest = (0..scene.meshes.len())
            .max_by_key(|&m| placed[m] * scene.meshes[m].indices.len() as u64)
            .map(|m| {
                format!(
                    " (mesh {} of {} triangles placed by {} node(s))",
                    scene.meshes[m].gltf_index,
                    scene.meshes[m].indices.len(),
                    placed[m]
                )
            })
            .unwrap_or_default();
        let copies = if copies > 1 {
            format!(", {copies} times over")
        } else {
            String::new()
        };
        self.check_memory(
            &format!(
                "{}: {}: {tris} triangles and {verts} vertices over {} mesh instances{heaviest}{copies}",
                scene.path.display(),
                per.job,
                scene.instances.len()
            ),
            estimate,
        )
    }
}

/// The bounds of the commands that run frames: `--max-frames` and `--max-memory`.
#[derive(Args, Debug, Clone, Copy, Default)]
pub struct Limits {
    /// Most frames a run may ask for (through --frames, or the clip's duration x --fps).
    #[arg(long, allow_negative_numbers = true, value_name = "N", default_value_t = DEFAULT_MAX_FRAMES,
          value_parser = clap::value_parser!(u64).range(1..=MAX_TIMELINE))]
    pub max_frames: u64,
    #[command(flatten)]
    pub memory: MemoryLimit,
}

impl Limits {
    /// See [`MemoryLimit::check_memory`].
    pub fn check_memory(&self, what: &str, estimate: u64) -> Result<()> {
        self.memory.check_memory(what, estimate)
    }

    /// Refuses an explicit request of `frames` frames (`what` names the argument and its
    /// value) above `--max-frames`.
    pub fn check_frames(&self, what: &str, frames: f64) -> Result<()> {
        if frames.is_nan() || frames > self.max_frames as f64 {
            bail!(
                "{what} asks for {} frames, above the bound of {} (--max-frames raises it)",
                count(frames),
                self.max_frames
            );
        }
        Ok(())
    }
}

/// A count that may be huge: whole digits up to 1e15, else in exponent form.
#[must_use]
pub fn count(n: f64) -> String {
    if n < 1e15 {
        format!("{n:.0}")
    } else {
        format!("{n:.3e}")
    }
}

/// Frames of a clip of `duration` seconds at `fps`, rounded up as the frame sources do, in
/// `f64` so that a huge duration or rate gives a huge count instead of overflowing.
#[must_use]
pub fn frames_at(duration: f32, fps: f32) -> f64 {
    (f64::from(duration) * f64::from(fps)).ceil().max(1.0)
}

/// Parses a time in seconds: any finite number, negative included.
pub fn finite_time(s: &str) -> std::result::Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(t) if t.is_finite() => Ok(t),
        Ok(t) => Err(format!("{t} s: must be finite")),
        Err(_) => Err(format!("{s:?} is not a number of seconds")),
    }
}

/// Parses a frame rate: positive and finite.
pub fn frame_rate(s: &str) -> std::result::Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(f) if f > 0.0 && f.is_finite() => Ok(f),
        Ok(f) => Err(format!(
            "{f} frames per second: must be positive and finite"
        )),
        Err(_) => Err(format!("{s:?} is not a number of frames per second")),
    }
}

/// `--frames`: a count spread over one loop of the animation, or a range `A..B` (B excluded)
/// of the frames of the timeline at `--fps`. Frames are numbered from 0, the animation's
/// start, in every command's output.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameSpan {
    /// `N` frames spread over one loop.
    Count(usize),
    /// Frames `start..end` of the timeline at `--fps`.
    Range {
        /// First frame (the fresh build).
        start: usize,
        /// One past the last frame.
        end: usize,
    },
}

impl FromStr for FrameSpan {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let whole = |v: &str| -> std::result::Result<usize, String> {
            v.trim()
                .parse::<usize>()
                .map_err(|_| format!("{s:?}: expected a frame count N or a range A..B"))
        };
        match s.split_once("..") {
            Some((a, b)) => {
                let (start, end) = (whole(a)?, whole(b)?);
                if end <= start {
                    return Err(format!("{s:?}: the range is empty (B must exceed A)"));
                }
                Ok(FrameSpan::Range { start, end })
            }
            None => match whole(s)? {
                0 => Err("0 frames: give at least 1".into()),
                n => Ok(FrameSpan::Count(n)),
            },
        }
    }
}

impl fmt::Display for FrameSpan {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FrameSpan::Count(n) => write!(f, "{n}"),
            FrameSpan::Range { start, end } => write!(f, "{start}..{end}"),
        }
    }
}

/// The frame timeline that `--frames` and `--fps` ask for, and the range of it to run (`None`:
/// all of it); `default` when neither is given. A range takes its frames at `--fps` (default
/// 30); a count and `--fps` both set the count, so they are refused together. The count or
/// range is checked against `--max-frames`.
pub fn timeline(
    frames: Option<FrameSpan>,
    fps: Option<f32>,
    default: FrameTimes,
    limits: &Limits,
) -> Result<(FrameTimes, Option<(usize, usize)>)> {
    let at_fps = FrameTimes::Fps(fps.unwrap_or(30.0));
    match frames {
        None => Ok((fps.map_or(default, FrameTimes::Fps), None)),
        Some(FrameSpan::Count(n)) => {
            if fps.is_some() {
                bail!(
                    "--frames {n} and --fps both set the frame count: give one (or a range A..B \
                     with --fps)"
                );
            }
            limits.check_frames(&format!("--frames {n}"), n as f64)?;
            Ok((FrameTimes::Count(n), None))
        }
        Some(FrameSpan::Range { start, end }) => {
            limits.check_frames(&format!("--frames {start}..{end}"), (end - start) as f64)?;
            Ok((at_fps, Some((start, end))))
        }
    }
}

/// The animation `-a/--animation` names (`None`: the file's first, or none when it has no
/// animation, and then every frame is the rest pose).
pub fn animation_or_first(
    scene: &Scene,
    file: &std::path::Path,
    key: Option<&str>,
) -> Result<Option<usize>> {
    match key {
        Some(k) => choose_animation(scene, file, k).map(Some),
        None => Ok((!scene.animations.is_empty()).then_some(0)),
    }
}

/// The animation `key` (a name or an index) of `scene`, or an error naming the file and
/// listing the animations it has. The one place `-a/--animation` is resolved.
pub fn choose_animation(scene: &Scene, file: &std::path::Path, key: &str) -> Result<usize> {
    scene.find_animation(key).ok_or_else(|| {
        let names: Vec<String> = scene
            .animations
            .iter()
            .enumerate()
            .map(|(i, a)| match &a.name {
                Some(n) if !n.is_empty() => format!("{i} ({n:?})"),
                _ => i.to_string(),
            })
            .collect();
        let list = if names.is_empty() {
            "it has none".to_string()
        } else {
            format!("it has: {}", names.join(", "))
        };
        anyhow::anyhow!(
            "{}: no animation named or numbered {key:?}; {list}",
            file.display()
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes() {
        assert_eq!("96x72".parse::<Size>(), Ok(Size { w: 96, h: 72 }));
        assert!("0x5".parse::<Size>().is_err());
        let e = "32x".parse::<Size>().unwrap_err();
        assert!(e.contains("height") && e.contains("32x"), "{e}");
        let e = "100000x100000".parse::<Size>().unwrap_err();
        assert!(e.contains("16384"), "{e}");
    }

    #[test]
    fn bytes() {
        assert_eq!("4G".parse::<Bytes>(), Ok(Bytes(4 << 30)));
        assert_eq!("512m".parse::<Bytes>(), Ok(Bytes(512 << 20)));
        assert_eq!("100".parse::<Bytes>(), Ok(Bytes(100)));
        assert!("99999999999T".parse::<Bytes>().is_err());
        assert!("4Q".parse::<Bytes>().is_err());
    }

    #[test]
    fn frame_spans() {
        assert_eq!("12".parse::<FrameSpan>(), Ok(FrameSpan::Count(12)));
        assert_eq!(
            "100..200".parse::<FrameSpan>(),
            Ok(FrameSpan::Range {
                start: 100,
                end: 200
            })
        );
        assert_eq!("3..7".parse::<FrameSpan>().unwrap().to_string(), "3..7");
        for bad in ["5..5", "7..3", "x", "0", "1..", "-1"] {
            assert!(bad.parse::<FrameSpan>().is_err(), "{bad}");
        }
        let limits = Limits {
            max_frames: 1000,
            ..Limits::default()
        };
        let count = FrameTimes::Count(60);
        let t = |f: &str, fps| timeline(Some(f.parse().unwrap()), fps, count, &limits);
        assert_eq!(t("12", None).unwrap(), (FrameTimes::Count(12), None));
        assert_eq!(
            t("100..200", Some(24.0)).unwrap(),
            (FrameTimes::Fps(24.0), Some((100, 200)))
        );
        assert_eq!(
            t("0..5", None).unwrap(),
            (FrameTimes::Fps(30.0), Some((0, 5)))
        );
        assert!(t("12", Some(10.0)).is_err());
        assert!(t("0..5000", None).is_err());
        assert_eq!(timeline(None, None, count, &limits).unwrap(), (count, None));
        assert_eq!(
            timeline(None, Some(10.0), count, &limits).unwrap(),
            (FrameTimes::Fps(10.0), None)
        );
    }

    #[test]
    fn rates_and_threads() {
        assert!(frame_rate("1e30").is_ok());
        assert!(frame_rate("0").is_err());
        assert!(frame_rate("inf").is_err());
        assert!(thread_count("0").is_err());
        assert_eq!(thread_count("3"), Ok(3));
        assert_eq!(frames_at(2.0, 30.0), 60.0);
        assert!(frames_at(3e38, 30.0) > 1e39);
    }
}
