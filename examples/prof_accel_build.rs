//! Build time (CPU) of the other structures against the binned BVH's, builds alternating in one
//! process, medians: `cargo run --release --example prof_accel_build MESH.tri [NAMES] [RUNS]`
//! (MESH a `.tri`, `.obj` or glTF file, flattened at rest; NAMES comma-separated, default
//! `grid`; RUNS default 5; `BIH_SAH=n` builds the BIH with the SAH tried at its nodes of at
//! least 1/n of the triangles, 0: nowhere). Run with `RAYON_NUM_THREADS=1` to
//! build the BVH on one thread. Prints each structure's builds, the BVH's, and the ratio of
//! the medians.
use dynbvh::accel::{AccelKind, Bih, BihParams};
use dynbvh::bvh::{BuildParams, MeshBvh};

#[path = "common/cpu.rs"]
mod cpu;
use cpu::{cpu_s, median};
#[path = "common/input.rs"]
mod input;

fn main() {
    let mut args = std::env::args().skip(1);
    let mesh = input::mesh(&args.next().expect("mesh"));
    let names = args.next().unwrap_or_else(|| "grid".into());
    let runs: usize = args.next().map_or(5, |r| r.parse().unwrap());
    let kinds: Vec<AccelKind> = names.split(',').map(|n| n.parse().unwrap()).collect();
    let bih_sah = std::env::var("BIH_SAH")
        .ok()
        .map(|v| v.parse::<usize>().unwrap());
    let mut bvh_ms = Vec::new();
    let mut ms = vec![Vec::new(); kinds.len()];
    for _ in 0..runs {
        let c = cpu_s();
        drop(MeshBvh::build(&mesh, &BuildParams::BINNED));
        bvh_ms.push((cpu_s() - c) * 1e3);
        for (k, m) in kinds.iter().zip(&mut ms) {
            let c = cpu_s();
            match (k, bih_sah) {
                (AccelKind::Bih, Some(sah_share)) => drop(Bih::build(
                    &mesh,
                    &BihParams {
                        sah_share,
                        ..BihParams::default()
                    },
                )),
                _ => drop(k.build(&mesh)),
            }
            m.push((cpu_s() - c) * 1e3);
        }
    }
    let b = median(bvh_ms.clone());
    println!("binned16      median {b:8.1} ms cpu  {bvh_ms:.1?}");
    for (name, m) in names.split(',').zip(&ms) {
        let x = median(m.clone());
        println!(
            "{name:<13} median {x:8.1} ms cpu  {m:.1?}  {:.3}x binned16",
            x / b
        );
    }
}
