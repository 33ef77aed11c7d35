//! Posing and loading throughput of `dynbvh::anim` (issue 3, "What it must reach").
//!
//! Every `pose/*` benchmark times `Poser::pose(t)` of generated skinned tubes (`skinned_tube`
//! with cubic B-spline weights over 16 joints: 4 non-zero weights per vertex) at successive
//! times 1/60 s apart, inside a 1-thread and then a 2-thread rayon pool. Throughput is in
//! vertices per second. One pose of a 1,000,042-vertex tube touches about 48 MB (rest
//! positions 12 MB, joint indices 8 MB, weights 16 MB, output 12 MB), so what the figures mean
//! depends on where those bytes live; the three regimes:
//!
//! - `pose/tube_1m_x4/*` (**the issue's figure**): four separately loaded copies of the
//!   1,000,042-vertex tube, posed in turn, one per iteration. The working set (about 190 MB)
//!   is far beyond the 32 MiB L3 for both thread counts, so each pose streams its 48 MB from
//!   DRAM whether one core does it or two: the fair 1-thread / 2-thread comparison.
//! - `pose/tube_1m/*`: one copy posed over and over. Its 48 MB do not fit the 32 MiB L3 for
//!   one thread, but with two, part of each thread's half could stay cached from one pose to
//!   the next and flatter the 2-thread figure. Kept beside `tube_1m_x4` to show whether it
//!   does (on the development VM it did not: posing is bound by arithmetic at this rate).
//! - `pose/tube_24k/*`: a 23,817-vertex tube (about 1.1 MB), which stays in cache: what the
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
//! cargo bench --bench pose -- pose/ --warm-up-time 1 --measurement-time 3
//! ```
//!
//! The development VM has 2 cores of an AMD EPYC (Zen 5, AVX-512, 2 MiB L2 per core, 32 MiB
//! shared L3); the build is `.cargo/config.toml`'s `target-cpu=native`. Measured figures, the
//! command and how noisy they were: `benches/README.md`, section `pose`.

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

/// Copies of the 1M-vertex tube posed in turn by `pose/tube_1m_x4`: about 190 MB of rest
/// positions, joints, weights and output, far beyond the L3.
const COPIES: usize = 4;

/// Loads the generated tube of `triangles` triangles `copies` times (separate allocations).
fn tubes(triangles: usize, copies: usize) -> Vec<Scene> {
    let g = skinned_tube(triangles, TUBE_JOINTS, TubeWeights::Cubic);
    (0..copies)
        .map(|_| {
            let (scene, warnings) =
                Scene::from_slice(Path::new("tube.glb"), &g.glb, &LoadOptions::default())
                    .expect("the generated tube loads");
            assert!(warnings.is_empty(), "{warnings:?}");
            let skin = scene.meshes[0].skin.as_ref().expect("the tube is skinned");
            assert!(skin.influences == 4 && skin.weights.iter().all(|&w| w > 0.0));
            scene
        })
        .collect()
}

fn pose(c: &mut Criterion) {
    let mut group = c.benchmark_group("pose");
    group.sample_size(20);
    let big = tubes(TUBE_TRIANGLES, COPIES);
    let small = tubes(SMALL_TUBE_TRIANGLES, 1);
    for (name, scenes) in [
        ("tube_1m_x4", &big[..]),
        ("tube_1m", &big[..1]),
        ("tube_24k", &small[..]),
    ] {
        group.throughput(Throughput::Elements(scenes[0].vertex_count() as u64));
        for threads in [1, 2] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("a rayon pool");
            let mut posers: Vec<_> = scenes
                .iter()
                .map(|s| s.poser(Some(0)).expect("the tube has an animation"))
                .collect();
            let (mut t, mut k) = (0.0f32, 0usize);
            group.bench_function(BenchmarkId::new(name, format!("threads{threads}")), |b| {
                pool.install(|| {
                    b.iter(|| {
                        t += FRAME;
                        k = (k + 1) % posers.len();
                        let poser = &mut posers[k];
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
