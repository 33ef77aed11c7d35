//! Times single-threaded packet tracing of a square camera image against single rays:
//! `cargo run --release --example prof_packet MESH.tri PRIMARY.rays [WxH...]` (tile shapes,
//! default 4x4 8x8; a tile is one packet, at most `MAX_PACKET` rays, its rays in 4x4 blocks),
//! through the binary tree and the BVH8 collapsed from it (`TREES=bin` or `TREES=bvh8` for one).
//! `SUBSET=n` traces about `n` rays of the image instead, a lower-resolution image of the same
//! view (every k-th row and column, as the peers bench takes it): less coherent packets.
use dynbvh::bvh::{BuildParams, MeshBvh, MeshBvh8};
use dynbvh::geom::Hit;
use dynbvh::geom::Ray;

#[path = "common/cpu.rs"]
mod cpu;
use cpu::cpu_s;

/// The rays of `rays` (a `w`-wide image) regrouped tile by tile (`tw` x `th` pixels), each
/// tile in 4x4 blocks so that every 16-ray SIMD group is a compact square.
fn tiled(rays: &[Ray], w: usize, tw: usize, th: usize) -> Vec<Ray> {
    let h = rays.len() / w;
    let mut out = Vec::with_capacity(rays.len());
    let (ntx, nty) = (w.div_ceil(tw), h.div_ceil(th));
    let mut order: Vec<(usize, usize)> = (0..nty)
        .flat_map(|y| (0..ntx).map(move |x| (x, y)))
        .collect();
    if std::env::var_os("MORTON").is_some() {
        order.sort_by_key(|&(x, y)| morton(x as u32, y as u32));
    }
    for (tx, ty) in order {
        let (tx, ty) = (tx * tw, ty * th);
        {
            let (ye, xe) = ((ty + th).min(h), (tx + tw).min(w));
            for qy in (ty..ye).step_by(4) {
                for qx in (tx..xe).step_by(4) {
                    for y in qy..(qy + 4).min(ye) {
                        for x in qx..(qx + 4).min(xe) {
                            out.push(rays[y * w + x]);
                        }
                    }
                }
            }
        }
    }
    out
}

/// Interleaves the bits of `x` and `y` (Z order).
fn morton(x: u32, y: u32) -> u64 {
    let spread = |v: u32| {
        let mut v = u64::from(v);
        v = (v | (v << 16)) & 0x0000_FFFF_0000_FFFF;
        v = (v | (v << 8)) & 0x00FF_00FF_00FF_00FF;
        v = (v | (v << 4)) & 0x0F0F_0F0F_0F0F_0F0F;
        v = (v | (v << 2)) & 0x3333_3333_3333_3333;
        (v | (v << 1)) & 0x5555_5555_5555_5555
    };
    spread(x) | (spread(y) << 1)
}

/// Median CPU Mrays/s of 3 measurements of `f` over `n` rays, each repeating `f` for at least
/// 0.3 s of CPU time (the process's CPU clock ticks coarsely on some machines).
fn mrays(n: usize, mut f: impl FnMut() -> usize) -> (f64, usize) {
    let mut v = Vec::new();
    let mut hits = 0;
    for _ in 0..3 {
        let c = cpu_s();
        let mut runs = 0;
        while runs == 0 || cpu_s() - c < 0.3 {
            hits = f();
            runs += 1;
        }
        v.push((runs * n) as f64 / ((cpu_s() - c) * 1e6));
    }
    v.sort_by(f64::total_cmp);
    (v[1], hits)
}

fn main() {
    let mut args = std::env::args().skip(1);
    let mesh = dynbvh::io::read_tri(args.next().expect("mesh").as_ref()).unwrap();
    let rays = dynbvh::io::read_rays(args.next().expect("rays").as_ref()).unwrap();
    let mut shapes: Vec<(usize, usize)> = args
        .map(|s| {
            let (a, b) = s.split_once('x').expect("WxH");
            (a.parse().unwrap(), b.parse().unwrap())
        })
        .collect();
    if shapes.is_empty() {
        shapes = vec![(4, 4), (8, 8)];
    }
    let single = std::env::var_os("SINGLE").is_some();
    let rays = match std::env::var("SUBSET") {
        Ok(n) => dynbvh::report::rays::image_subset(&rays, n.parse().expect("SUBSET: a ray count")),
        Err(_) => rays,
    };
    let w = (rays.len() as f64).sqrt() as usize;
    assert_eq!(w * w, rays.len(), "a square image of rays");
    let bvh = MeshBvh::build(&mesh, &BuildParams::BINNED);
    // Where the node array starts within a cache line: a child pair (64 bytes) fits one line
    // only when the pair starts on a 64-byte boundary.
    println!(
        "nodes start at {} mod 64; the first child pair (node 1) at {} mod 64",
        bvh.bvh().nodes().as_ptr() as usize % 64,
        (bvh.bvh().nodes().as_ptr() as usize + 32) % 64
    );
    if single {
        let (m, hits) = mrays(rays.len(), || {
            rays.iter().filter(|r| bvh.closest_hit(r).is_some()).count()
        });
        println!("single closest {m:.2} Mrays/s cpu ({hits} hits)");
        let (m, hits) = mrays(rays.len(), || {
            rays.iter().filter(|r| bvh.any_hit(r)).count()
        });
        println!("single any     {m:.2} Mrays/s cpu ({hits} hits)");
    }
    if std::env::var_os("LOADONLY").is_some() {
        load_only(&tiled(&rays, w, 16, 8));
    }
    let bvh8 = MeshBvh8::from_mesh_bvh(&bvh);
    let trees = std::env::var("TREES").unwrap_or_else(|_| "bin,bvh8".into());
    if single && trees.contains("bvh8") {
        let (m, hits) = mrays(rays.len(), || {
            rays.iter()
                .filter(|r| bvh8.closest_hit(r).is_some())
                .count()
        });
        println!("bvh8 single closest {m:.2} Mrays/s cpu ({hits} hits)");
        let (m, hits) = mrays(rays.len(), || {
            rays.iter().filter(|r| bvh8.any_hit(r)).count()
        });
        println!("bvh8 single any     {m:.2} Mrays/s cpu ({hits} hits)");
    }
    type Closest<'a> = Box<dyn Fn(&[Ray], &mut [Option<Hit>]) + 'a>;
    type Any<'a> = Box<dyn Fn(&[Ray], &mut [bool]) + 'a>;
    let mut variants: Vec<(&str, Closest, Any)> = Vec::new();
    if trees.contains("bin") {
        variants.push((
            "bin ",
            Box::new(|r, h| bvh.closest_hit_packet(r, h)),
            Box::new(|r, o| bvh.any_hit_packet(r, o)),
        ));
    }
    if trees.contains("bvh8") {
        variants.push((
            "bvh8",
            Box::new(|r, h| bvh8.closest_hit_packet(r, h)),
            Box::new(|r, o| bvh8.any_hit_packet(r, o)),
        ));
    }
    for (tw, th) in shapes {
        let t = tiled(&rays, w, tw, th);
        let p = tw * th;
        assert!(p <= dynbvh::bvh::MAX_PACKET);
        for (name, closest, any) in &variants {
            let mut out = vec![None; p];
            let (m, hits) = mrays(t.len(), || {
                let mut n = 0;
                for c in t.chunks(p) {
                    closest(c, &mut out[..c.len()]);
                    n += out[..c.len()].iter().filter(|h| h.is_some()).count();
                }
                n
            });
            println!("{name} {tw}x{th} closest {m:.2} Mrays/s cpu ({hits} hits)");
            let mut out = vec![false; p];
            let (m, hits) = mrays(t.len(), || {
                let mut n = 0;
                for c in t.chunks(p) {
                    any(c, &mut out[..c.len()]);
                    n += out[..c.len()].iter().filter(|h| **h).count();
                }
                n
            });
            println!("{name} {tw}x{th} any     {m:.2} Mrays/s cpu ({hits} hits)");
        }
    }
}

#[allow(dead_code)]
fn load_only(rays: &[Ray]) {
    let mut p = dynbvh::bvh::RayPacket::new();
    let (m, _) = mrays(rays.len(), || {
        let mut n = 0;
        for c in rays.chunks(128) {
            p.load(c);
            n += usize::from(p.is_coherent());
        }
        n
    });
    println!("load only {m:.2} Mrays/s cpu");
    let hot = &rays[..128];
    let (m, _) = mrays(rays.len(), || {
        let mut n = 0;
        for _ in 0..rays.len() / 128 {
            p.load(std::hint::black_box(hot));
            n += usize::from(p.is_coherent());
        }
        n
    });
    println!("load only, cached {m:.2} Mrays/s cpu");
    let (m, _) = mrays(rays.len(), || {
        let mut n = 0.0;
        for r in rays {
            n += r.origin().x + r.tmax;
        }
        n as usize
    });
    println!("read only {m:.2} Mrays/s cpu");
}
