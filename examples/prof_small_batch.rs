//! The engine's batch queries at a simulator's batch sizes against the same rays answered one
//! by one on the calling thread: `cargo run --release --example prof_small_batch FILE.glb
//! [SIDE...]` (default sides 32 64 128: square camera images of 1,024 to 16,384 rays, the scene
//! posed at its fourth frame). Wall clock on the pool the machine gives (this is about handing
//! work to the pool), medians of `PASSES` (default 1000) alternations of
//! `Engine::closest_hit_batch`, a loop of `Engine::closest_hit`, and `Engine::trace_closest`
//! (the frame's pass, sampling included); the answers are checked to be the loop's. First, what
//! a parallel call costs once the pool's threads sleep. `LIDAR=1`:
//! SIDE² rays of the bench's rotating lidar fan at the fourth frame instead of a camera image.
use dynbvh::anim::Scene;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::{EngineConfig, FrameSource};
use dynbvh::report::rays::{camera_rays, lidar_rays};
use std::time::Instant;

/// What handing work to the pool costs once its threads have gone to sleep: four empty tasks
/// after 1 ms of idling (spun on this thread, so that the pool's threads are the ones asleep).
fn wake_us() -> f64 {
    use rayon::prelude::*;
    let mut v = [0u8; 4];
    let times = (0..200)
        .map(|_| {
            let idle = Instant::now();
            while idle.elapsed().as_micros() < 1000 {}
            let t = Instant::now();
            v.par_iter_mut().for_each(|x| *x = x.wrapping_add(1));
            t.elapsed().as_secs_f64() * 1e6
        })
        .collect();
    median(times)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (scene, _) = Scene::load(&args[0]).unwrap();
    let sides: Vec<usize> = if args.len() > 1 {
        args[1..]
            .iter()
            .map(|s| s.parse().expect("a side"))
            .collect()
    } else {
        vec![32, 64, 128]
    };
    let passes: usize = std::env::var("PASSES").map_or(1000, |s| s.parse().expect("PASSES"));
    let lidar = std::env::var("LIDAR").is_ok();
    let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(30)).unwrap();
    let mut e = src.engine(EngineConfig::default());
    src.advance(&mut e, 3);
    e.update();
    println!(
        "{}, {} threads in the pool; a parallel call of four empty tasks after the pool idled 1 ms: {:.1} us (median of 200)",
        args[0],
        rayon::current_num_threads(),
        wake_us()
    );
    for side in sides {
        let rays = if lidar {
            let mut rays = Vec::new();
            lidar_rays(&e.bounds(), side * side, 3, &mut rays);
            rays
        } else {
            camera_rays(&e.bounds(), side, side)
        };
        let mut expected = vec![None; rays.len()];
        for (o, r) in expected.iter_mut().zip(&rays) {
            *o = e.closest_hit(r);
        }
        let same = |hits: &[Option<dynbvh::engine::SceneHit>]| {
            let key = |h: &Option<dynbvh::engine::SceneHit>| h.map(|h| (h.t.to_bits(), h.prim));
            assert!(hits.iter().zip(&expected).all(|(a, b)| key(a) == key(b)));
        };
        let mut hits = vec![None; rays.len()];
        let (mut batch, mut one_by_one, mut frame) = (vec![], vec![], vec![]);
        for _ in 0..passes {
            let t = Instant::now();
            e.closest_hit_batch(&rays, &mut hits);
            batch.push(t.elapsed().as_secs_f64());
            same(&hits);
            let t = Instant::now();
            for (o, r) in hits.iter_mut().zip(&rays) {
                *o = e.closest_hit(r);
            }
            one_by_one.push(t.elapsed().as_secs_f64());
            let t = Instant::now();
            e.trace_closest(&rays, &mut hits);
            frame.push(t.elapsed().as_secs_f64());
            same(&hits);
        }
        let (b, l, f) = (median(batch), median(one_by_one), median(frame));
        println!(
            "{:6} rays: batch {:8.1} us, one by one {:8.1} us, frame pass {:8.1} us; batch / one by one {:.2}",
            rays.len(),
            b * 1e6,
            l * 1e6,
            f * 1e6,
            b / l
        );
    }
}
