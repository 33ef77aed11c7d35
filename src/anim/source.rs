//! Reading a glTF file into its JSON document and binary buffers: GLB container, external `.bin`
//! files and base64 data URIs. Images are never read or decoded.

use crate::error::{Error, Result};
use gltf_json::Root;
use std::path::{Path, PathBuf};

/// The parsed JSON of a glTF file and the bytes of each of its buffers.
pub(crate) struct Source {
    /// The JSON document, not validated.
    pub root: Root,
    /// One byte vector per `buffers[i]`, cut to its declared `byteLength` (empty for a
    /// buffer without data, see `absent`).
    pub buffers: Vec<Vec<u8>>,
    /// Per buffer: it has no data, only a `byteLength` (the fallback buffer of
    /// `EXT_meshopt_compression` / `KHR_meshopt_compression`, whose views hold compressed
    /// data elsewhere, which the engine does not decode).
    pub absent: Vec<bool>,
}

/// Compression extensions whose buffer views carry the real (compressed) data.
pub(crate) const MESHOPT: &[&str] = &["EXT_meshopt_compression", "KHR_meshopt_compression"];

/// The compression extension of a buffer or buffer view's extension map, if any.
pub(crate) fn meshopt_extension(
    others: Option<&serde_json::Map<String, serde_json::Value>>,
) -> Option<&'static str> {
    let others = others?;
    MESHOPT.iter().copied().find(|e| others.contains_key(*e))
}

/// Splits a GLB container into its JSON chunk and optional BIN chunk.
fn split_glb<'a>(path: &Path, bytes: &'a [u8]) -> Result<(&'a [u8], Option<&'a [u8]>)> {
    let bad = |what: &str| Error::malformed(path, "GLB container", what);
    let word = |at: usize| -> Option<u32> {
        let b = bytes.get(at..at.checked_add(4)?)?;
        Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    let version = word(4).ok_or_else(|| bad("a 12-byte header"))?;
    let length = word(8).ok_or_else(|| bad("a 12-byte header"))? as usize;
    if version != 2 {
        return Err(bad(&format!("version 2, found {version}")));
    }
    if length > bytes.len() || length < 12 {
        return Err(bad(&format!(
            "header length {length} within the file's {} bytes",
            bytes.len()
        )));
    }
    let bytes = &bytes[..length];
    let mut at = 12usize;
    let mut json = None;
    let mut bin = None;
    while at < bytes.len() {
        let (Some(len), Some(kind)) = (word(at), word(at + 4)) else {
            return Err(bad(&format!("a complete chunk header at byte {at}")));
        };
        let start = at + 8;
        let end = start
            .checked_add(len as usize)
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| {
                bad(&format!(
                    "chunk at byte {at} of {len} bytes within the file's {} bytes",
                    bytes.len()
                ))
            })?;
        let data = &bytes[start..end];
        match kind {
            0x4E4F_534A if json.is_none() && at == 12 => json = Some(data),
            0x004E_4942 if bin.is_none() && json.is_some() => bin = Some(data),
            _ if json.is_none() => return Err(bad("a JSON chunk first")),
            _ => {} // unknown chunks are ignored, as the spec says
        }
        at = end.div_ceil(4) * 4;
    }
    Ok((json.ok_or_else(|| bad("a JSON chunk"))?, bin))
}

/// Decodes standard base64 (with or without padding); `None` on a bad character.
fn base64_decode(text: &str) -> Option<Vec<u8>> {
    let mut out = Vec::with_capacity(text.len() / 4 * 3);
    let mut acc = 0u32;
    let mut bits = 0u32;
    for c in text.bytes() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            b'=' => break,
            b' ' | b'\n' | b'\r' | b'\t' => continue,
            _ => return None,
        };
        acc = (acc << 6) | u32::from(v);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Some(out)
}

/// Decodes `%XX` escapes of a relative URI into a file name.
fn percent_decode(uri: &str) -> String {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        if b[i] == b'%'
            && let (Some(h), Some(l)) = (
                b.get(i + 1).copied().and_then(hex),
                b.get(i + 2).copied().and_then(hex),
            )
        {
            out.push((h * 16 + l) as u8);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Whether a decoded relative URI stays inside the folder it is resolved in: not absolute, no
/// scheme or drive (`file:`, `C:`), and no `..` that climbs above its start.
fn inside_folder(rel: &str) -> bool {
    if rel.starts_with(['/', '\\']) || rel.contains(':') {
        return false;
    }
    let mut depth = 0i64;
    for part in rel.split(['/', '\\']) {
        match part {
            "" | "." => {}
            ".." => {
                depth -= 1;
                if depth < 0 {
                    return false;
                }
            }
            _ => depth += 1,
        }
    }
    true
}

impl Source {
    /// Parses `bytes` (the content of `path`, GLB or JSON) and reads every buffer; external
    /// buffers are resolved relative to `path`'s folder, read up to their `byteLength`, and
    /// refused when their URI is absolute or leaves that folder unless `allow_outside`.
    pub fn parse(path: &Path, bytes: &[u8], allow_outside: bool) -> Result<Self> {
        let (json, blob) = if bytes.starts_with(b"glTF") {
            split_glb(path, bytes)?
        } else {
            (bytes, None)
        };
        let root: Root = gltf_json::deserialize::from_slice(json)
            .map_err(|e| Error::malformed(path, "JSON", format!("a glTF 2.0 document: {e}")))?;
        let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
        let mut buffers = Vec::with_capacity(root.buffers.len());
        let mut absent = vec![false; root.buffers.len()];
        for (i, buf) in root.buffers.iter().enumerate() {
            let object = format!("buffer {i}");
            let declared = buf.byte_length.0;
            let mut data = match (&buf.uri, i, blob) {
                (None, 0, Some(blob)) => blob.to_vec(),
                (None, _, _)
                    if meshopt_extension(buf.extensions.as_ref().map(|e| &e.others)).is_some() =>
                {
                    absent[i] = true;
                    buffers.push(Vec::new());
                    continue;
                }
                (None, _, _) => {
                    return Err(Error::malformed(
                        path,
                        object,
                        "a uri (only buffer 0 of a GLB file may use the BIN chunk)",
                    ));
                }
                (Some(uri), _, _) if uri.starts_with("data:") => {
                    let payload = uri
                        .split_once(";base64,")
                        .map(|(_, p)| p)
                        .ok_or_else(|| Error::malformed(path, &object, "a base64 data URI"))?;
                    base64_decode(payload).ok_or_else(|| {
                        Error::malformed(path, &object, "valid base64 in its data URI")
                    })?
                }
                (Some(uri), _, _) => {
                    let rel = percent_decode(uri);
                    if !allow_outside && !inside_folder(&rel) {
                        return Err(Error::malformed(
                            path,
                            &object,
                            format!(
                                "a uri inside the file's folder, found {uri:?} (absolute or \
                                 leaving it; LoadOptions::allow_outside_files, or the \
                                 command line's --allow-outside-files, allows it)"
                            ),
                        ));
                    }
                    let file: PathBuf = base.join(rel);
                    crate::io::read_file(&file, Some(declared)).map_err(|e| {
                        Error::malformed(
                            path,
                            &object,
                            format!("a readable file at {}: {e}", file.display()),
                        )
                    })?
                }
            };
            if (data.len() as u64) < declared {
                return Err(Error::malformed(
                    path,
                    object,
                    format!("{declared} bytes, found only {}", data.len()),
                ));
            }
            data.truncate(declared as usize);
            buffers.push(data);
        }
        Ok(Source {
            root,
            buffers,
            absent,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_round_trip() {
        assert_eq!(base64_decode("TWFu").unwrap(), b"Man");
        assert_eq!(base64_decode("TWE=").unwrap(), b"Ma");
        assert_eq!(base64_decode("TQ==").unwrap(), b"M");
        assert!(base64_decode("T*Q=").is_none());
    }

    #[test]
    fn percent() {
        assert_eq!(percent_decode("a%20b.bin"), "a b.bin");
        assert_eq!(percent_decode("a%2"), "a%2");
    }

    #[test]
    fn uris_inside_the_folder() {
        assert!(inside_folder("a.bin"));
        assert!(inside_folder("sub/../a.bin"));
        assert!(inside_folder("./sub/a%20.bin"));
        assert!(!inside_folder("../a.bin"));
        assert!(!inside_folder("sub/../../a.bin"));
        assert!(!inside_folder("/dev/zero"));
        assert!(!inside_folder("\\\\server\\a.bin"));
        assert!(!inside_folder("C:/a.bin"));
        assert!(!inside_folder("file:///etc/hostname"));
    }

    #[test]
    fn glb_garbage_is_an_error() {
        let p = Path::new("x.glb");
        assert!(split_glb(p, b"glTF").is_err());
        assert!(split_glb(p, b"glTF\x02\0\0\0\x05\0\0\0").is_err());
        assert!(split_glb(p, b"glTF\x02\0\0\0\x0c\0\0\0").is_err());
    }
}
