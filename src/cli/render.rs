//! `dynbvh render`: an animation's frames as numbered PNGs (and an animated GIF), shaded or as
//! traversal-work heat maps, under one policy or two side by side.

use super::args::{self, Limits, Size};
use anyhow::{Context, Result, bail};
use clap::Args;
use dynbvh::anim::Scene;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::source::FrameSource;
use dynbvh::engine::{Action, Engine, EngineConfig, Policy, Traversal, WorkerPriority};
use dynbvh::render::{
    Camera, EngineShading, FrameCounts, GltfCamera, PacketUse, Renderer, Settings, Stage,
    animation_view, font, gltf_cameras,
};
use dynbvh::report::or_dash;
use image::RgbImage;
use image::codecs::gif::{GifEncoder, Repeat};
use indicatif::ProgressBar;
use std::io::BufWriter;
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `render`.
#[derive(Args, Debug, Clone)]
pub struct RenderArgs {
    /// Animated glTF file (.glb/.gltf).
    pub file: PathBuf,
    /// Animation name or index (default: the first).
    #[arg(long, short)]
    pub animation: Option<String>,
    /// Frames: a count N spread over one loop of the animation, or a range A..B (B excluded)
    /// of the frames at --fps (default 30). Frames are numbered from 0, the animation's start,
    /// as in every command's output (PNG names, captions, tables). Each run starts with a fresh
    /// build at its first frame, so a long sequence can be split over processes. Default:
    /// every frame at --fps.
    #[arg(long, allow_negative_numbers = true, value_name = "N|A..B")]
    pub frames: Option<args::FrameSpan>,
    /// Frames per second of animation time (default 30).
    #[arg(long, allow_negative_numbers = true, value_parser = args::frame_rate)]
    pub fps: Option<f32>,
    /// Image size WxH (sides up to 16384).
    #[arg(long, value_name = "WxH", default_value = "640x480")]
    pub size: Size,
    /// Refit-or-rebuild policy: refit, rebuild, periodic:N, threshold:R, amortized,
    /// amortized-plain, optimize:B, partial:F, ladder or async.
    #[arg(long, short, default_value_t = Policy::DEFAULT)]
    pub policy: Policy,
    /// Output directory.
    #[arg(long, default_value = "out/render")]
    pub out: PathBuf,
    /// Also write the sequence as one animated GIF.
    #[arg(long)]
    pub gif: bool,
    /// Colour pixels by traversal work (nodes visited + triangles tested) instead of shading.
    /// Heat maps trace each ray on its own (the work counted is a single ray's), whereas shaded
    /// frames trace packets (--packets does not apply).
    #[arg(long)]
    pub heatmap: bool,
    /// Top of the heat map's scale, in nodes + triangles per pixel. Default: the 98th
    /// percentile of the first frame's work (over the pixels that cost any, under every
    /// compared policy), then kept for the whole run so that its frames compare.
    #[arg(long, value_name = "WORK", value_parser = clap::value_parser!(u32).range(1..))]
    pub heat_max: Option<u32>,
    /// Cast a shadow ray toward the key light from every lit point.
    #[arg(long)]
    pub shadows: bool,
    /// Flat shading with geometric normals (default: smooth, interpolated vertex normals).
    #[arg(long)]
    pub flat: bool,
    /// No ground plane under the scene.
    #[arg(long)]
    pub no_ground: bool,
    /// Frame the animation automatically even when the file has a camera.
    #[arg(long)]
    pub auto_camera: bool,
    /// Render every frame under two policies side by side (e.g. refit,rebuild).
    #[arg(long, value_name = "P1,P2", value_delimiter = ',')]
    pub compare: Vec<Policy>,
    /// Measure only: render without writing images; print each frame's timings and ray counts
    /// (primary, shadow), then their means over the frames after the first (whose fresh build
    /// is left out).
    #[arg(long)]
    pub bench: bool,
    /// Worker threads (default: all cores; more than the cores are capped).
    #[arg(long, allow_negative_numbers = true, value_parser = args::thread_count)]
    pub threads: Option<usize>,
    /// Rays traced as packets: primary, shadow, both or none (the pictures are the same).
    /// Shaded frames only: heat maps trace ray by ray.
    #[arg(long, value_name = "both|primary|shadow|none", default_value_t = PacketUse::DEFAULT)]
    pub packets: PacketUse,
    /// Mesh trees the rays walk: binary, or wide (8-wide trees kept beside the binary ones;
    /// the pictures are the same).
    #[arg(long, value_name = "binary|wide", default_value_t = Traversal::DEFAULT)]
    pub traversal: Traversal,
    /// The scheduling class of `async`'s background worker: `normal`, or `idle` (Linux
    /// `SCHED_IDLE`: it builds on cycles the frame loop leaves).
    #[arg(long, value_name = "normal|idle", default_value_t = WorkerPriority::Normal)]
    pub worker_priority: WorkerPriority,
    #[command(flatten)]
    pub limits: Limits,
}

/// Timings of one rendered frame of one policy, ms.
#[derive(Clone, Copy, Debug, Default)]
pub struct FrameTiming {
    /// Frame index.
    pub frame: usize,
    /// Posing (engine's record).
    pub pose_ms: f64,
    /// Refit, rebuild and top-level update (without posing).
    pub update_ms: f64,
    /// Fresh build of the engine (first frame of a run only; includes posing).
    pub build_ms: f64,
    /// Vertex normals and instance normal matrices.
    pub normals_ms: f64,
    /// Primary and shadow rays with shading.
    pub trace_ms: f64,
    /// Wall time of all of the above.
    pub total_ms: f64,
    /// Rays cast.
    pub counts: FrameCounts,
    /// What the policy did.
    pub action: Action,
    /// Trace-weighted SAH ratio after the update.
    pub sah_ratio: f32,
}

/// What a render run did.
#[derive(Clone, Debug)]
pub struct RenderSummary {
    /// Where the images went (`None` in bench mode).
    pub out: Option<PathBuf>,
    /// Frames written as PNG.
    pub pngs: Vec<PathBuf>,
    /// The GIF, when asked.
    pub gif: Option<PathBuf>,
    /// Frame range rendered.
    pub range: (usize, usize),
    /// Per policy, its name and per-frame timings.
    pub timings: Vec<(String, Vec<FrameTiming>)>,
    /// Triangles in the scene.
    pub triangles: usize,
    /// Image size.
    pub size: (u32, u32),
    /// Where the camera came from.
    pub camera: String,
}

impl RenderSummary {
    /// Frames per second of posing, updating and tracing of policy `k` over the frames after
    /// the first (the first one builds), or over all when there is only one.
    #[must_use]
    pub fn fps(&self, k: usize) -> f64 {
        let t = &self.timings[k].1;
        let steady = if t.len() > 1 { &t[1..] } else { t };
        let ms: f64 = steady.iter().map(|f| f.total_ms).sum();
        if ms > 0.0 {
            steady.len() as f64 * 1e3 / ms
        } else {
            0.0
        }
    }
}

/// One policy's engine following the animation.
struct Pipeline<'s> {
    policy: Policy,
    src: GltfSource<'s>,
    engine: Option<Engine>,
    shading: EngineShading,
    renderer: Renderer,
    img: RgbImage,
    timings: Vec<FrameTiming>,
    packets: PacketUse,
    traversal: Traversal,
    worker: WorkerPriority,
}

impl<'s> Pipeline<'s> {
    fn new(
        scene: &'s Scene,
        anim: Option<usize>,
        times: FrameTimes,
        policy: Policy,
        settings: Settings,
    ) -> Result<Self> {
        Ok(Self {
            policy,
            src: GltfSource::new(scene, anim, times)?,
            engine: None,
            shading: EngineShading::new(),
            renderer: Renderer::new(settings),
            img: RgbImage::new(settings.width, settings.height),
            timings: Vec::new(),
            packets: PacketUse::DEFAULT,
            traversal: Traversal::DEFAULT,
            worker: WorkerPriority::Normal,
        })
    }

    /// Brings the engine to frame `f` (a fresh build on the first call).
    fn step(&mut self, f: usize) -> FrameTiming {
        let t0 = Instant::now();
        let mut timing = FrameTiming {
            frame: f,
            ..FrameTiming::default()
        };
        match &mut self.engine {
            None => {
                let config = EngineConfig {
                    policy: self.policy,
                    traversal: self.traversal,
                    worker: self.worker,
                    ..EngineConfig::default()
                };
                self.engine = Some(self.src.build(f, config));
                timing.build_ms = ms(t0);
                timing.action = Action::Rebuild;
                timing.sah_ratio = 1.0;
            }
            Some(e) => {
                // Timed here: the engine's update starts a new record without the pose time.
                self.src.advance(e, f);
                timing.pose_ms = ms(t0);
                let t = Instant::now();
                let s = *e.update();
                timing.update_ms = ms(t);
                timing.action = s.action;
                timing.sah_ratio = s.sah_ratio;
            }
        }
        let engine = self.engine.as_ref().expect("built above");
        let t1 = Instant::now();
        if timing.build_ms > 0.0 {
            self.shading.refresh_all(engine);
        } else {
            self.shading.refresh(engine, self.src.deforming());
        }
        timing.normals_ms = ms(t1);
        timing.total_ms = ms(t0);
        timing
    }

    fn render(&mut self, stage: &Stage, mut timing: FrameTiming) {
        let engine = self.engine.as_ref().expect("stepped first");
        let t = Instant::now();
        timing.counts = self.renderer.render(
            &self.shading.tracer(engine).with_packets(self.packets),
            stage,
            &mut self.img,
        );
        timing.trace_ms = ms(t);
        timing.total_ms += timing.trace_ms;
        self.timings.push(timing);
    }
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Runs `render`.
pub fn run(a: RenderArgs) -> Result<()> {
    let s = execute(&a)?;
    print_summary(&s, a.bench);
    Ok(())
}

/// Prints where the images went and the speed of each policy.
pub fn print_summary(s: &RenderSummary, per_frame: bool) {
    for (k, (name, t)) in s.timings.iter().enumerate() {
        if per_frame {
            println!(
                "policy {name}: frame  action   build_ms  pose_ms  update_ms  normals_ms  trace_ms  total_ms  primary  shadow  SAH ratio  work/px  max work"
            );
            for f in t {
                // A run's first frame is a fresh build (no pose or update of its own); the
                // others are posed and updated (no build).
                let built = f.frame == s.range.0;
                let (build, update) = (built.then_some(f.build_ms), (!built).then_some(()));
                // Traversal work is counted for heat maps only.
                let counted = f.counts.max_work > 0;
                println!(
                    "policy {name}: {:5}  {:7}  {:>8}  {:>7}  {:>9}  {:10.3}  {:8.3}  {:8.3}  {:7}  {:6}  {:9.3}  {:>7}  {:>8}",
                    f.frame,
                    f.action.name(),
                    or_dash(build, 3),
                    or_dash(update.map(|()| f.pose_ms), 3),
                    or_dash(update.map(|()| f.update_ms), 3),
                    f.normals_ms,
                    f.trace_ms,
                    f.total_ms,
                    f.counts.primary,
                    f.counts.shadow,
                    f.sah_ratio,
                    or_dash(counted.then(|| f.counts.work_per_pixel()), 1),
                    or_dash(counted.then_some(f.counts.max_work as f64), 0),
                );
            }
        }
        let steady = if t.len() > 1 { &t[1..] } else { &t[..] };
        let n = steady.len().max(1) as f64;
        let mean = |g: fn(&FrameTiming) -> f64| steady.iter().map(g).sum::<f64>() / n;
        let primary = mean(|f| f.counts.primary as f64);
        let shadow = mean(|f| f.counts.shadow as f64);
        let trace = mean(|f| f.trace_ms);
        let averaged = if t.len() > 1 {
            format!(
                "mean of the {} frame{} after the first (frame {}, a fresh build, excluded)",
                steady.len(),
                if steady.len() == 1 { "" } else { "s" },
                s.range.0
            )
        } else {
            "the only frame, a fresh build".to_string()
        };
        let shadow_note = if shadow > 0.0 {
            "one from each lit point: front-facing surface or ground"
        } else {
            "none without --shadows"
        };
        println!(
            "{name}: {} frames {}..{} at {}x{}, {} triangles: {:.1} fps, pose {:.2} + update {:.2} + normals {:.2} + trace {:.2} = {:.2} ms/frame ({averaged}); rays/frame: {:.0} primary (one per pixel) + {:.0} shadow ({shadow_note}) = {:.0}, {} Mrays/s while tracing",
            t.len(),
            s.range.0,
            s.range.1,
            s.size.0,
            s.size.1,
            s.triangles,
            s.fps(k),
            mean(|f| f.pose_ms),
            mean(|f| f.update_ms),
            mean(|f| f.normals_ms),
            trace,
            mean(|f| f.total_ms),
            primary,
            shadow,
            primary + shadow,
            or_dash((trace > 0.0).then(|| (primary + shadow) / (trace * 1e3)), 1),
        );
    }
    println!("camera: {}", s.camera);
    if let Some(out) = &s.out {
        println!("wrote {} PNG frame(s) to {}", s.pngs.len(), out.display());
    }
    if let Some(g) = &s.gif {
        println!("wrote {}", g.display());
    }
}

/// Renders as `a` asks and returns what was done.
pub fn execute(a: &RenderArgs) -> Result<RenderSummary> {
    args::init_threads(a.threads)?;
    let Size { w, h } = a.size;
    let (mut times, range) = args::timeline(a.frames, a.fps, FrameTimes::Fps(30.0), &a.limits)?;
    let policies: Vec<Policy> = match a.compare.len() {
        0 => vec![a.policy],
        2 => a.compare.clone(),
        n => bail!("--compare: {n} policies given; expected two, e.g. refit,rebuild"),
    };

    let scene = super::load_scene(&a.file, None)?;
    a.limits
        .memory
        .check_scene(&scene, args::RENDER_MEMORY, policies.len() as u64)?;
    let anim = args::animation_or_first(&scene, &a.file, a.animation.as_deref())?;
    if let FrameTimes::Fps(fps) = times {
        let d = anim.map_or(0.0, |k| scene.animations[k].duration);
        let n = args::frames_at(d, fps);
        if range.is_some() && n > args::MAX_TIMELINE as f64 {
            bail!(
                "{}: --fps {fps} over the animation's {d} s is a timeline of {} frames, above \
                 the bound of {} that --frames A..B indexes into (--frames N spreads N frames \
                 over the animation)",
                a.file.display(),
                args::count(n),
                args::MAX_TIMELINE
            );
        }
        if range.is_none() && n > a.limits.max_frames as f64 {
            let cut = args::LONG_CLIP_FRAMES.min(a.limits.max_frames);
            eprintln!(
                "note: {}: the animation is {d} s long, {} frames at {fps} fps, above \
                 --max-frames {}; rendering {cut} frames spread over it (--frames N spreads N, \
                 --frames A..B renders a stretch at --fps)",
                a.file.display(),
                args::count(n),
                a.limits.max_frames
            );
            times = FrameTimes::Count(cut as usize);
        }
    }
    // Per pipeline its image and the renderer's buffers, plus the composed image and the
    // GIF's RGBA copy.
    let images = a.size.pixels() * (16 * policies.len() as u64 + 8);
    a.limits.check_memory(
        &format!("--size {} (x{} policies)", a.size, policies.len()),
        images,
    )?;
    let settings = Settings {
        width: w,
        height: h,
        smooth: !a.flat,
        shadows: a.shadows,
        heatmap: a.heatmap.then_some(a.heat_max.unwrap_or(1)),
    };
    let mut pipes: Vec<Pipeline<'_>> = policies
        .iter()
        .map(|&p| {
            Pipeline::new(&scene, anim, times, p, settings).map(|mut pl| {
                pl.packets = a.packets;
                pl.traversal = a.traversal;
                pl.worker = a.worker_priority;
                pl
            })
        })
        .collect::<Result<_>>()?;
    // The last timeline entry is the animation's end: the same pose as its start when it
    // loops, so a full run stops before it; a range may include it.
    let last = pipes[0].src.frames();
    let (start, end) = match range {
        Some((s, e)) if e > last + 1 => bail!(
            "--frames {s}..{e}: the animation has frames 0..{} at this rate",
            last + 1
        ),
        Some(r) => r,
        None => (0, last.max(1)),
    };
    let frame_ms = match times {
        FrameTimes::Fps(f) => 1000.0 / f64::from(f),
        FrameTimes::Count(n) => {
            let d = anim.map_or(0.0, |k| scene.animations[k].duration);
            if d > 0.0 {
                f64::from(d) * 1000.0 / n as f64
            } else {
                100.0
            }
        }
    };

    // The camera: the file's own, else framed on the whole animation (the same for every
    // range, so that split runs join up).
    let (bounds, left_out) = animation_view(&scene, anim, pipes[0].src.times())?;
    let file_camera: Option<GltfCamera> = if a.auto_camera {
        None
    } else {
        match gltf_cameras(&scene) {
            Ok(c) => c.into_iter().next(),
            Err(e) => {
                eprintln!("warning: reading the file's cameras: {e}; framing automatically");
                None
            }
        }
    };
    let aspect = w as f32 / h as f32;
    let camera_note = match &file_camera {
        Some(c) => format!(
            "the file's camera {} (node {})",
            c.name.as_deref().unwrap_or("(unnamed)"),
            c.node
        ),
        None if left_out > 0 => format!(
            "framed on the animation's bounds, less {left_out} vertex use(s) far outside the rest"
        ),
        None => "framed on the animation's bounds".to_string(),
    };
    let mut stage: Option<Stage> = None;

    let out = (!a.bench).then(|| a.out.clone());
    if let Some(o) = &out {
        std::fs::create_dir_all(o).with_context(|| format!("creating {}", o.display()))?;
    }
    let stem = match (policies.len() > 1, a.heatmap) {
        (true, _) => "compare",
        (false, true) => "heatmap",
        (false, false) => "frame",
    };
    let partial = range.is_some();
    let gif_path = out.as_ref().filter(|_| a.gif).map(|o| {
        if partial {
            o.join(format!("{stem}_{start:04}-{end:04}.gif"))
        } else {
            o.join(format!("{stem}.gif"))
        }
    });
    let mut gif = match &gif_path {
        Some(p) => {
            let f =
                std::fs::File::create(p).with_context(|| format!("creating {}", p.display()))?;
            let mut g = GifEncoder::new_with_speed(BufWriter::new(f), 20);
            g.set_repeat(Repeat::Infinite)?;
            Some(g)
        }
        None => None,
    };
    let delay = image::Delay::from_numer_denom_ms((frame_ms * 100.0).round() as u32, 100);

    let bar = if a.bench {
        ProgressBar::hidden()
    } else {
        super::progress::bar((end - start) as u64, "frames", "rendering")
    };
    let mut pngs = Vec::new();
    let mut composed = RgbImage::new(1, 1);
    let mut heat_max = a.heat_max;
    for f in start..end {
        let mut stepped = Vec::with_capacity(pipes.len());
        for p in &mut pipes {
            stepped.push(p.step(f));
        }
        let camera = match &file_camera {
            Some(c) => {
                Camera::from_node(&pipes[0].src.poser().world_matrices()[c.node], c.projection)
            }
            None => Camera::framing(&bounds, aspect),
        };
        let st = stage.get_or_insert_with(|| Stage::new(camera, &bounds, !a.no_ground));
        st.camera = camera;
        for (p, t) in pipes.iter_mut().zip(stepped) {
            p.render(st, t);
        }
        if a.heatmap && heat_max.is_none() {
            let q = dynbvh::render::work_quantile(pipes.iter().map(|p| p.renderer.work()), 0.98);
            for p in &mut pipes {
                p.renderer.set_heat_max(q);
                p.renderer.recolor(&mut p.img, q);
            }
            heat_max = Some(q);
        }
        if out.is_none() {
            bar.inc(1);
            continue;
        }
        let img: &RgbImage = if pipes.len() == 1 {
            if a.heatmap {
                let p = &mut pipes[0];
                let t = p.timings.last().copied().unwrap_or_default();
                label(&mut p.img, &p.policy, &t, true);
            }
            &pipes[0].img
        } else {
            compose(&mut pipes, &mut composed, a.heatmap);
            &composed
        };
        if let Some(o) = &out {
            let path = o.join(format!("{stem}_{f:04}.png"));
            img.save(&path)
                .with_context(|| format!("writing {}", path.display()))?;
            pngs.push(path);
        }
        if let Some(g) = &mut gif {
            let rgba = image::DynamicImage::ImageRgb8(img.clone()).into_rgba8();
            g.encode_frame(image::Frame::from_parts(rgba, 0, 0, delay))
                .context("encoding the GIF")?;
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    drop(gif);
    Ok(RenderSummary {
        out,
        pngs,
        gif: gif_path,
        range: (start, end),
        timings: pipes
            .into_iter()
            .map(|p| (p.policy.to_string(), p.timings))
            .collect(),
        triangles: scene.triangle_count(),
        size: (w, h),
        camera: camera_note,
    })
}

/// Writes what a frame did into its top-left corner, in words: policy, frame (numbered as the
/// PNG files are), what the policy did, the SAH ratio to the last build, and for heat maps the
/// mean work per covered pixel.
fn label(img: &mut RgbImage, policy: &Policy, t: &FrameTiming, heat: bool) {
    let scale = (img.height() / 480).max(1);
    let m = i64::from(4 * scale);
    let text = format!(
        "{policy} \u{2014} frame {} \u{2014} {} \u{2014} SAH {:.2}x last build",
        t.frame,
        t.action.name(),
        t.sah_ratio
    );
    font::draw_label(img, m, m, scale, &text, [255, 255, 255]);
    if heat {
        let text = format!(
            "{:.0} nodes+triangles per covered pixel",
            t.counts.work_per_pixel()
        );
        let y = m + i64::from(font::text_height(scale) + 2 * scale);
        font::draw_label(img, m, y, scale, &text, [255, 255, 255]);
    }
}

/// The pipelines' images side by side, labelled, separated by a dark gap.
fn compose(pipes: &mut [Pipeline<'_>], out: &mut RgbImage, heat: bool) {
    let (w, h) = pipes[0].img.dimensions();
    let gap = 4;
    let total_w = w * pipes.len() as u32 + gap * (pipes.len() as u32 - 1);
    if out.dimensions() != (total_w, h) {
        *out = RgbImage::new(total_w, h);
    }
    for px in out.pixels_mut() {
        px.0 = [20, 20, 24];
    }
    for (k, p) in pipes.iter_mut().enumerate() {
        let t = p.timings.last().copied().unwrap_or_default();
        label(&mut p.img, &p.policy, &t, heat);
        let x0 = k as u32 * (w + gap);
        image::imageops::replace(out, &p.img, i64::from(x0), 0);
    }
}
