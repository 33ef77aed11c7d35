//! Pinhole and orthographic cameras: framed automatically from a box, or read from the glTF
//! file's own camera nodes.

use crate::anim::Scene;
use crate::error::{Error, Result};
use crate::geom::{Aabb, Ray};
use glam::{Mat4, Vec3};
use std::path::Path;

/// How a camera projects.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    /// Pinhole with this vertical field of view, in radians.
    Perspective {
        /// Vertical field of view, radians.
        yfov: f32,
    },
    /// Parallel rays; the view is `2 * ymag` high (its width follows the image's aspect).
    Orthographic {
        /// Half the view's height, in world units.
        ymag: f32,
    },
}

/// A camera: position, orthonormal basis (looking along `forward`), projection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye position.
    pub eye: Vec3,
    /// Unit viewing direction.
    pub forward: Vec3,
    /// Unit vector to the right of the image.
    pub right: Vec3,
    /// Unit vector to the top of the image.
    pub up: Vec3,
    /// Projection.
    pub projection: Projection,
}

/// Vertical field of view of the automatic camera.
pub const AUTO_YFOV_DEGREES: f32 = 40.0;

/// Direction from the scene's centre to the automatic camera (y up, as in glTF).
pub const AUTO_VIEW_DIR: Vec3 = Vec3::new(0.45, 0.35, 1.0);

impl Camera {
    /// A camera at `eye` looking at `target`, with `up_hint` giving the image's up.
    #[must_use]
    pub fn look_at(eye: Vec3, target: Vec3, up_hint: Vec3, projection: Projection) -> Self {
        let forward = (target - eye).try_normalize().unwrap_or(Vec3::NEG_Z);
        Self::from_forward(eye, forward, up_hint, projection)
    }

    fn from_forward(eye: Vec3, forward: Vec3, up_hint: Vec3, projection: Projection) -> Self {
        let right = forward
            .cross(up_hint)
            .try_normalize()
            .or_else(|| forward.cross(Vec3::Z).try_normalize())
            .unwrap_or(Vec3::X);
        let up = right.cross(forward);
        Self {
            eye,
            forward,
            right,
            up,
            projection,
        }
    }

    /// A perspective camera looking at `bounds` from [`AUTO_VIEW_DIR`], as close as it can be
    /// with every corner of the box inside the image (`aspect` = width / height) and a margin.
    #[must_use]
    pub fn framing(bounds: &Aabb, aspect: f32) -> Self {
        let yfov = AUTO_YFOV_DEGREES.to_radians();
        let projection = Projection::Perspective { yfov };
        if bounds.is_empty() || !bounds.is_finite() {
            return Self::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y, projection);
        }
        let c = bounds.center();
        let dir = AUTO_VIEW_DIR.normalize();
        // The view's axes only (at the origin: `c + dir` would round to `c` far from it).
        let cam = Self::look_at(dir, Vec3::ZERO, Vec3::Y, projection);
        let tan_y = (yfov * 0.5).tan();
        let tan_x = tan_y * aspect.max(1e-3);
        // Distance from the centre such that each corner projects inside the frustum:
        // |x| <= tan_x (d + z) and |y| <= tan_y (d + z), z along the view direction.
        let mut d = 0.0f32;
        for k in 0..8 {
            let p = Vec3::new(
                if k & 1 == 0 {
                    bounds.min.x
                } else {
                    bounds.max.x
                },
                if k & 2 == 0 {
                    bounds.min.y
                } else {
                    bounds.max.y
                },
                if k & 4 == 0 {
                    bounds.min.z
                } else {
                    bounds.max.z
                },
            ) - c;
            let (x, y, z) = (p.dot(cam.right), p.dot(cam.up), p.dot(cam.forward));
            d = d.max(x.abs() / tan_x - z).max(y.abs() / tan_y - z);
        }
        // Relative bounds only: a scene 1e-10 across is framed as one 1 across.
        let size = bounds.extent().length();
        let d = (d * 1.08).max(size * 0.05);
        if !(d > 0.0 && d.is_finite()) {
            // A box that is one point: any distance sees it.
            let d = c.abs().max_element().max(1.0) * 1e-3;
            return Self::look_at(c + dir * d, c, Vec3::Y, projection);
        }
        Self::look_at(c + dir * d, c, Vec3::Y, projection)
    }

    /// The camera of a glTF camera node with world matrix `world` (looking down its local -z,
    /// local +y up; scale is ignored).
    #[must_use]
    pub fn from_node(world: &Mat4, projection: Projection) -> Self {
        let eye = world.transform_point3(Vec3::ZERO);
        let forward = world
            .transform_vector3(Vec3::NEG_Z)
            .try_normalize()
            .unwrap_or(Vec3::NEG_Z);
        let up = world.transform_vector3(Vec3::Y);
        Self::from_forward(eye, forward, up, projection)
    }

    /// Primary rays of a `w x h` image, one through the centre of each pixel.
    #[must_use]
    pub fn rays(&self, w: u32, h: u32) -> RayGen {
        let aspect = w as f32 / h.max(1) as f32;
        let (sx, sy) = match self.projection {
            Projection::Perspective { yfov } => {
                let ty = (yfov * 0.5).tan();
                (ty * aspect, ty)
            }
            Projection::Orthographic { ymag } => (ymag * aspect, ymag),
        };
        RayGen {
            cam: *self,
            ortho: matches!(self.projection, Projection::Orthographic { .. }),
            du: self.right * (2.0 * sx / w.max(1) as f32),
            dv: -self.up * (2.0 * sy / h.max(1) as f32),
            corner: self.right * -sx + self.up * sy,
        }
    }
}

/// Generates the primary ray of any pixel (see [`Camera::rays`]).
#[derive(Clone, Copy, Debug)]
pub struct RayGen {
    cam: Camera,
    ortho: bool,
    du: Vec3,
    dv: Vec3,
    corner: Vec3,
}

impl RayGen {
    /// The ray through the centre of pixel `(x, y)` (row 0 at the top), with a unit direction.
    #[must_use]
    #[inline]
    pub fn ray(&self, x: u32, y: u32) -> Ray {
        let off = self.corner + self.du * (x as f32 + 0.5) + self.dv * (y as f32 + 0.5);
        if self.ortho {
            Ray::new(self.cam.eye + off, self.cam.forward)
        } else {
            Ray::new(self.cam.eye, (self.cam.forward + off).normalize())
        }
    }
}

/// A camera found in a glTF file: the node placing it and its projection.
#[derive(Clone, Debug, PartialEq)]
pub struct GltfCamera {
    /// Node index in the file.
    pub node: usize,
    /// Camera name, if any.
    pub name: Option<String>,
    /// Projection (the file's aspect ratio is ignored: the image's is used).
    pub projection: Projection,
}

/// The cameras placed by the nodes of `scene`'s chosen glTF scene, in depth-first node order.
/// Reads the JSON of `scene.path` again (the animation loader keeps no cameras).
pub fn gltf_cameras(scene: &Scene) -> Result<Vec<GltfCamera>> {
    let path = scene.path.as_path();
    let bytes = crate::io::read_file(path, None)?;
    cameras_from_bytes(scene, path, &bytes)
}

fn cameras_from_bytes(scene: &Scene, path: &Path, bytes: &[u8]) -> Result<Vec<GltfCamera>> {
    let json: std::borrow::Cow<'_, [u8]> = if bytes.starts_with(b"glTF") {
        let glb = gltf::binary::Glb::from_slice(bytes)
            .map_err(|e| Error::malformed(path, "GLB container", format!("valid: {e}")))?;
        glb.json
    } else {
        bytes.into()
    };
    let root: gltf_json::Root = gltf_json::deserialize::from_slice(&json)
        .map_err(|e| Error::malformed(path, "JSON", format!("a glTF 2.0 document: {e}")))?;
    let mut out = Vec::new();
    let mut stack: Vec<usize> = scene.roots.iter().rev().copied().collect();
    let mut seen = vec![false; scene.nodes.len()];
    while let Some(n) = stack.pop() {
        if n >= seen.len() || std::mem::replace(&mut seen[n], true) {
            continue;
        }
        let cam = root
            .nodes
            .get(n)
            .and_then(|node| node.camera)
            .and_then(|c| root.cameras.get(c.value()));
        if let Some(cam) = cam {
            let projection = if let Some(p) = &cam.perspective {
                (p.yfov > 0.0 && p.yfov < std::f32::consts::PI)
                    .then_some(Projection::Perspective { yfov: p.yfov })
            } else {
                cam.orthographic
                    .as_ref()
                    .filter(|o| o.ymag.abs() > 0.0)
                    .map(|o| Projection::Orthographic { ymag: o.ymag.abs() })
            };
            if let Some(projection) = projection {
                out.push(GltfCamera {
                    node: n,
                    name: cam.name.clone(),
                    projection,
                });
            }
        }
        stack.extend(scene.nodes[n].children.iter().rev());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn framing_keeps_every_corner_inside() {
        let b = Aabb::new(Vec3::new(-1.0, 0.0, -0.3), Vec3::new(1.0, 3.0, 0.4));
        for aspect in [0.5, 1.0, 4.0 / 3.0, 2.5] {
            let cam = Camera::framing(&b, aspect);
            let Projection::Perspective { yfov } = cam.projection else {
                panic!("perspective expected")
            };
            let ty = (yfov * 0.5).tan();
            let tx = ty * aspect;
            let mut tightest = 0.0f32;
            for k in 0..8 {
                let p = Vec3::new(
                    if k & 1 == 0 { b.min.x } else { b.max.x },
                    if k & 2 == 0 { b.min.y } else { b.max.y },
                    if k & 4 == 0 { b.min.z } else { b.max.z },
                ) - cam.eye;
                let z = p.dot(cam.forward);
                assert!(z > 0.0);
                let fx = p.dot(cam.right).abs() / (z * tx);
                let fy = p.dot(cam.up).abs() / (z * ty);
                assert!(fx <= 1.0 && fy <= 1.0, "corner outside at aspect {aspect}");
                tightest = tightest.max(fx).max(fy);
            }
            assert!(tightest > 0.85, "framing too loose: {tightest}");
        }
    }

    #[test]
    fn centre_pixel_looks_forward() {
        let cam = Camera::look_at(
            Vec3::new(0.0, 0.0, 5.0),
            Vec3::ZERO,
            Vec3::Y,
            Projection::Perspective { yfov: 1.0 },
        );
        let g = cam.rays(101, 51);
        let r = g.ray(50, 25);
        assert!((r.dir - Vec3::NEG_Z).length() < 1e-6);
        // Top-left pixel points up and to the left.
        let r = g.ray(0, 0);
        assert!(r.dir.x < 0.0 && r.dir.y > 0.0);
    }
}
