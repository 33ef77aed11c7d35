//! A rotating multi-beam lidar over an animated glTF scene: each frame the scene is posed at
//! the frame's time, the engine updates its trees, the sensor's head turns a full revolution
//! (beams fanned in elevation, every azimuth step), the returns are traced as one batch (which
//! feeds the refit-or-rebuild policy its trace time) and written as a PLY point cloud with
//! each point's surface normal.
//!
//! `cargo run --release --example lidar -- [--file animations/lidar_cloth.glb] [--frames 8]
//! [--beams 16] [--azimuths 360] [--out target/lidar]`

use anyhow::{Context, Result};
use clap::Parser;
use dynbvh::anim::Scene;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::{EngineConfig, FrameSource};
use dynbvh::geom::Ray;
use dynbvh::glam::Vec3;
use std::io::Write;
use std::path::PathBuf;

/// Scan an animated glTF scene with a spinning lidar and write a PLY cloud per frame.
#[derive(Parser, Debug, Clone)]
pub struct Args {
    /// The glTF scene (its first animation is played).
    #[arg(long, default_value = "animations/lidar_cloth.glb")]
    pub file: PathBuf,
    /// Frames over one loop of the animation.
    #[arg(long, default_value_t = 8)]
    pub frames: usize,
    /// Beams (elevation channels) of the sensor.
    #[arg(long, default_value_t = 16)]
    pub beams: usize,
    /// Azimuth steps per revolution.
    #[arg(long, default_value_t = 360)]
    pub azimuths: usize,
    /// Folder of the clouds (`frame_000.ply`, ...).
    #[arg(long, default_value = "target/lidar")]
    pub out: PathBuf,
}

/// What a run did, per frame: returns and rebuilds.
#[derive(Debug, Default)]
pub struct Summary {
    /// Points written per frame.
    pub points: Vec<usize>,
    /// Mesh rebuilds over the run.
    pub rebuilds: u32,
}

/// The sensor's rays: from `origin`, `beams` channels from 60° to 5° below the horizon,
/// `azimuths` steps round the vertical axis (y up).
fn sensor_rays(origin: Vec3, beams: usize, azimuths: usize, out: &mut Vec<Ray>) {
    out.clear();
    for a in 0..azimuths {
        let phi = a as f32 * std::f32::consts::TAU / azimuths as f32;
        for b in 0..beams {
            let s = if beams > 1 {
                b as f32 / (beams - 1) as f32
            } else {
                0.5
            };
            let elev = (-60.0 + 55.0 * s).to_radians();
            let d = Vec3::new(elev.cos() * phi.cos(), elev.sin(), elev.cos() * phi.sin());
            out.push(Ray::new(origin, d));
        }
    }
}

/// Writes a binary little-endian PLY of points with normals.
fn write_ply(path: &std::path::Path, points: &[(Vec3, Vec3)]) -> Result<()> {
    let mut f = std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?,
    );
    write!(
        f,
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\n\
         property float y\nproperty float z\nproperty float nx\nproperty float ny\n\
         property float nz\nend_header\n",
        points.len()
    )?;
    for (p, n) in points {
        for v in [p.x, p.y, p.z, n.x, n.y, n.z] {
            f.write_all(&v.to_le_bytes())?;
        }
    }
    f.flush()?;
    Ok(())
}

/// Runs the scan.
pub fn run(args: &Args) -> Result<Summary> {
    let (scene, _warnings) = Scene::load(&args.file)?;
    let anim = (!scene.animations.is_empty()).then_some(0);
    let mut src = GltfSource::new(&scene, anim, FrameTimes::Count(args.frames.max(1)))?;
    let mut engine = src.engine(EngineConfig::default());
    let bounds = engine.bounds();
    // Over the middle of the scene, a twentieth of its diagonal above its top.
    let origin = Vec3::new(
        bounds.center().x,
        bounds.max.y + 0.05 * bounds.extent().length(),
        bounds.center().z,
    );
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let mut rays = Vec::new();
    sensor_rays(origin, args.beams, args.azimuths, &mut rays);
    let mut hits = vec![None; rays.len()];
    let mut cloud = Vec::with_capacity(rays.len());
    let mut summary = Summary::default();
    for f in 0..src.frames() {
        src.advance(&mut engine, f);
        summary.rebuilds += engine.update().rebuilds;
        engine.trace_closest(&rays, &mut hits);
        cloud.clear();
        cloud.extend(hits.iter().flatten().map(|h| {
            let d = engine.hit_detail(h);
            (d.position, d.normal)
        }));
        write_ply(&args.out.join(format!("frame_{f:03}.ply")), &cloud)?;
        summary.points.push(cloud.len());
    }
    Ok(summary)
}

#[allow(dead_code)]
fn main() -> Result<()> {
    let args = Args::parse();
    let s = run(&args)?;
    for (f, n) in s.points.iter().enumerate() {
        println!("frame {f:3}: {n} returns");
    }
    println!(
        "{} frames, {} rebuilds; clouds in {}",
        s.points.len(),
        s.rebuilds,
        args.out.display()
    );
    Ok(())
}
