//! Reading meshes and ray sets: the binary `.tri` and `.rays` formats of the shared benchmark
//! inputs, and Wavefront `.obj` (positions and faces; polygons become triangle fans).

use crate::geom::{Ray, TriMesh};
use crate::{Error, Result};
use glam::Vec3;
use std::path::Path;

fn read(path: &Path) -> Result<Vec<u8>> {
    read_file(path, None)
}

/// Reads a regular file, at most `limit` bytes of it when given. Anything else (a FIFO, a
/// device, a directory) is refused before it is opened: reading a FIFO without a writer
/// blocks forever, and a device such as `/dev/zero` never ends.
pub fn read_file(path: &Path, limit: Option<u64>) -> Result<Vec<u8>> {
    use std::io::Read;
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        let kind = if meta.is_dir() {
            "a directory"
        } else {
            "not a regular file (a FIFO, socket or device)"
        };
        return Err(Error::io(
            path,
            std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("{kind}; only regular files are read"),
            ),
        ));
    }
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let len = meta.len();
    let take = limit.map_or(len, |l| l.min(len));
    let mut out = Vec::with_capacity(usize::try_from(take).unwrap_or(0));
    file.take(limit.unwrap_or(u64::MAX))
        .read_to_end(&mut out)
        .map_err(|e| Error::io(path, e))?;
    Ok(out)
}

/// Reads `u32 count` then `count * floats_per_item` little-endian f32.
fn read_f32_records(path: &Path, floats_per_item: usize, what: &str) -> Result<Vec<f32>> {
    let bytes = read(path)?;
    let header: [u8; 4] = bytes
        .get(..4)
        .and_then(|h| h.try_into().ok())
        .ok_or_else(|| Error::malformed(path, "header", "expected a u32 count"))?;
    let count = u32::from_le_bytes(header) as usize;
    let expected = count
        .checked_mul(floats_per_item * 4)
        .and_then(|n| n.checked_add(4))
        .ok_or_else(|| Error::malformed(path, "header", format!("count {count} too large")))?;
    if bytes.len() != expected {
        return Err(Error::malformed(
            path,
            "body",
            format!(
                "{count} {what} need {expected} bytes, the file has {}",
                bytes.len()
            ),
        ));
    }
    Ok(bytes[4..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect())
}

/// Reads a `.tri` file: `u32 count`, then nine f32 per triangle. Vertices are not shared.
pub fn read_tri(path: &Path) -> Result<TriMesh> {
    let f = read_f32_records(path, 9, "triangles")?;
    let tris: Vec<[Vec3; 3]> = f
        .chunks_exact(9)
        .map(|c| {
            [
                Vec3::new(c[0], c[1], c[2]),
                Vec3::new(c[3], c[4], c[5]),
                Vec3::new(c[6], c[7], c[8]),
            ]
        })
        .collect();
    check_finite(path, tris.iter().flatten())?;
    Ok(TriMesh::from_soup(&tris))
}

/// Reads a `.rays` file: `u32 count`, then origin and direction (six f32) per ray; every ray
/// spans `t` from 0 to infinity.
pub fn read_rays(path: &Path) -> Result<Vec<Ray>> {
    let f = read_f32_records(path, 6, "rays")?;
    f.chunks_exact(6)
        .enumerate()
        .map(|(i, c)| {
            let o = Vec3::new(c[0], c[1], c[2]);
            let d = Vec3::new(c[3], c[4], c[5]);
            if !o.is_finite() || !d.is_finite() || d == Vec3::ZERO {
                return Err(Error::malformed(
                    path,
                    format!("ray {i}"),
                    "origin and direction must be finite and the direction non-zero",
                ));
            }
            Ok(Ray::new(o, d))
        })
        .collect()
}

/// Reads a Wavefront `.obj`: `v` lines and `f` lines (1-based or negative indices,
/// `v/vt/vn` forms); polygons are split into fans. Everything else is ignored.
pub fn read_obj(path: &Path) -> Result<TriMesh> {
    let text = String::from_utf8(read(path)?)
        .map_err(|_| Error::malformed(path, "file", "not UTF-8 text"))?;
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    let mut face = Vec::new();
    for (lineno, line) in text.lines().enumerate() {
        let at = || format!("line {}", lineno + 1);
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let mut c = [0f32; 3];
                for v in &mut c {
                    *v = it
                        .next()
                        .and_then(|s| s.parse().ok())
                        .filter(|x: &f32| x.is_finite())
                        .ok_or_else(|| {
                            Error::malformed(path, at(), "expected three finite coordinates")
                        })?;
                }
                positions.push(Vec3::from(c));
            }
            Some("f") => {
                face.clear();
                for tok in it {
                    let idx: i64 = tok
                        .split('/')
                        .next()
                        .and_then(|s| s.parse().ok())
                        .ok_or_else(|| {
                            Error::malformed(path, at(), format!("bad vertex reference {tok:?}"))
                        })?;
                    let n = positions.len() as i64;
                    let i = if idx < 0 { n + idx } else { idx - 1 };
                    if !(0..n).contains(&i) {
                        return Err(Error::malformed(
                            path,
                            at(),
                            format!("vertex {idx} out of range (1..={n})"),
                        ));
                    }
                    face.push(i as u32);
                }
                if face.len() < 3 {
                    return Err(Error::malformed(
                        path,
                        at(),
                        "a face needs at least 3 vertices",
                    ));
                }
                for k in 1..face.len() - 1 {
                    indices.push([face[0], face[k], face[k + 1]]);
                }
            }
            _ => {}
        }
    }
    Ok(TriMesh::new(positions, indices))
}

fn check_finite<'a>(path: &Path, mut points: impl Iterator<Item = &'a Vec3>) -> Result<()> {
    match points.position(|p| !p.is_finite()) {
        Some(i) => Err(Error::malformed(
            path,
            format!("triangle {}", i / 3),
            "coordinates must be finite",
        )),
        None => Ok(()),
    }
}
