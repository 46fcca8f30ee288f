//! A Tessera model exported as OGC 3D Tiles 1.1 (`tessera export-tiles`): a
//! `tileset.json` and one binary glTF per tile, for CesiumJS, 3DTilesRendererJS and any
//! other 3D Tiles client.
//!
//! The mapping ([`plan`], `docs/tiles.md`): one tile per node of the diamond hierarchy
//! (one root tile for all the roots), `refine: "REPLACE"`, each tile's `geometricError`
//! its node's saturated error and its bounding sphere its node's saturated sphere. A
//! client's screen-space-error refinement is then Tessera's own refinement test, and
//! mates of a diamond decide alike, so every cut a client draws is a crack-free
//! Tessera cut.
//!
//! Content ([`export_tiles`]): each tile's patch through `tessera-extract`'s glTF
//! writer: positions relative to the tile's centre (f32 stays precise), normals,
//! colours, a textured model's patch textures (stored PNG or JPEG as they are, BC7
//! decoded and written as PNG), axes turned to glTF's +Y up (the clients turn glTF
//! content to 3D Tiles' +Z up). Tileset coordinates are model coordinates minus the
//! model's bounding-sphere centre; `root.transform` puts that back, composed with the
//! optional placement on the Earth ([`frame`]).
//!
//! Written atomically: everything goes into a temporary directory beside the output,
//! synced (one `syncfs` on Linux), then renamed into place; an existing output is replaced only when
//! asked ([`TilesOptions::force`]) and only if it is a tileset. Memory is bounded: a
//! tile is decoded, encoded and written by one worker of a bounded pool at a time, and
//! `tileset.json` is streamed tile by tile.

pub mod frame;
pub mod plan;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use rayon::prelude::*;
use tessera_extract::{encode_gltf, GltfContainer, GltfContent, GltfFrame};
use tessera_format::{decode_patch_with, FormatError, Model, PatchData, ATTR_TEXTURE};
use tessera_mesh::Progress;
use tessera_select::{merge_patches, PatchRef};

pub use plan::{PlanError, Tile, TileTree};

/// How to export.
#[derive(Clone, Debug, Default)]
pub struct TilesOptions {
    /// Where the model goes on the Earth: a column-major 4x4 from model coordinates to
    /// ECEF (e.g. [`frame::enu_at_geodetic`]); `None`: model coordinates are the
    /// tileset's world.
    pub placement: Option<[f64; 16]>,
    /// Worker threads (None: rayon's default, one per core).
    pub threads: Option<usize>,
    /// Replace an output directory that exists and holds a tileset (never anything
    /// else).
    pub force: bool,
}

/// What was written.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TilesSummary {
    /// Tiles in the tree (with or without content).
    pub tiles: usize,
    /// Files written: the `.glb`s and `tileset.json`.
    pub files: usize,
    /// Bytes of all files.
    pub bytes: u64,
    /// Bytes of `tileset.json` among them.
    pub tileset_bytes: u64,
    /// Patch textures written as glTF images.
    pub textures: usize,
    /// Triangles over all tiles (every level of the hierarchy).
    pub triangles: u64,
    /// The model's input triangles (for bytes per input triangle).
    pub input_triangles: u64,
    /// The model file's size.
    pub model_bytes: u64,
    /// Levels of the hierarchy (the tree's depth).
    pub levels: u32,
    /// Seconds the export took.
    pub seconds: f64,
}

/// Why an export failed; nothing is left at the output when it does.
#[derive(Debug, thiserror::Error)]
pub enum TilesError {
    #[error("{}: not a readable Tessera model: {cause}", path.display())]
    Model { path: PathBuf, cause: FormatError },
    #[error("{}: {cause}", path.display())]
    Plan { path: PathBuf, cause: PlanError },
    #[error("{}: {cause}", path.display())]
    Patch { path: PathBuf, cause: FormatError },
    #[error("{} exists and is not a directory: remove it or choose another output", path.display())]
    NotADirectory { path: PathBuf },
    #[error("{} is not empty and holds no tileset.json: refusing to replace it (choose an empty or new directory)", path.display())]
    NotATileset { path: PathBuf },
    #[error("{} already holds a tileset: pass --force to replace it", path.display())]
    Exists { path: PathBuf },
    #[error("cannot write {}: {} is not an existing directory", out.display(), parent.display())]
    NoParent { out: PathBuf, parent: PathBuf },
    #[error("cannot write {}: {cause}", path.display())]
    Io {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("interrupted: nothing written")]
    Interrupted,
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> TilesError + '_ {
    move |cause| TilesError::Io {
        path: path.to_owned(),
        cause,
    }
}

/// Exports `model` as a 3D Tiles 1.1 tileset in the directory `out_dir` (created; see
/// the crate documentation for what it holds and [`TilesOptions`]).
pub fn export_tiles(
    model: &Path,
    out_dir: &Path,
    opts: &TilesOptions,
    progress: &dyn Progress,
) -> Result<TilesSummary, TilesError> {
    let start = Instant::now();
    let replace = check_output(out_dir, opts.force)?;
    let m = Model::open(model).map_err(|cause| TilesError::Model {
        path: model.to_owned(),
        cause,
    })?;
    let h = *m.index().header();
    let tree = TileTree::plan(&h, m.nodes()).map_err(|cause| TilesError::Plan {
        path: model.to_owned(),
        cause,
    })?;
    let tmp = Staging::create(out_dir)?;
    std::fs::create_dir(tmp.path.join("tiles")).map_err(io(&tmp.path))?;

    // Tileset coordinates: model coordinates minus the bounding sphere's centre.
    let origin = [
        h.bounding_sphere[0],
        h.bounding_sphere[1],
        h.bounding_sphere[2],
    ];
    let to_world = frame::mul(
        &opts.placement.unwrap_or(frame::IDENTITY),
        &frame::translation(origin),
    );

    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.threads.unwrap_or(0))
        .thread_name(|i| format!("tessera-tiles-{i}"))
        .build()
        .map_err(|e| io(out_dir)(std::io::Error::other(e)))?;
    progress.stage("tiles", tree.tiles.len() as u64);
    let stop = AtomicBool::new(false);
    let written: Vec<(u64, usize)> = pool.install(|| {
        (0..tree.tiles.len())
            .into_par_iter()
            .map(|t| {
                if stop.load(Ordering::Relaxed) || progress.cancelled() {
                    stop.store(true, Ordering::Relaxed);
                    return Err(TilesError::Interrupted);
                }
                let r = write_tile(&m, model, &tree, t, origin, &tmp.path);
                progress.advance(1);
                if r.is_err() {
                    stop.store(true, Ordering::Relaxed);
                }
                r
            })
            .collect::<Result<_, _>>()
    })?;
    progress.finish_stage();

    let tileset = tmp.path.join("tileset.json");
    let file = std::fs::File::create(&tileset).map_err(io(&tileset))?;
    let mut w = std::io::BufWriter::with_capacity(1 << 20, file);
    tree.write_tileset_json(
        &mut w,
        origin,
        to_world,
        &format!("tessera export-tiles {}", env!("CARGO_PKG_VERSION")),
    )
    .and_then(|()| w.flush())
    .map_err(io(&tileset))?;
    drop(w);
    let json_bytes = std::fs::metadata(&tileset).map_err(io(&tileset))?.len();
    sync_tree(&tmp.path)?;
    tmp.commit(out_dir, replace)?;

    let files = written.iter().filter(|w| w.0 > 0).count() + 1;
    tracing::info!(
        tiles = tree.tiles.len(),
        files,
        seconds = start.elapsed().as_secs_f64(),
        "tileset written to {}",
        out_dir.display()
    );
    Ok(TilesSummary {
        tiles: tree.tiles.len(),
        files,
        bytes: written.iter().map(|w| w.0).sum::<u64>() + json_bytes,
        tileset_bytes: json_bytes,
        textures: written.iter().map(|w| w.1).sum(),
        triangles: tree.tiles.iter().map(|t| t.triangles).sum(),
        input_triangles: h.input_triangles,
        model_bytes: h.file_bytes,
        levels: h.level_count,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Decodes, encodes and writes tile `t`'s content (if it has any) into `dir`; its
/// bytes and textures.
fn write_tile(
    m: &Model,
    model: &Path,
    tree: &TileTree,
    t: usize,
    origin: [f64; 3],
    dir: &Path,
) -> Result<(u64, usize), TilesError> {
    let Some(uri) = tree.content_uri(t) else {
        return Ok((0, 0));
    };
    let tile = &tree.tiles[t];
    let h = m.index().header();
    let bad = |cause: FormatError| TilesError::Patch {
        path: model.to_owned(),
        cause,
    };
    let patches: Vec<PatchData> = tile
        .nodes
        .iter()
        .map(|&n| {
            let bytes = m.patch_bytes(n as usize)?;
            // Texels stay encoded: a stored PNG or JPEG goes into the glTF as it is.
            decode_patch_with(
                bytes,
                h.attributes,
                m.index().node(n as usize)?.into(),
                false,
            )
            .map_err(|e| e.with_node(n))
        })
        .collect::<Result<_, _>>()
        .map_err(bad)?;
    let centre = [tile.sphere[0], tile.sphere[1], tile.sphere[2]];
    let gframe = GltfFrame::tile(centre, origin);
    let name = if t == 0 {
        "roots".to_string()
    } else {
        format!("node {}", tile.nodes[0])
    };
    let grid = m.index().grid();
    let (bytes, summary) = if h.attributes & ATTR_TEXTURE != 0 {
        let list: Vec<(u32, &PatchData)> = tile.nodes.iter().copied().zip(&patches).collect();
        encode_gltf(
            &grid,
            GltfContent::Textured(&list),
            &gframe,
            GltfContainer::Binary,
            &name,
        )
    } else {
        let mesh = merge_patches(patches.iter().map(PatchRef::from));
        encode_gltf(
            &grid,
            GltfContent::Welded(&mesh),
            &gframe,
            GltfContainer::Binary,
            &name,
        )
    }
    .map_err(bad)?;
    write_file(&dir.join(uri), &bytes)?;
    Ok((bytes.len() as u64, summary.textures))
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<(), TilesError> {
    let mut f = std::fs::File::create(path).map_err(io(path))?;
    f.write_all(bytes).map_err(io(path))
}

/// Makes everything written under `dir` durable before it is renamed into place. On
/// Linux one `syncfs` of its file system: a file each would cost one `fsync` per tile
/// (measured on the 30M-triangle sphere: 56,000 of them took most of a minute of the
/// export). Elsewhere every file and directory is synced in turn.
fn sync_tree(dir: &Path) -> Result<(), TilesError> {
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        let d = std::fs::File::open(dir).map_err(io(dir))?;
        // SAFETY: syncfs takes an open descriptor (d lives across the call).
        if unsafe { libc::syncfs(d.as_raw_fd()) } != 0 {
            return Err(io(dir)(std::io::Error::last_os_error()));
        }
        Ok(())
    }
    #[cfg(not(target_os = "linux"))]
    {
        for e in std::fs::read_dir(dir).map_err(io(dir))? {
            let p = e.map_err(io(dir))?.path();
            if p.is_dir() {
                sync_tree(&p)?;
            } else {
                std::fs::File::open(&p)
                    .and_then(|f| f.sync_all())
                    .map_err(io(&p))?;
            }
        }
        std::fs::File::open(dir)
            .and_then(|f| f.sync_all())
            .map_err(io(dir))
    }
}

/// Whether an existing output will be replaced; errors for outputs that must not be.
fn check_output(out: &Path, force: bool) -> Result<bool, TilesError> {
    let parent = parent_of(out);
    if !parent.is_dir() {
        return Err(TilesError::NoParent {
            out: out.to_owned(),
            parent,
        });
    }
    match std::fs::symlink_metadata(out) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(false),
        Err(e) => Err(io(out)(e)),
        Ok(md) if !md.is_dir() => Err(TilesError::NotADirectory {
            path: out.to_owned(),
        }),
        Ok(_) => {
            let empty = std::fs::read_dir(out).map_err(io(out))?.next().is_none();
            if empty {
                Ok(true)
            } else if !out.join("tileset.json").is_file() {
                Err(TilesError::NotATileset {
                    path: out.to_owned(),
                })
            } else if force {
                Ok(true)
            } else {
                Err(TilesError::Exists {
                    path: out.to_owned(),
                })
            }
        }
    }
}

fn parent_of(p: &Path) -> PathBuf {
    match p.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_owned(),
        _ => PathBuf::from("."),
    }
}

/// The temporary directory beside the output; removed on drop unless committed.
struct Staging {
    path: PathBuf,
    /// Where a replaced output waits until the new one is in place.
    aside: PathBuf,
    committed: bool,
}

impl Staging {
    fn create(out: &Path) -> Result<Staging, TilesError> {
        let name = out
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "tiles".into());
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.subsec_nanos())
            .unwrap_or(0);
        let tag = format!("{}-{nanos}", std::process::id());
        let path = parent_of(out).join(format!(".{name}.tmp-{tag}"));
        let aside = parent_of(out).join(format!(".{name}.old.tmp-{tag}"));
        std::fs::create_dir(&path).map_err(io(out))?;
        Ok(Staging {
            path,
            aside,
            committed: false,
        })
    }

    /// Renames the finished directory onto `out` (the old one, when `replace`, moved
    /// aside first and removed after), then syncs the parent directory.
    fn commit(mut self, out: &Path, replace: bool) -> Result<(), TilesError> {
        let parent = parent_of(out);
        let aside = self.aside.clone();
        if replace {
            std::fs::rename(out, &aside).map_err(io(out))?;
        }
        if let Err(e) = std::fs::rename(&self.path, out) {
            if replace {
                let _ = std::fs::rename(&aside, out);
            }
            return Err(io(out)(e));
        }
        self.committed = true;
        if replace {
            std::fs::remove_dir_all(&aside).map_err(io(&aside))?;
        }
        if let Ok(d) = std::fs::File::open(&parent) {
            let _ = d.sync_all();
        }
        Ok(())
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.path);
        }
    }
}
