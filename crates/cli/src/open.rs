//! Opening the MODEL argument of `info`, `render` and `extract`: a local path (memory-mapped) or an
//! `http://` URL (range requests through `tessera-http`).

use std::path::Path;
use std::sync::Arc;

use tessera_format::{FormatError, Model, PatchReader};
use tessera_http::{is_url, RemoteModel};

/// The model at `arg`, local or remote, its whole index read (callers add the context
/// of their message).
pub fn open_model(arg: &Path) -> Result<Arc<dyn PatchReader>, FormatError> {
    open_model_paged(arg, false)
}

/// The model at `arg`; with `paged`, a remote model reads only the top of its index
/// first and the rest as the view needs it (what progressive rendering wants). A local
/// model's index is always read whole: it is memory-mapped, reading it costs no
/// transfer.
pub fn open_model_paged(arg: &Path, paged: bool) -> Result<Arc<dyn PatchReader>, FormatError> {
    let s = arg.to_string_lossy();
    Ok(match (is_url(&s), paged) {
        (true, true) => Arc::new(RemoteModel::open_paged(&s)?),
        (true, false) => Arc::new(RemoteModel::open(&s)?),
        (false, _) => Arc::new(Model::open(arg)?),
    })
}

/// What `view` and `render` open: one model, or a scene file's models with their
/// placements.
pub struct OpenedScene {
    /// Each model and where it stands; the copies of one file share its reader (one
    /// index in memory, one mapping or connection).
    pub models: Vec<(Arc<dyn PatchReader>, tessera_select::Placement)>,
    /// The models' names (a lone model: its path).
    pub names: Vec<String>,
    /// The scene file's up axis, if it gives one.
    pub up: Option<tessera_nav::UpAxis>,
}

impl OpenedScene {
    /// The scene's framing points: each distinct model's root vertices (at most
    /// `max_points` in all), placed wherever it stands.
    pub fn points(&self, max_points: usize) -> tessera_nav::ScenePoints {
        let per = (max_points / self.models.len().max(1)).max(16);
        tessera_nav::ScenePoints::union(&tessera_nav::placed_scene_points(&self.models, per))
    }
}

/// Opens `arg`: a scene file (`.json`, see docs/scene.md) with its models, or one model
/// (local or remote, as [`open_model_paged`]). A scene's relative model paths are
/// relative to its folder; a model that cannot be opened is named in the error.
pub fn open_scene(arg: &Path, paged: bool) -> anyhow::Result<OpenedScene> {
    use anyhow::Context;
    let s = arg.to_string_lossy();
    if is_url(&s) || !tessera_scene::is_scene_path(arg) {
        let model = open_model_paged(arg, paged)
            .with_context(|| format!("cannot open {}", arg.display()))?;
        return Ok(OpenedScene {
            models: vec![(model, tessera_select::Placement::IDENTITY)],
            names: vec![arg.display().to_string()],
            up: None,
        });
    }
    let text = std::fs::read_to_string(arg)
        .with_context(|| format!("cannot read the scene file {}", arg.display()))?;
    let scene = tessera_scene::Scene::from_json_str(&text)
        .with_context(|| format!("{} is not a valid scene file", arg.display()))?;
    let base = arg.parent().unwrap_or(Path::new("."));
    let mut opened: Vec<(tessera_scene::ModelLocation, Arc<dyn PatchReader>)> = Vec::new();
    let mut models = Vec::with_capacity(scene.models.len());
    for (m, at) in scene.models.iter().zip(scene.resolve(base)) {
        let reader = match opened.iter().find(|(l, _)| *l == at) {
            Some((_, r)) => r.clone(),
            None => {
                let path = match &at {
                    tessera_scene::ModelLocation::Path(p) => p.clone(),
                    tessera_scene::ModelLocation::Url(u) => u.into(),
                };
                let r = open_model_paged(&path, paged).with_context(|| {
                    format!(
                        "{}: model \"{}\": cannot open {}",
                        arg.display(),
                        m.name,
                        path.display()
                    )
                })?;
                opened.push((at, r.clone()));
                r
            }
        };
        models.push((reader, m.placement));
    }
    Ok(OpenedScene {
        models,
        names: scene.models.iter().map(|m| m.name.clone()).collect(),
        up: scene.up,
    })
}
