//! Patch decoding off the main thread: the messages between the viewer and its decode
//! workers (`web/tessera_worker.js`, each running this same wasm module).
//!
//! - A [`Job`] is one fetched patch with what decoding it needs from the node's record
//!   (the model's attribute bits, the patch's CRC and shape, whether to make the
//!   texture's mips): [`Job::to_bytes`] on the main thread, [`run_job`] in the worker.
//! - The reply is the decoded [`PatchData`] flattened into one buffer (so it moves to
//!   the main thread as one transferred `ArrayBuffer`), the texture's mip chain
//!   included, or the decode error; [`read_reply`] turns it back into the
//!   [`Answer`] the scheduler takes, and the worker's milliseconds.
//!
//! These buffers live only between two instances of one build of this crate (never in
//! a file), so the layout is whatever is simplest: little-endian counts, then the
//! arrays' bytes. A version byte still guards against a page mixing two builds.
//!
//! Plain Rust, tested natively; the worker entry point is `crate::worker` (wasm32).

use std::sync::Arc;

use tessera_format::{
    decode_patch, texels, FormatError, ModelIndex, PatchData, PatchShape, PatchTexture,
    TextureChart, TextureCodec,
};
use tessera_stream::Answer;

/// Version of the job and reply layouts (bumped whenever either changes).
const WIRE_VERSION: u8 = 2;
/// Bytes of a job's header (the patch's bytes follow).
const JOB_HEADER_BYTES: usize = 40;
const REPLY_OK: u8 = 0;
const REPLY_FAILED: u8 = 1;

/// One patch to decode in a worker. See the module docs.
#[derive(Clone, Debug, PartialEq)]
pub struct Job {
    pub node: u32,
    pub attributes: u32,
    pub crc32: u32,
    pub shape: PatchShape,
    /// Make the texture's mip chain too (so the upload on the main thread only copies).
    pub mips: bool,
    /// The main thread uploads this patch's BC7 texture as blocks (its GPU samples BC7
    /// and the first level that fits has whole blocks): it comes back as its blocks;
    /// otherwise the worker decodes them to RGBA8 (every stored level), off the main
    /// thread.
    pub blocks: bool,
}

impl Job {
    /// The job for node `node` of `index`.
    /// `blocks`: the largest texture of a GPU that samples BC7 (`None`: it does not).
    pub fn of(
        index: &ModelIndex,
        node: u32,
        mips: bool,
        blocks: Option<u32>,
    ) -> Result<Job, FormatError> {
        let n = index.node(node as usize)?;
        Ok(Job {
            node,
            attributes: index.header().attributes,
            crc32: n.patch_crc32,
            shape: n.into(),
            mips,
            blocks: blocks.is_some_and(|max| {
                let [w, h] = n.texture_size.map(u32::from);
                texels::bc7_uploads_as_blocks(w, h, max)
            }),
        })
    }

    /// The job's message: its header, then `patch` (the patch's bytes as fetched).
    pub fn to_bytes(&self, patch: &[u8]) -> Vec<u8> {
        let mut b = Vec::with_capacity(JOB_HEADER_BYTES + patch.len());
        b.extend([WIRE_VERSION, u8::from(self.mips), u8::from(self.blocks), 0]);
        for v in [
            self.node,
            self.attributes,
            self.crc32,
            self.shape.quant_min[0],
            self.shape.quant_min[1],
            self.shape.quant_min[2],
            self.shape.vertex_count,
            self.shape.triangle_count,
        ] {
            b.extend(v.to_le_bytes());
        }
        b.extend(self.shape.texture_size[0].to_le_bytes());
        b.extend(self.shape.texture_size[1].to_le_bytes());
        debug_assert_eq!(b.len(), JOB_HEADER_BYTES);
        b.extend_from_slice(patch);
        b
    }

    /// A job's message back into the job and its patch bytes.
    pub fn parse(msg: &[u8]) -> Result<(Job, &[u8]), String> {
        if msg.len() < JOB_HEADER_BYTES {
            return Err(format!("decode job of {} bytes", msg.len()));
        }
        if msg[0] != WIRE_VERSION {
            return Err(format!(
                "decode job of layout {} (this build reads {WIRE_VERSION}): the page mixes two builds of Tessera",
                msg[0]
            ));
        }
        let u = |i: usize| u32::from_le_bytes(msg[4 + 4 * i..8 + 4 * i].try_into().unwrap());
        let h = |at: usize| u16::from_le_bytes([msg[at], msg[at + 1]]);
        let job = Job {
            node: u(0),
            attributes: u(1),
            crc32: u(2),
            shape: PatchShape {
                quant_min: [u(3), u(4), u(5)],
                vertex_count: u(6),
                triangle_count: u(7),
                texture_size: [h(36), h(38)],
            },
            mips: msg[1] != 0,
            blocks: msg[2] != 0,
        };
        Ok((job, &msg[JOB_HEADER_BYTES..]))
    }
}

/// Runs a job's message (the worker's side): checks the CRC, decodes the patch and its
/// texture, makes the texture's mips with `mip_chain` when asked, and returns the reply.
/// `clock` is milliseconds (the worker's `performance.now()`).
pub fn run_job(
    msg: &[u8],
    mip_chain: impl Fn(&[u8], u32, u32) -> Vec<Vec<u8>>,
    clock: fn() -> f64,
) -> Vec<u8> {
    let t0 = clock();
    let result = Job::parse(msg).and_then(|(job, bytes)| {
        if crc32fast::hash(bytes) != job.crc32 {
            return Err(FormatError::PatchChecksum { node: job.node }.to_string());
        }
        let mut p = decode_patch(bytes, job.attributes, job.shape)
            .map_err(|e| e.with_node(job.node).to_string())?;
        if let Some(t) = p
            .texture
            .as_mut()
            .filter(|t| !t.blocks.is_empty() && !job.blocks)
        {
            t.decode_rgba()
                .map_err(|e| e.with_node(job.node).to_string())?;
            t.blocks = Vec::new();
        }
        if job.mips {
            if let Some(t) = p.texture.as_mut() {
                if t.mips.is_empty() && !t.rgba.is_empty() {
                    t.mips = mip_chain(&t.rgba, t.width, t.height);
                }
            }
        }
        Ok(p)
    });
    let ms = clock() - t0;
    match result {
        Ok(p) => write_patch(&p, ms),
        Err(e) => {
            let mut b = vec![WIRE_VERSION, REPLY_FAILED, 0, 0];
            b.extend(ms.to_le_bytes());
            b.extend(e.as_bytes());
            b
        }
    }
}

fn write_patch(p: &PatchData, ms: f64) -> Vec<u8> {
    let t = p.texture.as_ref();
    let texels = t.map_or(0, |t| {
        t.rgba.len()
            + t.encoded.len()
            + t.mips.iter().map(Vec::len).sum::<usize>()
            + t.blocks.iter().map(Vec::len).sum::<usize>()
    });
    let mut b = Vec::with_capacity(
        128 + p.positions.len() * 12
            + p.normals.len() * 12
            + p.colors.len() * 4
            + p.uvs.len() * 8
            + p.morph_targets.len() * 12
            + p.indices.len() * 4
            + p.charts.len() * 20
            + p.chart_ids.len() * 2
            + texels,
    );
    b.extend([WIRE_VERSION, REPLY_OK, u8::from(t.is_some()), 0]);
    b.extend(ms.to_le_bytes());
    let counts = [
        p.positions.len(),
        p.normals.len(),
        p.colors.len(),
        p.uvs.len(),
        p.morph_targets.len(),
        p.indices.len(),
        p.charts.len(),
        p.chart_ids.len(),
    ];
    for c in counts {
        b.extend((c as u32).to_le_bytes());
    }
    if let Some(t) = t {
        let codec = match t.codec {
            None => 0u32,
            Some(TextureCodec::Png) => 1,
            Some(c) => c as u32,
        };
        for v in [
            t.width,
            t.height,
            codec,
            t.encoded.len() as u32,
            t.rgba.len() as u32,
            t.mips.len() as u32,
            t.blocks.len() as u32,
        ] {
            b.extend(v.to_le_bytes());
        }
        for m in t.mips.iter().chain(&t.blocks) {
            b.extend((m.len() as u32).to_le_bytes());
        }
    }
    b.extend_from_slice(bytemuck::cast_slice(&p.positions));
    b.extend_from_slice(bytemuck::cast_slice(&p.normals));
    b.extend_from_slice(bytemuck::cast_slice(&p.colors));
    b.extend_from_slice(bytemuck::cast_slice(&p.uvs));
    b.extend_from_slice(bytemuck::cast_slice(&p.morph_targets));
    b.extend_from_slice(bytemuck::cast_slice(&p.indices));
    for c in &p.charts {
        b.extend(c.image.to_le_bytes());
        for v in c.scale.iter().chain(&c.offset) {
            b.extend(v.to_le_bytes());
        }
    }
    b.extend_from_slice(bytemuck::cast_slice(&p.chart_ids));
    if let Some(t) = t {
        b.extend_from_slice(&t.encoded);
        b.extend_from_slice(&t.rgba);
        for m in t.mips.iter().chain(&t.blocks) {
            b.extend_from_slice(m);
        }
    }
    b
}

/// The bytes of a reply, wherever they are: a slice, or (in the browser) the
/// `Uint8Array` the worker sent, copied straight into the decoded patch's arrays, so
/// each byte is copied once.
pub trait ReplyBytes {
    fn len(&self) -> usize;
    /// Copies `dst.len()` bytes from offset `at` (in range: checked by the caller).
    fn copy_into(&self, at: usize, dst: &mut [u8]);
}

impl ReplyBytes for [u8] {
    fn len(&self) -> usize {
        <[u8]>::len(self)
    }
    fn copy_into(&self, at: usize, dst: &mut [u8]) {
        dst.copy_from_slice(&self[at..at + dst.len()]);
    }
}

/// Reads a reply front to back.
struct Cursor<'a, R: ReplyBytes + ?Sized> {
    msg: &'a R,
    at: usize,
}

impl<R: ReplyBytes + ?Sized> Cursor<'_, R> {
    fn into_slice(&mut self, dst: &mut [u8]) -> Result<(), String> {
        let end = self
            .at
            .checked_add(dst.len())
            .filter(|&e| e <= self.msg.len());
        let end =
            end.ok_or_else(|| format!("decode reply of {} bytes is short", self.msg.len()))?;
        self.msg.copy_into(self.at, dst);
        self.at = end;
        Ok(())
    }
    fn bytes(&mut self, n: u32) -> Result<Vec<u8>, String> {
        self.array(n)
    }
    fn u32(&mut self) -> Result<u32, String> {
        let mut b = [0u8; 4];
        self.into_slice(&mut b)?;
        Ok(u32::from_le_bytes(b))
    }
    fn array<T: bytemuck::Pod>(&mut self, count: u32) -> Result<Vec<T>, String> {
        let n = (count as usize)
            .checked_mul(std::mem::size_of::<T>())
            .ok_or("decode reply: array too long")?;
        if self.at.saturating_add(n) > self.msg.len() {
            return Err(format!("decode reply of {} bytes is short", self.msg.len()));
        }
        let mut v = vec![T::zeroed(); count as usize];
        self.into_slice(bytemuck::cast_slice_mut(&mut v))?;
        Ok(v)
    }
}

/// A worker's reply to node `node`'s job: the scheduler's answer (the decoded patch,
/// or [`Answer::Failed`] with the decode error) and the worker's milliseconds. A reply
/// that cannot be read (never from a healthy worker) is `Err`.
pub fn read_reply<R: ReplyBytes + ?Sized>(node: u32, msg: &R) -> Result<(Answer, f64), String> {
    if msg.len() < 12 {
        return Err(format!("decode reply of {} bytes", msg.len()));
    }
    let mut head = [0u8; 12];
    msg.copy_into(0, &mut head);
    if head[0] != WIRE_VERSION {
        return Err(format!(
            "decode reply of layout {} (this build reads {WIRE_VERSION})",
            head[0]
        ));
    }
    let ms = f64::from_le_bytes(head[4..12].try_into().unwrap());
    let mut c = Cursor { msg, at: 12 };
    if head[1] == REPLY_FAILED {
        let text = c.bytes((msg.len() - 12) as u32)?;
        let error = String::from_utf8_lossy(&text).into_owned();
        return Ok((Answer::Failed { node, error }, ms));
    }
    let mut counts = [0u32; 8];
    for n in &mut counts {
        *n = c.u32()?;
    }
    let texture = if head[2] != 0 {
        let [width, height, codec, encoded, rgba, mips, blocks] = [0; 7].map(|_| c.u32());
        let (mips, blocks) = (mips?, blocks?);
        let mut mip_lens = Vec::with_capacity(mips.min(32) as usize);
        for _ in 0..mips {
            mip_lens.push(c.u32()?);
        }
        let mut block_lens = Vec::with_capacity(blocks.min(32) as usize);
        for _ in 0..blocks {
            block_lens.push(c.u32()?);
        }
        Some((
            width?, height?, codec?, encoded?, rgba?, mip_lens, block_lens,
        ))
    } else {
        None
    };
    let mut p = PatchData {
        positions: c.array(counts[0])?,
        normals: c.array(counts[1])?,
        colors: c.array(counts[2])?,
        uvs: c.array(counts[3])?,
        morph_targets: c.array(counts[4])?,
        indices: c.array(counts[5])?,
        ..PatchData::default()
    };
    for _ in 0..counts[6] {
        let image = c.u32()?;
        let f: Vec<f32> = c.array(4)?;
        p.charts.push(TextureChart {
            image,
            scale: [f[0], f[1]],
            offset: [f[2], f[3]],
        });
    }
    p.chart_ids = c.array(counts[7])?;
    if let Some((width, height, codec, encoded, rgba, mip_lens, block_lens)) = texture {
        let codec = match codec {
            0 => None,
            k => Some(
                u8::try_from(k)
                    .ok()
                    .and_then(TextureCodec::from_byte)
                    .ok_or_else(|| format!("decode reply: texture codec {k}"))?,
            ),
        };
        let mut t = PatchTexture {
            width,
            height,
            codec,
            encoded: c.bytes(encoded)?,
            rgba: c.bytes(rgba)?,
            ..Default::default()
        };
        for n in mip_lens {
            t.mips.push(c.bytes(n)?);
        }
        for n in block_lens {
            t.blocks.push(c.bytes(n)?);
        }
        p.texture = Some(t);
    }
    if c.at != msg.len() {
        return Err(format!(
            "decode reply: {} bytes left over",
            msg.len() - c.at
        ));
    }
    Ok((
        Answer::Loaded {
            node,
            patch: Arc::new(p),
        },
        ms,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn clock() -> f64 {
        0.0
    }

    fn chain(rgba: &[u8], w: u32, h: u32) -> Vec<Vec<u8>> {
        // A stand-in chain with the right sizes (the real one is tessera-render's).
        let mut out = Vec::new();
        let (mut w, mut h) = (w, h);
        while w > 1 || h > 1 {
            (w, h) = ((w / 2).max(1), (h / 2).max(1));
            out.push(vec![rgba[0]; 4 * (w * h) as usize]);
        }
        out
    }

    /// The job of a one-triangle patch (3 vertices, grid origin 0), no mips or blocks.
    fn triangle_job(node: u32, attributes: u32, crc32: u32, texture_size: [u16; 2]) -> Job {
        Job {
            node,
            attributes,
            crc32,
            shape: PatchShape {
                quant_min: [0; 3],
                vertex_count: 3,
                triangle_count: 1,
                texture_size,
            },
            mips: false,
            blocks: false,
        }
    }

    #[test]
    fn job_round_trip() {
        let job = Job {
            node: 7,
            attributes: 0b1011,
            crc32: 0xDEADBEEF,
            shape: PatchShape {
                quant_min: [1, 2, 3],
                vertex_count: 40,
                triangle_count: 50,
                texture_size: [640, 48],
            },
            mips: true,
            blocks: true,
        };
        let msg = job.to_bytes(&[9, 8, 7]);
        let (back, bytes) = Job::parse(&msg).unwrap();
        assert_eq!(back, job);
        assert_eq!(bytes, &[9, 8, 7]);
        assert!(Job::parse(&msg[..10]).is_err());
        let mut other = msg.clone();
        other[0] = WIRE_VERSION + 1;
        assert!(Job::parse(&other).unwrap_err().contains("two builds"));
    }

    #[test]
    fn reply_of_a_failed_decode_is_the_error() {
        let job = triangle_job(3, 0, 0, [0, 0]);
        let reply = run_job(&job.to_bytes(b"not a patch"), chain, clock);
        match read_reply(3, &reply[..]).unwrap().0 {
            Answer::Failed { node, error } => {
                assert_eq!(node, 3);
                assert!(error.contains("checksum"), "{error}");
            }
            a => panic!("{a:?}"),
        }
        assert!(read_reply(3, &reply[..5]).is_err());
        assert!(read_reply(3, &reply[..]).is_ok());
    }

    #[test]
    fn reply_carries_every_array_and_the_mips() {
        let p = PatchData {
            positions: vec![[1, 2, 3], [4, 5, 6], [7, 8, 9]],
            normals: vec![[0.0, 0.0, 1.0]; 3],
            colors: vec![[1, 2, 3, 4]; 3],
            uvs: vec![[0.25, 0.5]; 3],
            morph_targets: vec![[1, 2, 3]; 3],
            indices: vec![0, 1, 2],
            charts: vec![TextureChart {
                image: 2,
                scale: [0.5, 2.0],
                offset: [0.125, -1.0],
            }],
            chart_ids: vec![0; 3],
            chart_planes: vec![],
            texture: Some(PatchTexture {
                width: 4,
                height: 2,
                codec: Some(TextureCodec::Png),
                encoded: Vec::new(),
                rgba: (0..32).collect(),
                mips: chain(&[5], 4, 2),
                blocks: vec![vec![1; 16], vec![2; 16], vec![3; 16]],
            }),
        };
        let msg = write_patch(&p, 2.5);
        let (a, ms) = read_reply(11, &msg[..]).unwrap();
        assert_eq!(ms, 2.5);
        match a {
            Answer::Loaded { node, patch } => {
                assert_eq!(node, 11);
                assert_eq!(*patch, p);
            }
            a => panic!("{a:?}"),
        }
        // Cut anywhere: an error, never a panic.
        for cut in [12, 20, 50, msg.len() - 1] {
            assert!(read_reply(11, &msg[..cut]).is_err(), "cut at {cut}");
        }
    }

    /// A BC7 texture comes back as its blocks where the page uploads blocks, and
    /// decoded to RGBA8 with its stored mips (by the worker, off the main thread) where
    /// it does not: a device without BC, or one whose texture limit starts the texture
    /// at a level that is not whole blocks (8x8 with a limit of 2: a 2x2 level).
    #[test]
    fn bc7_textures_come_back_as_blocks_or_decoded_as_the_page_uploads_them() {
        use tessera_format::{encode_patch, ATTR_TEXTURE, ATTR_UVS};
        let levels: Vec<Vec<u8>> = (0..4)
            .map(|l| {
                let (w, h) = texels::level_size(8, 8, l);
                (0..texels::bc7_level_bytes(w, h))
                    .map(|i| (i * 29 + l as usize) as u8 | 0x40)
                    .collect()
            })
            .collect();
        let p = PatchData {
            positions: vec![[0, 0, 0], [9, 0, 0], [0, 9, 0]],
            uvs: vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]],
            indices: vec![0, 1, 2],
            charts: vec![TextureChart {
                image: 0,
                scale: [1.0, 1.0],
                offset: [0.0, 0.0],
            }],
            chart_ids: vec![0; 3],
            texture: Some(PatchTexture::from_bc7(8, 8, levels.clone()).unwrap()),
            ..PatchData::default()
        };
        let attributes = ATTR_UVS | ATTR_TEXTURE;
        let bytes = encode_patch(&p, attributes, [0; 3]);
        let job = |blocks: Option<u32>| {
            let mut j = triangle_job(1, attributes, crc32fast::hash(&bytes), [8, 8]);
            j.mips = true;
            j.blocks = blocks.is_some_and(|max| texels::bc7_uploads_as_blocks(8, 8, max));
            j
        };
        let texture = |j: Job| match read_reply(1, &run_job(&j.to_bytes(&bytes), chain, clock)[..])
            .unwrap()
            .0
        {
            Answer::Loaded { patch, .. } => patch.texture.clone().unwrap(),
            a => panic!("{a:?}"),
        };
        let as_blocks = texture(job(Some(4096)));
        assert_eq!(as_blocks.blocks, levels);
        assert!(as_blocks.rgba.is_empty());
        for j in [job(None), job(Some(2))] {
            assert!(!j.blocks);
            let t = texture(j);
            assert!(t.blocks.is_empty());
            assert_eq!(t.rgba, texels::bc7_to_rgba(&levels[0], 8, 8));
            assert_eq!(t.mips.len(), 3);
            assert_eq!(t.mips[0], texels::bc7_to_rgba(&levels[1], 4, 4));
        }
    }
}
