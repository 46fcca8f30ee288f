//! Where a glTF's bytes live: the `.glb` container (a JSON chunk and a binary chunk in
//! one file), the buffers its JSON names (the GLB's binary chunk, `data:` URIs, external
//! `.bin` files) and the byte ranges of its buffer views, decoded first when they are
//! `EXT_meshopt_compression` views.
//!
//! Files are memory-mapped, never read whole: a scan whose `.bin` is several GB costs
//! address space, and the pages the importer touches, not RAM. Only `data:` URIs (which
//! are inside the JSON, so already in memory) and meshopt-compressed views (decoded per
//! mesh) are held as decoded bytes. Every offset and length from the file is checked
//! with checked arithmetic before it is sliced.

use std::collections::HashMap;
use std::ops::Range;
use std::path::{Path, PathBuf};

use ::gltf::json;
use base64::Engine as _;

use crate::assets::{open_regular, AssetError, Assets};
use crate::MeshError;

/// `glTF`, little-endian: the first four bytes of every `.glb`.
pub(crate) const GLB_MAGIC: &[u8; 4] = b"glTF";
/// `JSON` and `BIN\0`, the chunk types of a `.glb`.
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;

/// The `EXT_meshopt_compression` extension and its ratified successor, read alike.
const MESHOPT: [&str; 2] = ["EXT_meshopt_compression", "KHR_meshopt_compression"];

/// Decoded meshopt data over compressed size: the codecs cannot expand more than this
/// (the vertex codec's densest block is 2 header bits per 16 bytes, 64:1; index
/// sequences take at least a byte per index), so a larger claim is a lie that would only
/// make us allocate, and is refused before decoding.
const MESHOPT_MAX_RATIO: u64 = 1024;
/// Slack over [`MESHOPT_MAX_RATIO`] for tiny views (headers and tails of a few bytes).
const MESHOPT_SLACK_BYTES: u64 = 64 << 10;

/// The two parts of a glTF file: its JSON, and the range of the GLB binary chunk.
#[derive(Debug)]
pub(crate) struct Container {
    pub json: Range<usize>,
    pub bin: Option<Range<usize>>,
}

/// Split `bytes` (a whole `.gltf` or `.glb` file) into its JSON and binary chunk.
pub(crate) fn split(path: &Path, bytes: &[u8]) -> Result<Container, MeshError> {
    if !bytes.starts_with(GLB_MAGIC) {
        return Ok(Container {
            json: 0..bytes.len(),
            bin: None,
        });
    }
    let u32_at = |at: usize| -> Option<u32> {
        let b = bytes.get(at..at.checked_add(4)?)?;
        Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    let short = |what: &str| MeshError::truncated(path, format!("GLB: {what}"));
    let version = u32_at(4).ok_or_else(|| short("the 12-byte header is cut short"))?;
    if version != 2 {
        return Err(MeshError::malformed(
            path,
            "GLB header",
            format!("GLB version {version}; only glTF 2.0 (GLB version 2) is supported"),
        ));
    }
    let declared = u32_at(8).ok_or_else(|| short("the 12-byte header is cut short"))? as usize;
    if declared > bytes.len() {
        return Err(short(&format!(
            "the header says {declared} bytes, the file has {}",
            bytes.len()
        )));
    }
    let bytes = &bytes[..declared];
    let mut at = 12usize;
    let mut json = None;
    let mut bin = None;
    while at < bytes.len() {
        let (Some(len), Some(kind)) = (u32_at(at), u32_at(at + 4)) else {
            return Err(short(&format!("chunk header at byte {at} is cut short")));
        };
        let start = at + 8;
        let end = start
            .checked_add(len as usize)
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| {
                short(&format!(
                    "chunk at byte {at} claims {len} bytes, {} remain",
                    bytes.len().saturating_sub(start)
                ))
            })?;
        match kind {
            CHUNK_JSON if json.is_none() => json = Some(start..end),
            CHUNK_BIN if json.is_some() && bin.is_none() => bin = Some(start..end),
            CHUNK_JSON | CHUNK_BIN => {
                return Err(MeshError::malformed(
                    path,
                    format!("GLB byte {at}"),
                    "JSON chunk must come first, followed by at most one BIN chunk",
                ))
            }
            // Chunks of unknown types are skipped, as the specification says.
            _ => {}
        }
        // The chunk length includes its padding: the next chunk starts right after.
        at = end;
    }
    let json = json.ok_or_else(|| {
        MeshError::malformed(path, "GLB", "no JSON chunk (the first chunk must be JSON)")
    })?;
    Ok(Container { json, bin })
}

/// Where one buffer's bytes are.
pub(crate) enum BufferData {
    /// A range of the main file (the GLB binary chunk).
    Main(Range<usize>),
    /// An external file, memory-mapped (`None`: the file is empty).
    Mapped(Option<memmap2::Mmap>),
    /// A decoded `data:` URI.
    Owned(Vec<u8>),
}

impl BufferData {
    pub(crate) fn bytes<'a>(&'a self, main: &'a [u8]) -> &'a [u8] {
        match self {
            BufferData::Main(r) => &main[r.clone()],
            BufferData::Mapped(Some(m)) => m,
            BufferData::Mapped(None) => &[],
            BufferData::Owned(v) => v,
        }
    }
}

/// Memory-map `path` read-only (`None` for an empty file, which cannot be mapped).
pub(crate) fn map_file(path: &Path) -> std::io::Result<Option<memmap2::Mmap>> {
    map_opened(std::fs::File::open(path)?)
}

/// [`map_file`] for a file the input names: refused unless it is a regular file, and
/// opened without blocking ([`open_regular`]).
fn map_regular(path: &Path) -> std::io::Result<Option<memmap2::Mmap>> {
    map_opened(open_regular(path)?)
}

fn map_opened(file: std::fs::File) -> std::io::Result<Option<memmap2::Mmap>> {
    if file.metadata()?.len() == 0 {
        return Ok(None);
    }
    // SAFETY: the map is read-only and lives as long as the import. Another process
    // truncating the file meanwhile would fault the reader (SIGBUS), as for every
    // memory-mapped reader of Tessera; there is no safe way to map a file against that.
    let map = unsafe { memmap2::Mmap::map(&file) }?;
    let _ = map.advise(memmap2::Advice::Sequential);
    Ok(Some(map))
}

/// Where a glTF's external files (buffers, images) are looked up: relative to `dir`
/// (the glTF's folder), under the policy `assets`.
#[derive(Clone, Copy)]
pub(crate) struct External<'a> {
    pub dir: &'a Path,
    pub assets: &'a Assets,
}

/// Why an external file named by a URI is not read.
pub(crate) enum UriError {
    /// A URL (`file://`, `https://`): never fetched.
    Url,
    /// A bad `%` escape.
    BadEscape,
    /// Refused or missing: see [`AssetError`].
    Asset(AssetError),
}

impl External<'_> {
    /// The file the URI `uri` (not a `data:` URI) names, resolved under the policy;
    /// `what` names it in messages (`glTF buffer 0 URI`).
    pub(crate) fn resolve(&self, uri: &str, what: &str) -> Result<PathBuf, UriError> {
        if uri.contains("://") {
            return Err(UriError::Url);
        }
        let name = percent_decode(uri).ok_or(UriError::BadEscape)?;
        let what = format!("{what} '{}'", clip(uri));
        self.assets
            .resolve(self.dir, &name, &what)
            .map_err(UriError::Asset)
    }
}

/// What a URL URI is told (`file://` included: only file names and `data:` URIs are read).
pub(crate) const URL_REFUSED: &str = "is a URL, which is never fetched (file:// included); \
    glTF files are read with data: URIs and relative file names, under the input's folder \
    (or --asset-root DIR)";

/// How buffers are found: through `external` (the glTF's folder and the asset
/// policy), or nowhere (fuzzing: the input is one byte string and must not open files
/// named by its content).
pub(crate) struct Resolver<'a> {
    pub path: &'a Path,
    pub external: Option<External<'a>>,
    pub bin: Option<Range<usize>>,
}

impl Resolver<'_> {
    /// Load buffer `index` (a GLB's own binary chunk, a `data:` URI or an external file),
    /// of which the first `need` bytes are read (a `data:` URI is decoded that far only:
    /// the images that often follow the geometry in it stay undecoded).
    pub(crate) fn load(
        &self,
        root: &json::Root,
        index: usize,
        need: u64,
    ) -> Result<BufferData, MeshError> {
        let at = format!("buffer {index}");
        let buffer = root.buffers.get(index).ok_or_else(|| {
            MeshError::malformed(
                self.path,
                &at,
                format!(
                    "does not exist (the file has {} buffers)",
                    root.buffers.len()
                ),
            )
        })?;
        let Some(uri) = &buffer.uri else {
            if index == 0 {
                if let Some(bin) = &self.bin {
                    return Ok(BufferData::Main(bin.clone()));
                }
            }
            let why = if meshopt_fallback(buffer) {
                "is an EXT_meshopt_compression fallback without data, read by a view that is not compressed"
            } else {
                "has no uri and is not the binary chunk of a .glb"
            };
            return Err(MeshError::malformed(self.path, at, why));
        };
        if let Some(rest) = uri.strip_prefix("data:") {
            return decode_data_uri(rest, need)
                .map(BufferData::Owned)
                .map_err(|why| {
                    MeshError::malformed(self.path, at, format!("bad data URI: {why}"))
                });
        }
        let Some(external) = self.external else {
            return Err(MeshError::malformed(
                self.path,
                at,
                format!(
                    "names an external file '{}', which this reader may not open",
                    clip(uri)
                ),
            ));
        };
        let file = match external.resolve(uri, &format!("glTF buffer {index} URI")) {
            Ok(file) => file,
            Err(UriError::Url) => {
                return Err(MeshError::malformed(
                    self.path,
                    at,
                    format!("uri '{}' {URL_REFUSED}", clip(uri)),
                ))
            }
            Err(UriError::BadEscape) => {
                return Err(MeshError::malformed(
                    self.path,
                    &at,
                    format!("uri '{}' is badly percent-encoded", clip(uri)),
                ))
            }
            Err(UriError::Asset(AssetError::Refused(detail))) => {
                return Err(MeshError::Refused {
                    path: self.path.to_path_buf(),
                    detail,
                })
            }
            Err(UriError::Asset(AssetError::Missing { resolved, cause })) => {
                return Err(MeshError::malformed(
                    self.path,
                    at,
                    format!(
                        "cannot read its file '{}' ({}): {cause}",
                        clip(uri),
                        resolved.display()
                    ),
                ))
            }
        };
        map_regular(&file).map(BufferData::Mapped).map_err(|e| {
            MeshError::malformed(
                self.path,
                at,
                format!(
                    "cannot read its file '{}' ({}): {e}",
                    clip(uri),
                    file.display()
                ),
            )
        })
    }
}

/// A buffer that `EXT_meshopt_compression` marks as a fallback (may have no data).
fn meshopt_fallback(buffer: &json::Buffer) -> bool {
    let ext = buffer.extensions.as_ref();
    MESHOPT
        .iter()
        .find_map(|name| ext.and_then(|e| e.others.get(*name)))
        .and_then(|e| e.get("fallback"))
        .and_then(|f| f.as_bool())
        == Some(true)
}

/// At most 60 characters of a URI for a message (data URIs run to megabytes).
pub(crate) fn clip(s: &str) -> String {
    match s.char_indices().nth(60) {
        Some((cut, _)) => format!("{}...", &s[..cut]),
        None => s.to_string(),
    }
}

/// The first `need` bytes (or all, if fewer) of a `data:` URI, given after `data:`
/// (`[mediatype][;base64],payload`).
pub(crate) fn decode_data_uri(rest: &str, need: u64) -> Result<Vec<u8>, String> {
    let (meta, payload) = rest
        .split_once(',')
        .ok_or_else(|| "no ',' before the data".to_string())?;
    if meta.ends_with(";base64") {
        // Padding is optional in the wild; whitespace is not part of base64.
        let engine = base64::engine::GeneralPurpose::new(
            &base64::alphabet::STANDARD,
            base64::engine::GeneralPurposeConfig::new()
                .with_decode_padding_mode(base64::engine::DecodePaddingMode::Indifferent),
        );
        // 4 characters per 3 bytes (base64 has no whitespace to skip): decode the
        // characters of the first `need` bytes.
        let payload = payload.trim().as_bytes();
        let chars = need.div_ceil(3).saturating_mul(4);
        let payload = match usize::try_from(chars) {
            Ok(n) if n < payload.len() => &payload[..n],
            _ => payload,
        };
        engine.decode(payload).map_err(|e| format!("base64: {e}"))
    } else {
        percent_decode(payload)
            .ok_or_else(|| "bad percent-encoding".to_string())
            .map(String::into_bytes)
    }
}

/// `%20` -> ` ` (URIs of files with spaces); `None` for a bad escape or non-UTF-8 result.
pub(crate) fn percent_decode(s: &str) -> Option<String> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = std::str::from_utf8(b.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// The bytes of buffer views, raw or decoded.
pub(crate) struct Views<'a> {
    pub path: &'a Path,
    pub root: &'a json::Root,
    pub main: &'a [u8],
    /// Loaded buffers by index (`None`: not needed by what is read).
    pub buffers: &'a [Option<BufferData>],
    /// Meshopt-compressed views decoded for the mesh being read.
    pub decoded: &'a HashMap<usize, Vec<u8>>,
}

/// The meshopt part of a buffer view (`extensions.EXT_meshopt_compression`).
pub(crate) struct MeshoptView {
    pub buffer: usize,
    pub byte_offset: u64,
    pub byte_length: u64,
    pub byte_stride: u64,
    pub count: u64,
    pub mode: String,
    pub filter: String,
}

/// The meshopt extension of view `view`, if it has one (an error when it is malformed).
pub(crate) fn meshopt_of(
    path: &Path,
    root: &json::Root,
    view: usize,
) -> Result<Option<MeshoptView>, MeshError> {
    let Some(v) = root.buffer_views.get(view) else {
        return Ok(None);
    };
    let Some(ext) = MESHOPT
        .iter()
        .find_map(|name| v.extensions.as_ref().and_then(|e| e.others.get(*name)))
    else {
        return Ok(None);
    };
    let bad = |why: &str| {
        MeshError::malformed(
            path,
            format!("bufferView {view}"),
            format!("EXT_meshopt_compression: {why}"),
        )
    };
    let num = |key: &str, default: Option<u64>| -> Result<u64, MeshError> {
        match ext.get(key) {
            None => default.ok_or_else(|| bad(&format!("'{key}' is missing"))),
            Some(x) => x
                .as_u64()
                .ok_or_else(|| bad(&format!("'{key}' is not a non-negative integer"))),
        }
    };
    let text = |key: &str, default: &str| -> Result<String, MeshError> {
        match ext.get(key) {
            None => Ok(default.to_string()),
            Some(x) => x
                .as_str()
                .map(str::to_string)
                .ok_or_else(|| bad(&format!("'{key}' is not a string"))),
        }
    };
    Ok(Some(MeshoptView {
        buffer: usize::try_from(num("buffer", None)?).map_err(|_| bad("'buffer' is too large"))?,
        byte_offset: num("byteOffset", Some(0))?,
        byte_length: num("byteLength", None)?,
        byte_stride: num("byteStride", None)?,
        count: num("count", None)?,
        mode: text("mode", "")?,
        filter: text("filter", "NONE")?,
    }))
}

/// The buffer a view reads its stored bytes from (the meshopt source for compressed
/// views), and the end of the bytes it reads there (`u64::MAX` if that overflows).
pub(crate) fn source_buffer(
    path: &Path,
    root: &json::Root,
    view: usize,
) -> Result<(usize, u64), MeshError> {
    if let Some(m) = meshopt_of(path, root, view)? {
        let end = m.byte_offset.checked_add(m.byte_length);
        return Ok((m.buffer, end.unwrap_or(u64::MAX)));
    }
    let v = root
        .buffer_views
        .get(view)
        .ok_or_else(|| no_view(path, root, view))?;
    let end = v
        .byte_offset
        .map_or(0, |o| o.0)
        .checked_add(v.byte_length.0);
    Ok((v.buffer.value(), end.unwrap_or(u64::MAX)))
}

fn no_view(path: &Path, root: &json::Root, view: usize) -> MeshError {
    MeshError::malformed(
        path,
        format!("bufferView {view}"),
        format!(
            "does not exist (the file has {} buffer views)",
            root.buffer_views.len()
        ),
    )
}

/// `bytes[offset..offset + len]` of buffer `buffer`, or an error saying who needed what.
fn slice_of<'b>(
    path: &Path,
    bytes: &'b [u8],
    what: &str,
    buffer: usize,
    offset: u64,
    len: u64,
) -> Result<&'b [u8], MeshError> {
    let end = offset.checked_add(len);
    match end {
        Some(end) if end <= bytes.len() as u64 => Ok(&bytes[offset as usize..end as usize]),
        _ => Err(MeshError::truncated(
            path,
            format!(
                "{what} needs bytes {offset}..{} of buffer {buffer}, which has only {} bytes",
                end.map_or_else(|| "(overflow)".to_string(), |e| e.to_string()),
                bytes.len()
            ),
        )),
    }
}

impl<'a> Views<'a> {
    fn buffer_bytes(&self, buffer: usize, who: &str) -> Result<&'a [u8], MeshError> {
        match self.buffers.get(buffer) {
            Some(Some(b)) => Ok(b.bytes(self.main)),
            _ => Err(MeshError::malformed(
                self.path,
                who,
                format!("buffer {buffer} was not loaded (it does not exist)"),
            )),
        }
    }

    /// The bytes of view `view` and its byte stride (`None`: tightly packed).
    pub(crate) fn get(&self, view: usize) -> Result<(&'a [u8], Option<usize>), MeshError> {
        let v = self
            .root
            .buffer_views
            .get(view)
            .ok_or_else(|| no_view(self.path, self.root, view))?;
        let stride = v.byte_stride.map(|s| s.0);
        if let Some(d) = self.decoded.get(&view) {
            return Ok((d.as_slice(), stride));
        }
        let who = format!("bufferView {view}");
        let bytes = self.buffer_bytes(v.buffer.value(), &who)?;
        let offset = v.byte_offset.map_or(0, |o| o.0);
        let s = slice_of(
            self.path,
            bytes,
            &who,
            v.buffer.value(),
            offset,
            v.byte_length.0,
        )?;
        Ok((s, stride))
    }

    /// Decode the meshopt-compressed view `view` (its extension `m`).
    pub(crate) fn decode_meshopt(
        &self,
        view: usize,
        m: &MeshoptView,
    ) -> Result<Vec<u8>, MeshError> {
        let who = format!("bufferView {view}");
        let bad = |why: String| {
            MeshError::malformed(self.path, &who, format!("EXT_meshopt_compression: {why}"))
        };
        let src_bytes = self.buffer_bytes(m.buffer, &who)?;
        let src = slice_of(
            self.path,
            src_bytes,
            &who,
            m.buffer,
            m.byte_offset,
            m.byte_length,
        )?;
        let (count, stride) = (m.count, m.byte_stride);
        let size = count
            .checked_mul(stride)
            .filter(|&s| {
                s <= (src.len() as u64).saturating_mul(MESHOPT_MAX_RATIO) + MESHOPT_SLACK_BYTES
            })
            .ok_or_else(|| {
                bad(format!(
                    "{count} elements of {stride} bytes cannot come from {} compressed bytes",
                    src.len()
                ))
            })?;
        let (count, stride) = (count as usize, stride as usize);
        let native = |e: meshopt::Error| bad(format!("the data does not decode ({e:?})"));
        let mut out = match m.mode.as_str() {
            "ATTRIBUTES" => {
                if stride == 0 || stride % 4 != 0 || stride > 256 {
                    return Err(bad(format!(
                        "byteStride {stride} for ATTRIBUTES (must be a multiple of 4, at most 256)"
                    )));
                }
                let mut words = vec![0u32; size as usize / 4];
                // SAFETY: `words` holds `count * stride` bytes, the decoder writes at most
                // that many; `src` is a valid slice; the stride was checked against the
                // decoder's preconditions (multiple of 4, at most 256) above.
                let rc = unsafe {
                    meshopt::ffi::meshopt_decodeVertexBuffer(
                        words.as_mut_ptr().cast(),
                        count,
                        stride,
                        src.as_ptr(),
                        src.len(),
                    )
                };
                if rc != 0 {
                    return Err(bad(format!(
                        "the vertex data does not decode (meshoptimizer error {rc})"
                    )));
                }
                self.filter(&mut words, stride, &m.filter).map_err(bad)?;
                bytemuck::cast_slice(&words).to_vec()
            }
            "TRIANGLES" | "INDICES" => {
                if m.filter != "NONE" {
                    return Err(bad(format!(
                        "filter {} on {} (filters are for ATTRIBUTES)",
                        m.filter, m.mode
                    )));
                }
                let triangles = m.mode == "TRIANGLES";
                if triangles && count % 3 != 0 {
                    return Err(bad(format!(
                        "TRIANGLES with count {count}, not a multiple of 3"
                    )));
                }
                match (stride, triangles) {
                    (2, true) => bytemuck::cast_slice(
                        &meshopt::decode_index_buffer::<u16>(src, count).map_err(native)?,
                    )
                    .to_vec(),
                    (4, true) => bytemuck::cast_slice(
                        &meshopt::decode_index_buffer::<u32>(src, count).map_err(native)?,
                    )
                    .to_vec(),
                    (2, false) => bytemuck::cast_slice(
                        &meshopt::decode_index_sequence::<u16>(src, count).map_err(native)?,
                    )
                    .to_vec(),
                    (4, false) => bytemuck::cast_slice(
                        &meshopt::decode_index_sequence::<u32>(src, count).map_err(native)?,
                    )
                    .to_vec(),
                    _ => {
                        return Err(bad(format!(
                            "byteStride {stride} for {} (must be 2 or 4)",
                            m.mode
                        )))
                    }
                }
            }
            other => {
                return Err(bad(format!(
                    "unknown mode '{other}' (ATTRIBUTES, TRIANGLES or INDICES)"
                )))
            }
        };
        out.truncate(size as usize);
        Ok(out)
    }

    /// Undo the meshopt filter `filter` in place on decoded vertex data.
    fn filter(&self, words: &mut [u32], stride: usize, filter: &str) -> Result<(), String> {
        match (filter, stride) {
            ("NONE", _) => {}
            ("OCTAHEDRAL", 4) => meshopt::decode_filter_oct::<i8>(bytemuck::cast_slice_mut(words)),
            ("OCTAHEDRAL", 8) => meshopt::decode_filter_oct::<i16>(bytemuck::cast_slice_mut(words)),
            ("QUATERNION", 8) => meshopt::decode_filter_quat(bytemuck::cast_slice_mut(words)),
            // The exponential filter decodes every 32-bit word on its own.
            ("EXPONENTIAL", _) => meshopt::decode_filter_exp::<1>(bytemuck::cast_slice_mut(words)),
            ("COLOR", 4) => meshopt::decode_filter_color::<u8>(bytemuck::cast_slice_mut(words)),
            ("COLOR", 8) => meshopt::decode_filter_color::<u16>(bytemuck::cast_slice_mut(words)),
            ("OCTAHEDRAL" | "QUATERNION" | "COLOR", _) => {
                return Err(format!("filter {filter} with byteStride {stride}"));
            }
            (other, _) => return Err(format!("unknown filter '{other}'")),
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn data_uris_decode_with_or_without_padding() {
        let all = u64::MAX;
        assert_eq!(
            decode_data_uri("application/octet-stream;base64,AAEC", all).unwrap(),
            [0, 1, 2]
        );
        assert_eq!(decode_data_uri(";base64,AAE", all).unwrap(), [0, 1]);
        assert_eq!(decode_data_uri(",a%20b", all).unwrap(), b"a b");
        assert!(decode_data_uri(";base64,A*", all).is_err());
        assert!(decode_data_uri("application/octet-stream;base64", all).is_err());
        // A prefix: whole groups of 4 characters, enough for the bytes asked for.
        assert_eq!(
            decode_data_uri(";base64,AAECAwQF", 4).unwrap(),
            [0, 1, 2, 3, 4, 5]
        );
        assert_eq!(decode_data_uri(";base64,AAECAwQF", 3).unwrap(), [0, 1, 2]);
        assert_eq!(decode_data_uri(";base64,AAECAwQF", 0).unwrap(), [0u8; 0]);
    }

    #[test]
    fn percent_escapes() {
        assert_eq!(
            percent_decode("my%20scan.bin").as_deref(),
            Some("my scan.bin")
        );
        assert_eq!(percent_decode("a%2"), None);
        assert_eq!(percent_decode("a%zz"), None);
    }

    #[test]
    fn glb_chunks_are_bounds_checked() {
        let p = Path::new("x.glb");
        let mut glb = b"glTF".to_vec();
        glb.extend_from_slice(&2u32.to_le_bytes());
        glb.extend_from_slice(&36u32.to_le_bytes());
        glb.extend_from_slice(&4u32.to_le_bytes());
        glb.extend_from_slice(&CHUNK_JSON.to_le_bytes());
        glb.extend_from_slice(b"{}  ");
        glb.extend_from_slice(&4u32.to_le_bytes());
        glb.extend_from_slice(&CHUNK_BIN.to_le_bytes());
        glb.extend_from_slice(&[1, 2, 3, 4]);
        let c = split(p, &glb).unwrap();
        assert_eq!(&glb[c.json], b"{}  ");
        assert_eq!(&glb[c.bin.unwrap()], [1, 2, 3, 4]);
        // A chunk longer than the file.
        let mut bad = glb.clone();
        bad[24..28].copy_from_slice(&999u32.to_le_bytes());
        assert!(split(p, &bad)
            .unwrap_err()
            .to_string()
            .contains("claims 999 bytes"));
        // A header longer than the file.
        assert!(split(p, &glb[..30]).is_err());
    }
}
