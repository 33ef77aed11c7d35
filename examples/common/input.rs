//! The examples' inputs: a mesh from a `.tri` or `.obj` file or a glTF file flattened at rest,
//! and rays from a `.rays` file or, as `camera:SIDE` or `random:N`, `build-bench`'s own ray
//! sets over the mesh's box.
use dynbvh::geom::{Ray, TriMesh};
use dynbvh::report::rays::{camera_rays, random_rays};
use std::path::Path;

/// The mesh in `path`.
pub fn mesh(path: &str) -> TriMesh {
    let path = Path::new(path);
    match path.extension().and_then(|e| e.to_str()) {
        Some("tri") => dynbvh::io::read_tri(path).unwrap(),
        Some("obj") => dynbvh::io::read_obj(path).unwrap(),
        _ => dynbvh::anim::Scene::load(path).unwrap().0.flatten_rest(),
    }
}

/// The rays `arg` names over `mesh`.
#[allow(dead_code)]
pub fn rays(arg: &str, mesh: &TriMesh) -> Vec<Ray> {
    match arg.split_once(':') {
        Some(("camera", side)) => {
            let side = side.parse().unwrap();
            camera_rays(&mesh.bounds(), side, side)
        }
        Some(("random", n)) => random_rays(&mesh.bounds(), n.parse().unwrap(), 0xC0FFEE),
        _ => dynbvh::io::read_rays(arg.as_ref()).unwrap(),
    }
}
