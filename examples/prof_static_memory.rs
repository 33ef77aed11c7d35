//! What adding a large mesh as static costs in memory and time: the process's resident and
//! peak memory (`VmRSS`, `VmHWM` from `/proc/self/status`, Linux only) after loading the mesh
//! and after adding it to a fresh engine COUNT times, and each addition's wall time:
//! `cargo run --release --example prof_static_memory MESH [COUNT] [ordinary]` (`ordinary`
//! adds it with `Engine::add_mesh` instead, for comparison). MESH as `common/input.rs` reads it.
use dynbvh::engine::{Engine, EngineConfig};

#[path = "common/input.rs"]
mod input;

/// Resident and peak memory in MiB.
fn memory() -> (u64, u64) {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let kib = |key: &str| {
        status
            .lines()
            .find(|l| l.starts_with(key))
            .and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
            .unwrap_or(0)
    };
    (kib("VmRSS:") / 1024, kib("VmHWM:") / 1024)
}

fn main() {
    let mut args = std::env::args().skip(1);
    let mesh = input::mesh(&args.next().expect("mesh"));
    let count: usize = args.next().map_or(1, |v| v.parse().unwrap());
    let ordinary = args.next().as_deref() == Some("ordinary");
    let (rss, peak) = memory();
    println!(
        "{} triangles loaded: resident {rss} MiB, peak {peak} MiB",
        mesh.indices.len()
    );
    let mut e = Engine::new(EngineConfig::default());
    let mut ms = Vec::new();
    for _ in 0..count {
        let (p, i) = (mesh.positions.clone(), mesh.indices.clone());
        let t = std::time::Instant::now();
        let id = if ordinary {
            e.add_mesh(p, i)
        } else {
            e.add_static_mesh(p, i)
        };
        ms.push(t.elapsed().as_secs_f64() * 1e3);
        std::hint::black_box(id);
    }
    let (rss, peak) = memory();
    let how = if ordinary { "ordinary" } else { "static" };
    println!("after {count} {how}: resident {rss} MiB, peak {peak} MiB; ms each {ms:.1?}");
}
