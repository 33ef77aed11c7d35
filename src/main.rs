//! The `dynbvh` command line: parses arguments and calls the library.

mod cli;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "dynbvh",
    version,
    about = "Ray tracing animated scenes with BVHs that refit or rebuild as they must"
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand)]
enum Command {
    /// Every builder on one mesh: build time, SAH cost, size, Mrays/s, agreement with brute force.
    BuildBench(cli::build_bench::BuildBenchArgs),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Some(Command::BuildBench(a)) => cli::build_bench::run(a),
        None => Ok(()),
    }
}
