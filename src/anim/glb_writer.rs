//! A minimal binary glTF writer: one buffer (the BIN chunk), tightly packed accessors with
//! min/max, and a JSON document assembled by the caller.

use glam::{Mat4, Quat, Vec3};
use serde_json::{Value, json};

/// Accumulates binary data, buffer views and accessors for one `.glb`.
#[derive(Default)]
pub(crate) struct GlbWriter {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl GlbWriter {
    /// Appends `bytes` as a new buffer view (4-byte aligned) and returns its index.
    fn view(&mut self, bytes: &[u8]) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        self.views.push(json!({
            "buffer": 0,
            "byteOffset": self.bin.len(),
            "byteLength": bytes.len(),
        }));
        self.bin.extend_from_slice(bytes);
        self.views.len() - 1
    }

    /// Adds a float accessor of element type `ty` (`width` components) with min and max.
    pub fn floats(&mut self, data: &[f32], ty: &str, width: usize) -> usize {
        let bytes: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
        let view = self.view(&bytes);
        let mut min = vec![f32::INFINITY; width];
        let mut max = vec![f32::NEG_INFINITY; width];
        for e in data.chunks_exact(width) {
            for c in 0..width {
                min[c] = min[c].min(e[c]);
                max[c] = max[c].max(e[c]);
            }
        }
        self.accessors.push(json!({
            "bufferView": view,
            "componentType": 5126,
            "count": data.len() / width,
            "type": ty,
            "min": min,
            "max": max,
        }));
        self.accessors.len() - 1
    }

    /// Adds a VEC3 float accessor.
    pub fn vec3s(&mut self, v: &[Vec3]) -> usize {
        let flat: Vec<f32> = v.iter().flat_map(|p| p.to_array()).collect();
        self.floats(&flat, "VEC3", 3)
    }

    /// Adds a VEC4 float accessor of quaternions.
    pub fn quats(&mut self, q: &[Quat]) -> usize {
        let flat: Vec<f32> = q.iter().flat_map(|p| p.to_array()).collect();
        self.floats(&flat, "VEC4", 4)
    }

    /// Adds a SCALAR float accessor.
    pub fn scalars(&mut self, v: &[f32]) -> usize {
        self.floats(v, "SCALAR", 1)
    }

    /// Adds a MAT4 float accessor.
    pub fn mat4s(&mut self, m: &[Mat4]) -> usize {
        let flat: Vec<f32> = m.iter().flat_map(|p| p.to_cols_array()).collect();
        self.floats(&flat, "MAT4", 16)
    }

    /// Adds a triangle index accessor (u16 when every index fits, else u32).
    pub fn indices(&mut self, tris: &[[u32; 3]]) -> usize {
        let small = tris.iter().flatten().all(|&i| i < 65535);
        let bytes: Vec<u8> = if small {
            tris.iter()
                .flatten()
                .flat_map(|&i| (i as u16).to_le_bytes())
                .collect()
        } else {
            tris.iter()
                .flatten()
                .flat_map(|i| i.to_le_bytes())
                .collect()
        };
        let view = self.view(&bytes);
        self.accessors.push(json!({
            "bufferView": view,
            "componentType": if small { 5123 } else { 5125 },
            "count": tris.len() * 3,
            "type": "SCALAR",
        }));
        self.accessors.len() - 1
    }

    /// Adds a VEC4 u16 accessor of joint indices.
    pub fn joints(&mut self, j: &[[u16; 4]]) -> usize {
        let bytes: Vec<u8> = j.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
        let view = self.view(&bytes);
        self.accessors.push(json!({
            "bufferView": view,
            "componentType": 5123,
            "count": j.len(),
            "type": "VEC4",
        }));
        self.accessors.len() - 1
    }

    /// Completes `root` (nodes, meshes, ... already set) with the buffer, views, accessors and
    /// asset, and returns the `.glb` bytes.
    pub fn finish(mut self, mut root: Value) -> Vec<u8> {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        root["asset"] = json!({"version": "2.0", "generator": "dynbvh gen"});
        root["buffers"] = json!([{"byteLength": self.bin.len()}]);
        root["bufferViews"] = Value::Array(self.views);
        root["accessors"] = Value::Array(self.accessors);
        let mut text = serde_json::to_vec(&root).unwrap_or_default();
        while !text.len().is_multiple_of(4) {
            text.push(b' ');
        }
        let total = 12 + 8 + text.len() + 8 + self.bin.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(text.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&text);
        out.extend_from_slice(&(self.bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&self.bin);
        out
    }
}
