//! Decoding accessors straight from buffer bytes: byte strides, offsets, every component type,
//! normalized integers (KHR_mesh_quantization included), matrix column padding and sparse
//! substitution, with every range checked.

use super::source::{Source, meshopt_extension};
use crate::error::{Error, Result};
use gltf_json::accessor::{ComponentType, Type};
use gltf_json::validation::Checked;
use std::path::Path;

/// Largest number of components an accessor without a buffer view may hold (zeros plus sparse).
const MAX_ZERO_COMPONENTS: u64 = 1 << 24;

/// Bytes of decoded data a file may ask for beyond [`DECODED_PER_INPUT_BYTE`] bytes per byte
/// of its own (file and buffers): 4 GiB. See [`decoded_limit`].
pub const DECODED_BASE: u64 = 4 << 30;

/// Decoded bytes allowed per byte of input (file and buffers), on top of [`DECODED_BASE`].
pub const DECODED_PER_INPUT_BYTE: u64 = 16;

/// The default bound on the bytes of decoded accessor data (vertex attributes, indices, morph
/// deltas, skin attributes, keyframes) of one file of `input_bytes` bytes (file and buffers):
/// `4 GiB + 16 × input_bytes`. Data read through buffer views grows at most 4 times (8-bit
/// to `f32`) and triangle strips 12 times (8-bit indices to `[u32; 3]`), so every real file is
/// far below it; what reaches it is an accessor without buffer view (zeros plus sparse values)
/// or a view read again and again by many primitives, targets or samplers.
#[must_use]
pub fn decoded_limit(input_bytes: u64) -> u64 {
    DECODED_BASE.saturating_add(DECODED_PER_INPUT_BYTE.saturating_mul(input_bytes))
}

/// Reads accessors of one document, naming `path` in errors, and keeps the total decoded
/// size under `limit` bytes.
pub(crate) struct Reader<'a> {
    /// The file, for error messages.
    pub path: &'a Path,
    /// The document and its buffers.
    pub src: &'a Source,
    /// Bytes decoded so far.
    pub decoded: std::cell::Cell<u64>,
    /// Bound on `decoded`.
    pub limit: u64,
}

/// Bytes of one component.
fn comp_size(c: ComponentType) -> usize {
    match c {
        ComponentType::I8 | ComponentType::U8 => 1,
        ComponentType::I16 | ComponentType::U16 => 2,
        ComponentType::U32 | ComponentType::F32 => 4,
    }
}

/// Number of components of an element type.
pub(crate) fn type_components(t: Type) -> usize {
    match t {
        Type::Scalar => 1,
        Type::Vec2 => 2,
        Type::Vec3 => 3,
        Type::Vec4 | Type::Mat2 => 4,
        Type::Mat3 => 9,
        Type::Mat4 => 16,
    }
}

/// glTF name of an element type.
pub(crate) fn type_name(t: Type) -> &'static str {
    match t {
        Type::Scalar => "SCALAR",
        Type::Vec2 => "VEC2",
        Type::Vec3 => "VEC3",
        Type::Vec4 => "VEC4",
        Type::Mat2 => "MAT2",
        Type::Mat3 => "MAT3",
        Type::Mat4 => "MAT4",
    }
}

/// Byte offsets of each component inside one element (matrix columns start on 4-byte
/// boundaries) and the element's size in bytes.
fn layout(t: Type, c: ComponentType) -> (Vec<usize>, usize) {
    let cs = comp_size(c);
    let (cols, rows) = match t {
        Type::Mat2 => (2, 2),
        Type::Mat3 => (3, 3),
        Type::Mat4 => (4, 4),
        other => (1, type_components(other)),
    };
    let col_bytes = if cols > 1 {
        (rows * cs).div_ceil(4) * 4
    } else {
        rows * cs
    };
    let offsets = (0..cols)
        .flat_map(|col| (0..rows).map(move |r| col * col_bytes + r * cs))
        .collect();
    (offsets, cols * col_bytes)
}

/// One component as an unsigned integer (`None` for floats and signed types).
fn read_uint(b: &[u8], c: ComponentType) -> Option<u32> {
    match c {
        ComponentType::U8 => b.first().map(|&x| u32::from(x)),
        ComponentType::U16 => Some(u32::from(u16::from_le_bytes([*b.first()?, *b.get(1)?]))),
        ComponentType::U32 => Some(u32::from_le_bytes([
            *b.first()?,
            *b.get(1)?,
            *b.get(2)?,
            *b.get(3)?,
        ])),
        _ => None,
    }
}

/// One component as a float, normalized per the glTF spec when `norm` is set.
fn read_float(b: &[u8], c: ComponentType, norm: bool) -> f32 {
    let byte = |i: usize| b.get(i).copied().unwrap_or(0);
    match c {
        ComponentType::I8 => {
            let v = f32::from(byte(0) as i8);
            if norm { (v / 127.0).max(-1.0) } else { v }
        }
        ComponentType::U8 => {
            let v = f32::from(byte(0));
            if norm { v / 255.0 } else { v }
        }
        ComponentType::I16 => {
            let v = f32::from(i16::from_le_bytes([byte(0), byte(1)]));
            if norm { (v / 32767.0).max(-1.0) } else { v }
        }
        ComponentType::U16 => {
            let v = f32::from(u16::from_le_bytes([byte(0), byte(1)]));
            if norm { v / 65535.0 } else { v }
        }
        ComponentType::U32 => {
            let v = u32::from_le_bytes([byte(0), byte(1), byte(2), byte(3)]) as f64;
            (if norm { v / f64::from(u32::MAX) } else { v }) as f32
        }
        ComponentType::F32 => f32::from_le_bytes([byte(0), byte(1), byte(2), byte(3)]),
    }
}

/// A decoded accessor: `count` elements of `width` components, flattened.
#[derive(Debug)]
pub(crate) struct Decoded<T> {
    /// The components, element after element.
    pub values: Vec<T>,
    /// Components per element.
    pub width: usize,
    /// Element type.
    pub ty: Type,
    /// Component type.
    pub comp: ComponentType,
}

impl<'a> Reader<'a> {
    /// A reader of `src` (the content of `path`) that decodes at most `limit` bytes.
    pub fn new(path: &'a Path, src: &'a Source, limit: u64) -> Self {
        Reader {
            path,
            src,
            decoded: std::cell::Cell::new(0),
            limit,
        }
    }

    /// Bytes that may still be decoded.
    pub fn remaining(&self) -> u64 {
        self.limit.saturating_sub(self.decoded.get())
    }

    /// An error about `object` asking for `bytes` more decoded bytes than remain.
    pub fn too_big(&self, object: impl Into<String>, bytes: u64) -> Error {
        self.err(
            object,
            format!(
                "at most {} bytes of decoded data for the whole file (the loader's bound; {} \
                 already decoded), found a request for {bytes} more",
                self.limit,
                self.decoded.get()
            ),
        )
    }

    /// Counts `bytes` of decoded data against the bound, or fails naming `object`.
    fn charge(&self, object: &str, bytes: u64) -> Result<()> {
        if bytes > self.remaining() {
            return Err(self.too_big(object, bytes));
        }
        self.decoded.set(self.decoded.get() + bytes);
        Ok(())
    }

    /// An error about `object`.
    pub fn err(&self, object: impl Into<String>, what: impl Into<String>) -> Error {
        Error::malformed(self.path, object, what)
    }

    /// Bytes of buffer view `v` (checked against its buffer) and its byte stride.
    fn view(&self, v: usize, object: &str) -> Result<(&[u8], Option<usize>)> {
        let view = self.src.root.buffer_views.get(v).ok_or_else(|| {
            self.err(
                object,
                format!(
                    "buffer view {v} to exist ({} buffer views)",
                    self.src.root.buffer_views.len()
                ),
            )
        })?;
        let b = view.buffer.value();
        if self.src.absent.get(b).copied().unwrap_or(false) {
            let ext = meshopt_extension(view.extensions.as_ref().map(|e| &e.others))
                .unwrap_or("EXT_meshopt_compression");
            return Err(Error::Unsupported {
                path: self.path.into(),
                object: format!("{object} buffer view {v}"),
                what: format!(
                    "data compressed with {ext} (buffer {b} has no uncompressed fallback), which the engine does not decode"
                ),
            });
        }
        let buf = self.src.buffers.get(b).ok_or_else(|| {
            self.err(
                format!("{object} buffer view {v}"),
                format!("buffer {b} to exist"),
            )
        })?;
        let start = view.byte_offset.map_or(0, |o| o.0);
        let end = start.checked_add(view.byte_length.0);
        let bytes = end
            .filter(|&e| e <= buf.len() as u64)
            .and_then(|e| buf.get(start as usize..e as usize))
            .ok_or_else(|| {
                self.err(
                    format!("{object} buffer view {v}"),
                    format!(
                        "bytes {start}..{start}+{} inside buffer {b} of {} bytes",
                        view.byte_length.0,
                        buf.len()
                    ),
                )
            })?;
        Ok((bytes, view.byte_stride.map(|s| s.0)))
    }

    /// Decodes accessor `index` with `conv` applied to each component's bytes. `object` names
    /// the user (e.g. `mesh 2 primitive 0`) and `role` the attribute (e.g. `POSITION`).
    fn decode<T: Copy + Default>(
        &self,
        index: usize,
        object: &str,
        role: &str,
        conv: impl Fn(&[u8], ComponentType, bool) -> Option<T>,
    ) -> Result<Decoded<T>> {
        let name = format!("{object} accessor {index} ({role})");
        let acc = self.src.root.accessors.get(index).ok_or_else(|| {
            self.err(
                &name,
                format!(
                    "accessor {index} to exist ({} accessors)",
                    self.src.root.accessors.len()
                ),
            )
        })?;
        let (Checked::Valid(ty), Checked::Valid(comp)) = (acc.type_, acc.component_type) else {
            return Err(self.err(&name, "a valid type and componentType"));
        };
        let comp = comp.0;
        let norm = acc.normalized;
        let count = acc.count.0;
        let (offsets, elem) = layout(ty, comp);
        let width = offsets.len();
        self.charge(
            &name,
            count
                .saturating_mul(width as u64)
                .saturating_mul(std::mem::size_of::<T>() as u64),
        )?;
        let bad_comp = || {
            self.err(
                &name,
                format!("a component type fit for {role}, found {comp:?}"),
            )
        };
        let mut values: Vec<T>;
        if let Some(v) = acc.buffer_view {
            let (bytes, stride) = self.view(v.value(), &name)?;
            let stride = stride.unwrap_or(elem);
            if stride < elem {
                return Err(self.err(
                    &name,
                    format!("byteStride {stride} of at least the element size {elem}"),
                ));
            }
            let off = acc.byte_offset.map_or(0, |o| o.0);
            let need = if count == 0 {
                Some(0)
            } else {
                (count - 1)
                    .checked_mul(stride as u64)
                    .and_then(|x| x.checked_add(off))
                    .and_then(|x| x.checked_add(elem as u64))
            };
            if need.is_none_or(|n| n > bytes.len() as u64) {
                return Err(self.err(
                    &name,
                    format!(
                        "{count} elements of {elem} bytes (stride {stride}, offset {off}) inside buffer view {} of {} bytes",
                        v.value(),
                        bytes.len()
                    ),
                ));
            }
            values = Vec::with_capacity(count as usize * width);
            for i in 0..count as usize {
                let e = off as usize + i * stride;
                for &o in &offsets {
                    let b = bytes.get(e + o..).ok_or_else(bad_comp)?;
                    values.push(conv(b, comp, norm).ok_or_else(bad_comp)?);
                }
            }
        } else {
            // No buffer view: zeros, then sparse substitution (a valid file always has sparse).
            let total = count.saturating_mul(width as u64);
            if total > MAX_ZERO_COMPONENTS {
                return Err(self.err(
                    &name,
                    format!("at most {MAX_ZERO_COMPONENTS} components without a buffer view"),
                ));
            }
            // Check the component type is acceptable for the role even without data.
            conv(&[0u8; 4], comp, norm).ok_or_else(bad_comp)?;
            values = vec![T::default(); total as usize];
        }
        if let Some(sparse) = &acc.sparse {
            let n = sparse.count.0;
            if n > count {
                return Err(self.err(
                    &name,
                    format!("sparse count {n} at most the accessor count {count}"),
                ));
            }
            let Checked::Valid(ic) = sparse.indices.component_type else {
                return Err(self.err(&name, "a valid sparse indices componentType"));
            };
            let ic = ic.0;
            let (ib, _) = self.view(
                sparse.indices.buffer_view.value(),
                &format!("{name} sparse indices"),
            )?;
            let (vb, _) = self.view(
                sparse.values.buffer_view.value(),
                &format!("{name} sparse values"),
            )?;
            let isz = comp_size(ic) as u64;
            let ioff = sparse.indices.byte_offset.0;
            let voff = sparse.values.byte_offset.0;
            let fits = |off: u64, size: u64, len: usize| {
                n.checked_mul(size)
                    .and_then(|x| x.checked_add(off))
                    .is_some_and(|x| x <= len as u64)
            };
            if !fits(ioff, isz, ib.len()) || !fits(voff, elem as u64, vb.len()) {
                return Err(self.err(
                    &name,
                    format!("{n} sparse indices and values inside their buffer views"),
                ));
            }
            for k in 0..n as usize {
                let at = ioff as usize + k * isz as usize;
                let target = ib
                    .get(at..)
                    .and_then(|b| read_uint(b, ic))
                    .ok_or_else(|| self.err(&name, "unsigned sparse indices"))?;
                if u64::from(target) >= count {
                    return Err(self.err(
                        &name,
                        format!("sparse index {target} below the count {count}"),
                    ));
                }
                let e = voff as usize + k * elem;
                for (j, &o) in offsets.iter().enumerate() {
                    let b = vb.get(e + o..).ok_or_else(bad_comp)?;
                    values[target as usize * width + j] =
                        conv(b, comp, norm).ok_or_else(bad_comp)?;
                }
            }
        }
        Ok(Decoded {
            values,
            width,
            ty,
            comp,
        })
    }

    /// Decodes accessor `index` as floats (normalized integers mapped per the spec), requiring
    /// one of the element types `types`; rejects NaN and infinities.
    pub fn floats(
        &self,
        index: usize,
        object: &str,
        role: &str,
        types: &[Type],
    ) -> Result<Decoded<f32>> {
        let d = self.decode(index, object, role, |b, c, n| Some(read_float(b, c, n)))?;
        let name = || format!("{object} accessor {index} ({role})");
        if !types.contains(&d.ty) {
            let want: Vec<_> = types.iter().map(|&t| type_name(t)).collect();
            return Err(self.err(
                name(),
                format!("type {}, found {}", want.join(" or "), type_name(d.ty)),
            ));
        }
        if let Some(i) = d.values.iter().position(|v| !v.is_finite()) {
            return Err(self.err(
                name(),
                format!(
                    "finite values, found {} at element {}",
                    d.values[i],
                    i / d.width
                ),
            ));
        }
        Ok(d)
    }

    /// Decodes accessor `index` as unsigned integers (u8, u16 or u32, not normalized),
    /// requiring element type `ty`.
    pub fn uints(&self, index: usize, object: &str, role: &str, ty: Type) -> Result<Decoded<u32>> {
        let d = self.decode(
            index,
            object,
            role,
            |b, c, n| {
                if n { None } else { read_uint(b, c) }
            },
        )?;
        if d.ty != ty {
            return Err(self.err(
                format!("{object} accessor {index} ({role})"),
                format!("type {}, found {}", type_name(ty), type_name(d.ty)),
            ));
        }
        Ok(d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalized_formulas() {
        assert_eq!(read_float(&[255], ComponentType::U8, true), 1.0);
        assert_eq!(read_float(&[0x80], ComponentType::I8, true), -1.0);
        assert_eq!(read_float(&[0x81], ComponentType::I8, true), -1.0);
        assert_eq!(read_float(&[127], ComponentType::I8, true), 1.0);
        assert_eq!(read_float(&[0xff, 0xff], ComponentType::U16, true), 1.0);
        assert_eq!(read_float(&[0x00, 0x80], ComponentType::I16, true), -1.0);
        assert_eq!(
            read_float(&[0x00, 0x80], ComponentType::I16, false),
            -32768.0
        );
    }

    #[test]
    fn matrix_padding() {
        assert_eq!(layout(Type::Mat3, ComponentType::U8).1, 12);
        assert_eq!(layout(Type::Mat3, ComponentType::U8).0[3], 4);
        assert_eq!(layout(Type::Mat2, ComponentType::I16).1, 8);
        assert_eq!(layout(Type::Mat4, ComponentType::F32).1, 64);
        assert_eq!(layout(Type::Vec3, ComponentType::U16).1, 6);
    }
}
