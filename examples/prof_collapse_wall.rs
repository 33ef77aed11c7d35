//! The greedy BVH8 collapse of one binary tree on the global rayon pool, in wall-clock time:
//! `RAYON_NUM_THREADS=2 cargo run --release --example prof_collapse_wall MESH.tri`.
//!
//! Prints the median and least of 15 collapses into the tree's own storage (as an engine's
//! rebuild collapses), of 5 into fresh storage (as a cold build does), and a hash of the
//! nodes and blocks, so that builds and thread counts can be checked to give the same tree.

use dynbvh::bvh::{BuildParams, MeshBvh, MeshBvh8};
use std::hash::{Hash, Hasher};
use std::time::Instant;

fn stats(mut v: Vec<f64>) -> (f64, f64) {
    v.sort_by(f64::total_cmp);
    (v[v.len() / 2], v[0])
}

fn main() {
    let path = std::env::args().nth(1).expect("MESH.tri");
    let mesh = dynbvh::io::read_tri(path.as_ref()).unwrap();
    let bin = MeshBvh::build(&mesh, &BuildParams::BINNED);
    let mut w = MeshBvh8::from_mesh_bvh(&bin);
    let time = |f: &mut dyn FnMut()| {
        let t = Instant::now();
        f();
        t.elapsed().as_secs_f64() * 1e3
    };
    let warm = stats(
        (0..15)
            .map(|_| time(&mut || w.collapse_from(&bin)))
            .collect(),
    );
    let cold = stats(
        (0..5)
            .map(|_| time(&mut || w = MeshBvh8::from_mesh_bvh(&bin)))
            .collect(),
    );
    let mut h = std::collections::hash_map::DefaultHasher::new();
    format!("{:?}{:?}", w.nodes(), w.blocks()).hash(&mut h);
    println!(
        "{path}: {} threads, {} nodes, tree hash {:016x}; into its storage median {:.2} ms (least {:.2}), into fresh storage {:.2} ms (least {:.2})",
        rayon::current_num_threads(),
        w.nodes().len(),
        h.finish(),
        warm.0,
        warm.1,
        cold.0,
        cold.1
    );
}
