//! Criterion benchmarks of the BVH core: build (every builder preset), refit (rest pose to a
//! deformed pose), and closest-hit / any-hit traversal with coherent (camera) and incoherent
//! (random) rays, on meshes of about 100k and 1M triangles.
//!
//! Benchmark ids are `<kind>/<input>/<variant>`, e.g. `build/sphere_1m/binned16`,
//! `refit/gltf_spheres/binned16`, `closest/bumpy_100k/camera`, so a filter picks a subset:
//! `cargo bench --bench bvh -- build/sphere_100k`. Inputs are loaded on first use, so a filter
//! that skips an input never loads it. See `benches/README.md`.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use dynbvh::anim::Scene;
use dynbvh::bvh::{BuildParams, MeshBvh, MeshBvh4, MeshBvh8};
use dynbvh::geom::shapes::{bumpy_sphere, sine_deform};
use dynbvh::geom::{Aabb, Ray, TriMesh};
use dynbvh::io::{read_rays, read_tri};
use dynbvh::report::rays::{camera_rays, random_rays};
use std::cell::OnceCell;
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Rays traced per iteration of a traversal benchmark (a 256 x 256 image for camera rays).
const RAYS_PER_ITER: usize = 1 << 16;
/// Side of the camera image when the rays are generated here.
const CAMERA_SIDE: usize = 256;
/// Amplitude of the synthetic deformation (fraction of the box's largest extent), as in the
/// shared `_def` inputs.
const DEFORM_AMPLITUDE: f32 = 0.1;
/// Meshes with at least this many triangles get the small sample size.
const LARGE: usize = 500_000;

/// Where an input comes from.
enum Source {
    /// A glTF file, flattened at rest; refit goes to a sine deformation of it.
    Gltf(PathBuf),
    /// `bumpy_sphere(n)`; refit goes to its sine deformation.
    Synthetic(usize),
    /// A shared benchmark input: `<stem>.tri`, `<stem>_def.tri`, `<stem>_primary.rays`,
    /// `<stem>_random.rays` in `dir`.
    Shared { dir: PathBuf, stem: String },
}

/// A mesh, its deformed pose, and the two ray subsets.
struct Loaded {
    rest: TriMesh,
    deformed: TriMesh,
    camera: Vec<Ray>,
    random: Vec<Ray>,
    /// Binned-16 tree over the rest pose: the one traversal and refit run on.
    bvh: OnceCell<MeshBvh>,
    /// That tree collapsed into 4- and 8-wide trees.
    wide: OnceCell<(MeshBvh4, MeshBvh8)>,
}

impl Loaded {
    fn bvh(&self) -> &MeshBvh {
        self.bvh
            .get_or_init(|| MeshBvh::build(&self.rest, &BuildParams::BINNED))
    }

    fn wide(&self) -> &(MeshBvh4, MeshBvh8) {
        self.wide.get_or_init(|| {
            (
                MeshBvh4::from_mesh_bvh(self.bvh()),
                MeshBvh8::from_mesh_bvh(self.bvh()),
            )
        })
    }
}

/// One benchmark input, loaded on first use.
struct Input {
    name: String,
    source: Source,
    /// Approximate triangle count, for choosing the sample size before loading.
    approx_tris: usize,
    loaded: OnceCell<Loaded>,
}

impl Input {
    fn get(&self) -> &Loaded {
        self.loaded.get_or_init(|| {
            eprintln!("loading input {} ...", self.name);
            let l = self.source.load();
            eprintln!(
                "input {}: {} triangles, {} camera and {} random rays per iteration",
                self.name,
                l.rest.len(),
                l.camera.len(),
                l.random.len()
            );
            l
        })
    }

    fn large(&self) -> bool {
        self.approx_tris >= LARGE
    }
}

impl Source {
    fn load(&self) -> Loaded {
        match self {
            Source::Gltf(path) => {
                let (scene, _warnings) = Scene::load(path)
                    .unwrap_or_else(|e| panic!("cannot load {}: {e}", path.display()));
                generated(scene.flatten_rest())
            }
            Source::Synthetic(n) => generated(bumpy_sphere(*n)),
            Source::Shared { dir, stem } => {
                let tri = |s: &str| {
                    let p = dir.join(format!("{s}.tri"));
                    read_tri(&p).unwrap_or_else(|e| panic!("cannot read {}: {e}", p.display()))
                };
                let rays = |s: &str| {
                    let p = dir.join(format!("{stem}_{s}.rays"));
                    read_rays(&p).unwrap_or_else(|e| panic!("cannot read {}: {e}", p.display()))
                };
                let rest = tri(stem);
                let deformed = tri(&format!("{stem}_def"));
                assert_eq!(
                    rest.len(),
                    deformed.len(),
                    "{stem}_def must have the triangles of {stem}"
                );
                Loaded {
                    camera: exactly(image_subset(&rays("primary"), RAYS_PER_ITER)),
                    random: exactly(rays("random")),
                    rest,
                    deformed,
                    bvh: OnceCell::new(),
                    wide: OnceCell::new(),
                }
            }
        }
    }
}

/// A mesh of our own: its sine deformation, and camera and random rays around its box.
fn generated(rest: TriMesh) -> Loaded {
    let mut moved = rest.positions.clone();
    sine_deform(&rest.positions, &mut moved, DEFORM_AMPLITUDE, 0.0);
    let deformed = TriMesh::new(moved, rest.indices.clone());
    let bounds: Aabb = rest.bounds();
    Loaded {
        camera: camera_rays(&bounds, CAMERA_SIDE, CAMERA_SIDE),
        random: random_rays(&bounds, RAYS_PER_ITER, 0x5eed),
        rest,
        deformed,
        bvh: OnceCell::new(),
        wide: OnceCell::new(),
    }
}

/// Exactly [`RAYS_PER_ITER`] rays: the first ones, repeated if there are fewer.
fn exactly(rays: Vec<Ray>) -> Vec<Ray> {
    assert!(!rays.is_empty(), "empty ray set");
    rays.iter().cycle().take(RAYS_PER_ITER).copied().collect()
}

/// A coherent subset of about `n` camera rays (see `dynbvh::report::rays::image_subset`).
fn image_subset(rays: &[Ray], n: usize) -> Vec<Ray> {
    dynbvh::report::rays::image_subset(rays, n)
}

/// The inputs that exist on this machine; a message for each one that does not.
fn inputs() -> Vec<Input> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut v = Vec::new();
    let gltf = root.join("../shared/gltf-samples");
    for (name, file, tris) in [
        (
            "gltf_transmission",
            "TransmissionTest/TransmissionTest.glb",
            129_000,
        ),
        (
            "gltf_spheres",
            "MetalRoughSpheresNoTextures/MetalRoughSpheresNoTextures.glb",
            1_040_000,
        ),
    ] {
        let path = gltf.join(file);
        if path.is_file() {
            v.push(Input {
                name: name.into(),
                source: Source::Gltf(path),
                approx_tris: tris,
                loaded: OnceCell::new(),
            });
        } else {
            eprintln!(
                "skipping input {name}: {} not found (the glTF samples live in ../shared/gltf-samples)",
                path.display()
            );
        }
    }
    for (name, n) in [("bumpy_100k", 100_000), ("bumpy_1m", 1_000_000)] {
        v.push(Input {
            name: name.into(),
            source: Source::Synthetic(n),
            approx_tris: n,
            loaded: OnceCell::new(),
        });
    }
    let dir = std::env::var_os("DYNBVH_BENCH_INPUTS")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("target/bench-inputs"));
    for (stem, tris) in [("sphere_100k", 100_820), ("sphere_1m", 1_003_520)] {
        let files = [
            format!("{stem}.tri"),
            format!("{stem}_def.tri"),
            format!("{stem}_primary.rays"),
            format!("{stem}_random.rays"),
        ];
        let missing: Vec<&String> = files.iter().filter(|f| !dir.join(f).is_file()).collect();
        if missing.is_empty() {
            v.push(Input {
                name: stem.into(),
                source: Source::Shared {
                    dir: dir.clone(),
                    stem: stem.into(),
                },
                approx_tris: tris,
                loaded: OnceCell::new(),
            });
        } else {
            eprintln!(
                "skipping input {stem}: {} missing from {} (generate them with \
                 `rustc -O ../shared/bench-inputs/gen.rs -o gen && ./gen {} --no-obj`, \
                 or point DYNBVH_BENCH_INPUTS at a directory holding them)",
                missing
                    .iter()
                    .map(|s| s.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
                dir.display(),
                dir.display()
            );
        }
    }
    v
}

/// The builders measured: the same as `dynbvh build-bench` (median, binned SAH with 4 to 32
/// bins, 16 bins on the widest axis only, and the full sweep).
fn builders() -> Vec<BuildParams> {
    dynbvh::report::build_bench::default_methods()
}

/// Sample size and measurement time for an input: small for the 1M meshes so that the whole
/// bench finishes in reasonable time. `--sample-size` and `--measurement-time` on the command
/// line win over these.
fn configure(
    group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    i: &Input,
) {
    let given =
        |flag: &str| std::env::args().any(|a| a == flag || a.starts_with(&format!("{flag}=")));
    if !given("--sample-size") {
        group.sample_size(if i.large() { 10 } else { 20 });
    }
    if i.large() && !given("--measurement-time") {
        group.measurement_time(Duration::from_secs(5));
    }
}

fn bench_build(c: &mut Criterion, input: &Input) {
    let mut g = c.benchmark_group(format!("build/{}", input.name));
    configure(&mut g, input);
    for params in builders() {
        g.bench_function(BenchmarkId::from_parameter(params.name()), |b| {
            let mesh = &input.get().rest;
            b.iter(|| MeshBvh::build(black_box(mesh), &params));
        });
    }
    g.finish();
}

fn bench_refit(c: &mut Criterion, input: &Input) {
    let mut g = c.benchmark_group(format!("refit/{}", input.name));
    configure(&mut g, input);
    g.bench_function(BenchmarkId::from_parameter("binned16"), |b| {
        let l = input.get();
        let mut bvh = l.bvh().clone();
        // Every iteration refits between the two poses, alternately rest -> deformed and
        // deformed -> rest: each is one full refit to moved vertices.
        let mut to_deformed = false;
        b.iter(|| {
            to_deformed = !to_deformed;
            bvh.refit(if to_deformed { &l.deformed } else { &l.rest });
            black_box(bvh.bvh().nodes().first().copied())
        });
    });
    g.finish();
}

fn bench_traversal(c: &mut Criterion, input: &Input) {
    for (kind, any) in [("closest", false), ("any", true)] {
        let mut g = c.benchmark_group(format!("{kind}/{}", input.name));
        configure(&mut g, input);
        g.throughput(Throughput::Elements(RAYS_PER_ITER as u64));
        for set in ["camera", "random"] {
            g.bench_function(BenchmarkId::from_parameter(set), |b| {
                let l = input.get();
                let bvh = l.bvh();
                let rays = if set == "camera" {
                    &l.camera
                } else {
                    &l.random
                };
                if any {
                    b.iter(|| rays.iter().filter(|r| bvh.any_hit(black_box(r))).count());
                } else {
                    b.iter(|| {
                        rays.iter()
                            .filter_map(|r| bvh.closest_hit(black_box(r)))
                            .fold(0.0f32, |s, h| s + h.t)
                    });
                }
            });
        }
        g.finish();
    }
}

/// The camera rays as packets: `MeshBvh::trace_image_closest` / `trace_image_any` over the
/// square image (16x8 tiles), one thread.
fn bench_packets(c: &mut Criterion, input: &Input) {
    let mut g = c.benchmark_group(format!("packets/{}", input.name));
    configure(&mut g, input);
    g.throughput(Throughput::Elements(RAYS_PER_ITER as u64));
    g.bench_function(BenchmarkId::from_parameter("closest-camera"), |b| {
        let l = input.get();
        let bvh = l.bvh();
        let width = (l.camera.len() as f64).sqrt() as usize;
        let mut hits = vec![None; l.camera.len()];
        b.iter(|| {
            bvh.trace_image_closest(black_box(&l.camera), width, &mut hits);
            hits.iter().flatten().fold(0.0f32, |s, h| s + h.t)
        });
    });
    g.bench_function(BenchmarkId::from_parameter("any-camera"), |b| {
        let l = input.get();
        let bvh = l.bvh();
        let width = (l.camera.len() as f64).sqrt() as usize;
        let mut out = vec![false; l.camera.len()];
        b.iter(|| {
            bvh.trace_image_any(black_box(&l.camera), width, &mut out);
            out.iter().filter(|&&o| o).count()
        });
    });
    g.finish();
}

/// The wide trees (collapsed from the binned16 tree): refit to the other pose, and closest /
/// any hit with ids `wide_closest/<input>/bvh8-camera` etc.
fn bench_wide(c: &mut Criterion, input: &Input) {
    let mut g = c.benchmark_group(format!("wide_refit/{}", input.name));
    configure(&mut g, input);
    for k in [4, 8] {
        g.bench_function(BenchmarkId::from_parameter(format!("bvh{k}")), |b| {
            let l = input.get();
            let (w4, w8) = l.wide();
            let (mut w4, mut w8) = (w4.clone(), w8.clone());
            let mut to_deformed = false;
            b.iter(|| {
                to_deformed = !to_deformed;
                let m = if to_deformed { &l.deformed } else { &l.rest };
                if k == 4 {
                    w4.refit(m);
                    black_box(w4.bounds())
                } else {
                    w8.refit(m);
                    black_box(w8.bounds())
                }
            });
        });
    }
    g.finish();
    for (kind, any) in [("wide_closest", false), ("wide_any", true)] {
        let mut g = c.benchmark_group(format!("{kind}/{}", input.name));
        configure(&mut g, input);
        g.throughput(Throughput::Elements(RAYS_PER_ITER as u64));
        for k in [4, 8] {
            for set in ["camera", "random"] {
                g.bench_function(BenchmarkId::from_parameter(format!("bvh{k}-{set}")), |b| {
                    let l = input.get();
                    let (w4, w8) = l.wide();
                    let rays = if set == "camera" {
                        &l.camera
                    } else {
                        &l.random
                    };
                    let closest = |r: &Ray| {
                        if k == 4 {
                            w4.closest_hit(r)
                        } else {
                            w8.closest_hit(r)
                        }
                    };
                    let hit = |r: &Ray| if k == 4 { w4.any_hit(r) } else { w8.any_hit(r) };
                    if any {
                        b.iter(|| rays.iter().filter(|r| hit(black_box(r))).count());
                    } else {
                        b.iter(|| {
                            rays.iter()
                                .filter_map(|r| closest(black_box(r)))
                                .fold(0.0f32, |s, h| s + h.t)
                        });
                    }
                });
            }
        }
        g.finish();
    }
}

fn all(c: &mut Criterion) {
    for input in inputs() {
        bench_build(c, &input);
        bench_refit(c, &input);
        bench_traversal(c, &input);
        bench_packets(c, &input);
        bench_wide(c, &input);
    }
}

criterion_group!(benches, all);
criterion_main!(benches);
