//! Posing and loading throughput of `dynbvh::anim` (issue 3, "What it must reach").
//!
//! - `pose/tube_1m/threads1`, `pose/tube_1m/threads2`: `Poser::pose(t)` of a generated skinned
//!   tube of 1,000,042 vertices with 4 non-zero weights each (`skinned_tube` with cubic
//!   B-spline weights over 16 joints), at successive times 1/60 s apart, inside a 1-thread and
//!   a 2-thread rayon pool. Throughput is in vertices.
//! - `pose/tube_24k/*`: the same on a 23,817-vertex tube, whose data stays in cache: what the
//!   arithmetic alone allows.
//! - `load/metal_rough_spheres`: `Scene::load` of the 1M-triangle
//!   `../shared/gltf-samples/MetalRoughSpheresNoTextures/MetalRoughSpheresNoTextures.glb`
//!   (skipped with a message when the samples are missing); `load/metal_rough_spheres_flattened`
//!   adds `Scene::flatten_rest`, the 1,040,409 world-space triangles.
//!
//! Run (from the repository root):
//!
//! ```sh
//! cargo bench --bench pose                                              # everything
//! cargo bench --bench pose -- --warm-up-time 1 --measurement-time 3     # short
//! cargo bench --bench pose -- pose/tube_1m --warm-up-time 1 --measurement-time 3
//! ```
//!
//! Measured with the short command on the 2-core development VM (Xeon, AVX-512, the
//! `target-cpu=native` build of `.cargo/config.toml`), in runs where both cores were otherwise
//! idle; medians:
//!
//! | benchmark | 1 thread | 2 threads | 2 threads / 1 thread |
//! |---|---|---|---|
//! | `pose/tube_1m` | 6.42 ms, 156 M vertices/s | 2.19 ms, 457 M vertices/s | 2.9 |
//! | `pose/tube_24k` | 91 µs, 261 M vertices/s | 49 µs, 484 M vertices/s | 1.85 |
//!
//! | benchmark | median |
//! |---|---|
//! | `load/metal_rough_spheres` | 15.2 ms |
//! | `load/metal_rough_spheres_flattened` | 20.8 ms |
//!
//! The skinning loop before it blended matrices (commit 71a73a6), side by side in one quiet
//! run: `pose/tube_1m` 11.1 ms (90 M vertices/s) on 1 thread, 5.2 ms (193 M vertices/s) on 2.
//!
//! Issue 3 asks for at least 100 M vertices/s on one core and at least 60% more with the
//! second, and for the sample to load in under 1 s. The 1M tube's super-linear scaling is the
//! VM's: one thread streams its ~60 bytes per vertex (rest positions, joints, weights, output)
//! more slowly alone than two threads do together, and its one-thread figure moves between
//! 155 and 205 M vertices/s with what the other core is doing; the cache-resident tube scales
//! as expected. When another process holds the second core, the 2-thread figures fall to the
//! 1-thread ones: compare figures taken side by side in one quiet run.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use dynbvh::anim::generate::{TubeWeights, skinned_tube};
use dynbvh::anim::{LoadOptions, Scene};
use std::hint::black_box;
use std::path::Path;

/// Triangles of the generated tube: 16 segments × 58,825 rings, 1,000,042 vertices.
const TUBE_TRIANGLES: usize = 1_882_400;
/// Triangles of a tube small enough to stay in cache (16 × 1,400, 23,817 vertices): what the
/// arithmetic alone allows.
const SMALL_TUBE_TRIANGLES: usize = 44_800;
/// Joints of the generated tubes' chain.
const TUBE_JOINTS: usize = 16;
/// Time between successive poses.
const FRAME: f32 = 1.0 / 60.0;

fn pose(c: &mut Criterion) {
    let mut group = c.benchmark_group("pose");
    group.sample_size(20);
    for (name, triangles) in [
        ("tube_1m", TUBE_TRIANGLES),
        ("tube_24k", SMALL_TUBE_TRIANGLES),
    ] {
        let g = skinned_tube(triangles, TUBE_JOINTS, TubeWeights::Cubic);
        let (scene, warnings) =
            Scene::from_slice(Path::new("tube.glb"), &g.glb, &LoadOptions::default())
                .expect("the generated tube loads");
        assert!(warnings.is_empty(), "{warnings:?}");
        let skin = scene.meshes[0].skin.as_ref().expect("the tube is skinned");
        assert!(skin.influences == 4 && skin.weights.iter().all(|&w| w > 0.0));
        group.throughput(Throughput::Elements(scene.vertex_count() as u64));
        for threads in [1, 2] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("a rayon pool");
            let mut poser = scene.poser(Some(0)).expect("the tube has an animation");
            let mut t = 0.0f32;
            group.bench_function(BenchmarkId::new(name, format!("threads{threads}")), |b| {
                pool.install(|| {
                    b.iter(|| {
                        t += FRAME;
                        poser.pose(t);
                        black_box(poser.positions(0).last().copied())
                    });
                });
            });
        }
    }
    group.finish();
}

fn load(c: &mut Criterion) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/gltf-samples/MetalRoughSpheresNoTextures/MetalRoughSpheresNoTextures.glb");
    if !path.exists() {
        eprintln!(
            "skipping load/metal_rough_spheres: {} not found (the glTF samples live in ../shared/gltf-samples)",
            path.display()
        );
        return;
    }
    let mut group = c.benchmark_group("load");
    group.sample_size(10);
    group.bench_function("metal_rough_spheres", |b| {
        b.iter(|| {
            let (scene, _) = Scene::load(&path).expect("the sample loads");
            black_box(scene.triangle_count())
        });
    });
    group.bench_function("metal_rough_spheres_flattened", |b| {
        b.iter(|| {
            let (scene, _) = Scene::load(&path).expect("the sample loads");
            black_box(scene.flatten_rest().indices.len())
        });
    });
    group.finish();
}

criterion_group!(benches, pose, load);
criterion_main!(benches);
