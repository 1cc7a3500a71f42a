//! Containers and resources: splitting a GLB into its chunks, telling glTF JSON from
//! anything else, resolving buffer and image URIs (data: URIs, files beside the .gltf),
//! and packing a .gltf with its files into one GLB.
//!
//! The GLB reader is ours rather than `gltf::binary`: that one subtracts from the header's
//! length without checking it, and refuses the unknown chunk types that the GLB spec says
//! a reader must skip.

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use gltf::json::Value;

use super::error::{Element, SceneError};

const GLB_MAGIC: &[u8; 4] = b"glTF";
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;

/// A glTF file split into its JSON text and, for GLB, its BIN chunk.
pub(crate) struct Container<'a> {
    /// The JSON document.
    pub json: &'a [u8],
    /// The GLB BIN chunk, if any.
    pub bin: Option<&'a [u8]>,
    /// Whether the bytes were a GLB.
    pub is_glb: bool,
}

fn read_u32(bytes: &[u8], at: usize) -> Option<u32> {
    let b = bytes.get(at..at.checked_add(4)?)?;
    Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

/// Splits `bytes` into JSON and BIN, or says why they are not glTF.
pub(crate) fn split(bytes: &[u8]) -> Result<Container<'_>, SceneError> {
    if bytes.starts_with(GLB_MAGIC) {
        return split_glb(bytes);
    }
    // glTF JSON is an object; allow a UTF-8 byte order mark and leading whitespace.
    let text = bytes.strip_prefix(&[0xEF, 0xBB, 0xBF]).unwrap_or(bytes);
    match text.iter().find(|b| !b.is_ascii_whitespace()) {
        Some(b'{') => Ok(Container {
            json: text,
            bin: None,
            is_glb: false,
        }),
        Some(_) => Err(SceneError::NotGltf(
            "expected a GLB header ('glTF') or a JSON object".into(),
        )),
        None => Err(SceneError::NotGltf("the file is empty".into())),
    }
}

fn split_glb(bytes: &[u8]) -> Result<Container<'_>, SceneError> {
    let glb = |m: String| SceneError::Glb(m);
    if bytes.len() < 12 {
        return Err(glb(format!(
            "truncated: {} bytes, but the GLB header alone needs 12",
            bytes.len()
        )));
    }
    let version = read_u32(bytes, 4).unwrap_or(0);
    if version != 2 {
        return Err(glb(format!(
            "version {version} is not supported (only glTF 2.0)"
        )));
    }
    let length = read_u32(bytes, 8).unwrap_or(0) as usize;
    if length > bytes.len() {
        return Err(glb(format!(
            "truncated: the header says {length} bytes, but there are only {}",
            bytes.len()
        )));
    }
    if length < 20 {
        return Err(glb(format!(
            "the header's length {length} leaves no room for a JSON chunk"
        )));
    }
    let bytes = &bytes[..length];
    let mut at = 12;
    let mut json = None;
    let mut bin = None;
    let mut chunk = 0;
    while at < bytes.len() {
        let (Some(len), Some(ty)) = (read_u32(bytes, at), read_u32(bytes, at + 4)) else {
            return Err(glb(format!("truncated: chunk {chunk} header at byte {at}")));
        };
        let start = at + 8;
        let end = start
            .checked_add(len as usize)
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| {
                glb(format!(
                    "truncated: chunk {chunk} declares {len} bytes, but only {} remain",
                    bytes.len() - start
                ))
            })?;
        let data = &bytes[start..end];
        match (chunk, ty) {
            (0, CHUNK_JSON) => json = Some(data),
            (0, _) => return Err(glb("the first chunk is not JSON".into())),
            (1, CHUNK_BIN) => bin = Some(data),
            // The spec asks readers to skip chunks of unknown types.
            _ => {}
        }
        chunk += 1;
        // Chunks are padded to four bytes; tolerate writers that forgot the last padding.
        at = end.next_multiple_of(4);
    }
    let json = json.ok_or_else(|| glb("no JSON chunk".into()))?;
    Ok(Container {
        json,
        bin,
        is_glb: true,
    })
}

/// Decodes standard (or URL-safe) base64, ignoring whitespace and padding.
pub(crate) fn base64_decode(text: &str) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(text.len() / 4 * 3 + 3);
    let mut acc = 0u32;
    let mut bits = 0u32;
    for (i, c) in text.bytes().enumerate() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            b'=' => break,
            c if c.is_ascii_whitespace() => continue,
            _ => return Err(format!("invalid base64 character {:?} at {i}", c as char)),
        };
        acc = (acc << 6) | v as u32;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Ok(out)
}

/// Decodes `%XX` escapes in a URI (file names with spaces are written `%20`).
fn percent_decode(uri: &str) -> Cow<'_, str> {
    if !uri.contains('%') {
        return Cow::Borrowed(uri);
    }
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        if b[i] == b'%' && i + 2 < b.len() {
            if let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2])) {
                out.push((h * 16 + l) as u8);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    Cow::Owned(String::from_utf8_lossy(&out).into_owned())
}

/// Where external files are looked up.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Resolver<'p> {
    /// Folder of the .gltf file; `None` for a scene that must be self-contained.
    pub base_dir: Option<&'p Path>,
}

/// A URI's bytes, and the MIME type a data: URI declares.
pub(crate) struct Resolved {
    pub bytes: Vec<u8>,
    pub mime: Option<String>,
    /// The file it came from, for messages.
    pub file: Option<PathBuf>,
}

impl Resolver<'_> {
    /// Reads what `uri` points at; errors name `element`.
    pub fn resolve(&self, uri: &str, element: Element) -> Result<Resolved, SceneError> {
        if let Some(rest) = uri.strip_prefix("data:") {
            let (header, payload) = rest.split_once(',').ok_or_else(|| {
                SceneError::at(element, "data: URI has no ',' before its payload")
            })?;
            let (mime, base64) = match header.strip_suffix(";base64") {
                Some(m) => (m, true),
                None => (header, false),
            };
            let bytes = if base64 {
                base64_decode(payload)
                    .map_err(|e| SceneError::at(element, format!("data: URI: {e}")))?
            } else {
                percent_decode(payload).as_bytes().to_vec()
            };
            let mime = (!mime.is_empty()).then(|| mime.to_owned());
            return Ok(Resolved {
                bytes,
                mime,
                file: None,
            });
        }
        if let Some((scheme, _)) = uri.split_once(':') {
            // A URL scheme (http:, file:) is never fetched; one letter is a Windows drive.
            if scheme.len() > 1
                && scheme
                    .bytes()
                    .all(|c| c.is_ascii_alphanumeric() || c == b'+')
            {
                return Err(SceneError::at(
                    element,
                    format!("URI '{uri}' is not supported: only data: URIs and relative paths"),
                ));
            }
        }
        let Some(base) = self.base_dir else {
            return Err(SceneError::at(
                element,
                format!(
                    "refers to external file '{uri}', but the scene must be self-contained \
                     (pack the .gltf and its files into one GLB)"
                ),
            ));
        };
        let rel = percent_decode(uri);
        let path = base.join(rel.as_ref());
        match std::fs::read(&path) {
            Ok(bytes) => Ok(Resolved {
                bytes,
                mime: None,
                file: Some(path),
            }),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                Err(SceneError::at(element, format!("file '{uri}' not found")))
            }
            Err(e) => Err(SceneError::at(
                element,
                format!("cannot read file '{uri}': {e}"),
            )),
        }
    }
}

/// Every buffer's bytes: the GLB BIN chunk borrowed, other buffers read or decoded. Each is
/// checked to hold at least its declared `byteLength`, and cut to it.
pub(crate) fn load_buffers<'a>(
    doc: &gltf::Document,
    bin: Option<&'a [u8]>,
    resolver: Resolver<'_>,
) -> Result<Vec<Cow<'a, [u8]>>, SceneError> {
    let mut out = Vec::with_capacity(doc.buffers().len());
    for buffer in doc.buffers() {
        let element = Element::Buffer(buffer.index());
        let (data, what): (Cow<'a, [u8]>, String) = match buffer.source() {
            gltf::buffer::Source::Bin => {
                let bin = bin.ok_or_else(|| {
                    SceneError::at(
                        element,
                        "has no URI, so it is the GLB BIN chunk, but there is no BIN chunk",
                    )
                })?;
                (Cow::Borrowed(bin), "the GLB BIN chunk".into())
            }
            gltf::buffer::Source::Uri(uri) => {
                let r = resolver.resolve(uri, element)?;
                let what = match &r.file {
                    Some(_) => format!("file '{uri}'"),
                    None => "its data: URI".into(),
                };
                (Cow::Owned(r.bytes), what)
            }
        };
        let declared = buffer.length();
        if data.len() < declared {
            return Err(SceneError::at(
                element,
                format!(
                    "byteLength is {declared}, but {what} holds only {} bytes",
                    data.len()
                ),
            ));
        }
        out.push(match data {
            Cow::Borrowed(b) => Cow::Borrowed(&b[..declared]),
            Cow::Owned(mut v) => {
                v.truncate(declared);
                Cow::Owned(v)
            }
        });
    }
    Ok(out)
}

/// Guesses an image's MIME type from its first bytes.
pub(crate) fn sniff_mime(bytes: &[u8]) -> Option<&'static str> {
    if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        Some("image/png")
    } else if bytes.starts_with(&[0xFF, 0xD8, 0xFF]) {
        Some("image/jpeg")
    } else {
        None
    }
}

/// Packs `path` (.gltf or .glb) and every file it refers to into one self-contained GLB:
/// all buffers become the BIN chunk and every image a buffer view in it. The JSON is kept
/// otherwise as it was, unknown extensions included.
pub(crate) fn pack(path: &Path) -> Result<Vec<u8>, SceneError> {
    let bytes = std::fs::read(path).map_err(|source| SceneError::Io {
        path: path.to_owned(),
        source,
    })?;
    let container = split(&bytes)?;
    let mut root: Value = gltf::json::deserialize::from_slice(container.json)
        .map_err(|e| SceneError::Json(e.to_string()))?;
    if !root.is_object() {
        return Err(SceneError::NotGltf("the JSON is not an object".into()));
    }
    let resolver = Resolver {
        base_dir: Some(path.parent().unwrap_or(Path::new("."))),
    };

    // Buffers, in order, each at a 16-byte aligned offset so that every buffer view keeps
    // the alignment its accessors need.
    let mut bin: Vec<u8> = Vec::new();
    let mut bases = Vec::new();
    let buffers = root
        .get("buffers")
        .and_then(Value::as_array)
        .cloned()
        .unwrap_or_default();
    for (i, buffer) in buffers.iter().enumerate() {
        let element = Element::Buffer(i);
        let declared = buffer
            .get("byteLength")
            .and_then(Value::as_u64)
            .ok_or_else(|| SceneError::at(element, "has no byteLength"))?
            as usize;
        let data: Cow<'_, [u8]> = match buffer.get("uri").and_then(Value::as_str) {
            Some(uri) => Cow::Owned(resolver.resolve(uri, element)?.bytes),
            None => match container.bin {
                Some(b) if container.is_glb => Cow::Borrowed(b),
                _ => {
                    return Err(SceneError::at(
                        element,
                        "has no URI and there is no BIN chunk",
                    ))
                }
            },
        };
        if data.len() < declared {
            return Err(SceneError::at(
                element,
                format!(
                    "byteLength is {declared}, but its data holds only {} bytes",
                    data.len()
                ),
            ));
        }
        bin.resize(bin.len().next_multiple_of(16), 0);
        bases.push(bin.len() as u64);
        bin.extend_from_slice(&data[..declared]);
    }

    // Buffer views now all point into buffer 0.
    let mut views = root
        .get("bufferViews")
        .and_then(Value::as_array)
        .cloned()
        .unwrap_or_default();
    for (i, view) in views.iter_mut().enumerate() {
        let b = view
            .get("buffer")
            .and_then(Value::as_u64)
            .unwrap_or(u64::MAX) as usize;
        let base = *bases.get(b).ok_or_else(|| {
            SceneError::at(Element::BufferView(i), format!("buffer {b} does not exist"))
        })?;
        let offset = view.get("byteOffset").and_then(Value::as_u64).unwrap_or(0);
        view["buffer"] = Value::from(0u64);
        view["byteOffset"] = Value::from(base + offset);
    }

    // Images given by URI move into the BIN chunk too.
    let mut images = root
        .get("images")
        .and_then(Value::as_array)
        .cloned()
        .unwrap_or_default();
    for (i, image) in images.iter_mut().enumerate() {
        let Some(uri) = image.get("uri").and_then(Value::as_str).map(str::to_owned) else {
            continue;
        };
        let element = Element::Image(i);
        let r = resolver.resolve(&uri, element)?;
        let declared = image
            .get("mimeType")
            .and_then(Value::as_str)
            .map(str::to_owned);
        let mime = declared
            .or(r.mime.clone())
            .or_else(|| sniff_mime(&r.bytes).map(str::to_owned))
            .ok_or_else(|| {
                SceneError::at(element, format!("cannot tell the image type of '{uri}'"))
            })?;
        bin.resize(bin.len().next_multiple_of(16), 0);
        let mut view = Value::Object(Default::default());
        view["buffer"] = Value::from(0u64);
        view["byteOffset"] = Value::from(bin.len() as u64);
        view["byteLength"] = Value::from(r.bytes.len() as u64);
        bin.extend_from_slice(&r.bytes);
        let obj = image
            .as_object_mut()
            .expect("images are objects: read one above");
        obj.remove("uri");
        obj.insert("bufferView".into(), Value::from(views.len() as u64));
        obj.insert("mimeType".into(), Value::from(mime));
        views.push(view);
    }

    let obj = root.as_object_mut().expect("checked to be an object above");
    if !images.is_empty() {
        obj.insert("images".into(), Value::Array(images));
    }
    if !views.is_empty() {
        obj.insert("bufferViews".into(), Value::Array(views));
    }
    if bin.is_empty() && buffers.is_empty() {
        obj.remove("buffers");
    } else {
        let mut buffer = Value::Object(Default::default());
        buffer["byteLength"] = Value::from(bin.len() as u64);
        obj.insert("buffers".into(), Value::Array(vec![buffer]));
    }
    let json = gltf::json::serialize::to_vec(&root)
        .map_err(|e| SceneError::Json(format!("cannot serialise the packed document: {e}")))?;
    let bin = (!bin.is_empty() || !buffers.is_empty()).then_some(&bin[..]);
    write_glb(&json, bin).ok_or_else(|| {
        SceneError::NotGltf("the packed scene would be larger than a GLB can be (4 GiB)".into())
    })
}

/// Writes a GLB: header, JSON chunk padded with spaces, optional BIN chunk padded with
/// zeros, each to a multiple of 4 bytes. `None` when the file would pass the format's
/// 32-bit length (4 GiB).
pub fn write_glb(json: &[u8], bin: Option<&[u8]>) -> Option<Vec<u8>> {
    let json_len = json.len().next_multiple_of(4);
    let bin_len = bin.map_or(0, |b| b.len().next_multiple_of(4));
    let total = 12 + 8 + json_len + bin.map_or(0, |_| 8 + bin_len);
    // Both chunk lengths are below `total`, so they fit when it does.
    u32::try_from(total).ok()?;
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(GLB_MAGIC);
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json_len as u32).to_le_bytes());
    out.extend_from_slice(&CHUNK_JSON.to_le_bytes());
    out.extend_from_slice(json);
    out.resize(20 + json_len, b' ');
    if let Some(bin) = bin {
        out.extend_from_slice(&(bin_len as u32).to_le_bytes());
        out.extend_from_slice(&CHUNK_BIN.to_le_bytes());
        out.extend_from_slice(bin);
        out.resize(total, 0);
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_decodes_with_and_without_padding() {
        assert_eq!(base64_decode("aGVsbG8=").unwrap(), b"hello");
        assert_eq!(base64_decode("aGVsbG8").unwrap(), b"hello");
        assert_eq!(base64_decode("AAECAwQF").unwrap(), [0, 1, 2, 3, 4, 5]);
        assert!(base64_decode("a*b").is_err());
    }

    #[test]
    fn percent_escapes_decode() {
        assert_eq!(percent_decode("Box%20Textured.png"), "Box Textured.png");
        assert_eq!(percent_decode("100%"), "100%");
        assert_eq!(percent_decode("a%2"), "a%2");
    }

    #[test]
    fn glb_round_trips_and_truncation_is_named() {
        let glb = write_glb(br#"{"asset":{"version":"2.0"}}"#, Some(&[1, 2, 3])).unwrap();
        let c = split(&glb).unwrap();
        assert!(c.json.starts_with(b"{\"asset\""));
        assert_eq!(&c.bin.unwrap()[..3], &[1, 2, 3]);
        for cut in [0, 5, 12, 19, glb.len() - 1] {
            let err = split(&glb[..cut]);
            assert!(err.is_err(), "cut at {cut}");
        }
        assert!(matches!(split(b"\x89PNG"), Err(SceneError::NotGltf(_))));
    }
}
