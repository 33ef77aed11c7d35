//! The `dynbvh` command line: parses arguments and calls the library.

mod cli;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "dynbvh",
    version,
    about = "Ray tracing animated scenes with BVHs that refit or rebuild as they must",
    after_help = "With no command, dynbvh runs the default job: it renders animations/explode.glb \
                  (frames, GIF, refit-against-rebuild heat maps), benchmarks every policy, \
                  draws the charts and sweeps the lidar scene, all into out/. No subcommand \
                  runs it."
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// Let glTF files read buffers whose URI is absolute or leaves the file's folder (refused
    /// by default: a file should not make dynbvh read what its user did not hand it).
    #[arg(long, global = true)]
    allow_outside_files: bool,
}

#[derive(Subcommand)]
enum Command {
    /// Every refit-or-rebuild policy on the same frames and rays of an animation: summary
    /// table, per-frame CSV and JSON, charts, and the ratio of each to the best schedule.
    Bench(cli::bench::BenchArgs),
    /// Every builder on one mesh: build time, SAH cost, size, Mrays/s, agreement with brute force.
    BuildBench(cli::build_bench::BuildBenchArgs),
    /// The acceleration structures per frame of an animation: the BVH and BIH refitted, the
    /// kd-tree, grid and octree rebuilt; update and trace time at each ray count per frame.
    AccelBench(cli::accel_bench::AccelBenchArgs),
    /// Summarize a glTF file: scenes, meshes, skins, morph targets, animations, instance classes.
    Info(cli::info::InfoArgs),
    /// Pose a glTF scene at a time and write its triangles as OBJ or PLY.
    Pose(cli::pose::PoseArgs),
    /// Generate an animated test scene as .glb.
    Gen(cli::r#gen::GenArgs),
    /// Render an animation's frames as PNGs (and a GIF): shaded, as traversal-work heat maps,
    /// or under two policies side by side.
    Render(cli::render::RenderArgs),
    /// The rungs between refit and rebuild (optimise, partial rebuild, rebuild) on an
    /// animation's largest deforming mesh: time, and how much of the quality lost to
    /// refitting each wins back.
    Rungs(cli::rungs::RungsArgs),
    /// A tree built for the whole clip (from sampled poses) against one built at the first
    /// frame, both refitted through an animation: SAH and ray work over fresh builds.
    Clip(cli::clip::ClipArgs),
}

fn main() -> std::process::ExitCode {
    // Errors are printed as one line of causes, without a backtrace: they describe bad input,
    // not a bug.
    match run(Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    cli::set_allow_outside_files(cli.allow_outside_files);
    match cli.command {
        Some(Command::BuildBench(a)) => cli::build_bench::run(a),
        Some(Command::AccelBench(a)) => cli::accel_bench::run(a),
        Some(Command::Bench(a)) => cli::bench::run(a),
        Some(Command::Info(a)) => cli::info::run(a),
        Some(Command::Pose(a)) => cli::pose::run(a),
        Some(Command::Gen(a)) => cli::r#gen::run(a),
        Some(Command::Render(a)) => cli::render::run(a),
        Some(Command::Rungs(a)) => cli::rungs::run(a),
        Some(Command::Clip(a)) => cli::clip::run(a),
        None => cli::default_job::run(),
    }
}
