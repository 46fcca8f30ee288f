//! Scene files: several models, each placed in one world by a similarity, that
//! `tessera view`, `tessera render` and the browser page open as one scene (the models
//! share one GPU cache, one RAM budget and one depth buffer, and the budgets are split
//! between them by demand every frame: `tessera_stream::Driver`). The format is in
//! `docs/scene.md`:
//!
//! ```json
//! { "tessera_scene": 1, "up": "+z",
//!   "models": [
//!     { "name": "bunny", "model": "bunny.tsr",
//!       "translate": [0, 0, 0], "rotate": { "axis": [0, 0, 1], "degrees": 30 }, "scale": 1 },
//!     { "name": "far", "model": "http://host:8080/models/far.tsr", "matrix": [16 numbers] } ] }
//! ```
//!
//! Reading checks everything a model's placement and name need (a field path in every
//! message: `models[3].scale: ...`); whether a model's file exists is the opener's
//! check ([`Scene::resolve`] says where each one is). [`copies`] writes the deterministic
//! scenes of placed copies of real scans that the tests and benchmarks walk through.
//! No I/O here: the crate builds for wasm32 like the browser client that reads it.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use glam::{DQuat, DVec3};
use serde_json::{json, Map, Value};
use tessera_nav::UpAxis;
use tessera_select::Placement;

mod copies;
pub use copies::{copies, CopiesOptions};

/// The format's version (`"tessera_scene"`).
pub const SCENE_VERSION: u64 = 1;

/// Most models a scene may place (each costs a scheduler and a loader thread natively).
pub const MAX_MODELS: usize = 100_000;

/// One model of a scene.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneModel {
    /// Unique within the scene.
    pub name: String,
    /// A path (relative to the scene file's folder unless absolute) or an `http(s)://`
    /// URL (relative ones resolved against the scene's own URL in the browser).
    pub model: String,
    pub placement: Placement,
}

/// A scene file's contents.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    /// The scene's up axis, when the file gives one (else the front end guesses it from
    /// the models, as for one model).
    pub up: Option<UpAxis>,
    pub models: Vec<SceneModel>,
}

/// What is wrong with a scene file.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("not a scene file (JSON): {0}")]
    Json(String),
    #[error("{field}: {message}")]
    Invalid { field: String, message: String },
}

fn invalid(field: impl Into<String>, message: impl Into<String>) -> SceneError {
    SceneError::Invalid {
        field: field.into(),
        message: message.into(),
    }
}

/// Where a scene's model is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ModelLocation {
    Path(PathBuf),
    Url(String),
}

fn is_url(s: &str) -> bool {
    s.starts_with("http://") || s.starts_with("https://")
}

/// Whether `path` names a scene file rather than a model (by its `.json` ending).
pub fn is_scene_path(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
}

impl Scene {
    /// Reads a scene from its JSON text.
    pub fn from_json_str(text: &str) -> Result<Scene, SceneError> {
        let value: Value =
            serde_json::from_str(text).map_err(|e| SceneError::Json(e.to_string()))?;
        Self::from_json_value(&value)
    }

    /// Reads a scene from parsed JSON.
    pub fn from_json_value(value: &Value) -> Result<Scene, SceneError> {
        let obj = value
            .as_object()
            .ok_or_else(|| invalid("(top level)", "a scene file is a JSON object"))?;
        only_keys(obj, "(top level)", &["tessera_scene", "up", "models"])?;
        match obj.get("tessera_scene") {
            Some(v) if v.as_u64() == Some(SCENE_VERSION) => {}
            Some(v) => {
                return Err(invalid(
                    "tessera_scene",
                    format!(
                        "version {v} is not known to this build (it reads version {SCENE_VERSION})"
                    ),
                ))
            }
            None => {
                return Err(invalid(
                    "tessera_scene",
                    format!("missing: a scene file starts with \"tessera_scene\": {SCENE_VERSION}"),
                ))
            }
        }
        let up = match obj.get("up") {
            None | Some(Value::Null) => None,
            Some(Value::String(s)) => Some(
                s.parse::<UpAxis>()
                    .map_err(|e| invalid("up", e.to_string()))?,
            ),
            Some(_) => return Err(invalid("up", "an axis: \"+x\", \"-x\", ..., \"-z\"")),
        };
        let list = obj
            .get("models")
            .and_then(Value::as_array)
            .ok_or_else(|| invalid("models", "missing: a list of models"))?;
        if list.is_empty() {
            return Err(invalid("models", "a scene needs at least one model"));
        }
        if list.len() > MAX_MODELS {
            return Err(invalid(
                "models",
                format!("{} models; at most {MAX_MODELS}", list.len()),
            ));
        }
        let mut names = HashSet::new();
        let mut models = Vec::with_capacity(list.len());
        for (i, entry) in list.iter().enumerate() {
            let field = format!("models[{i}]");
            let m = model_of(entry, &field)?;
            if !names.insert(m.name.clone()) {
                return Err(invalid(
                    format!("{field}.name"),
                    format!("\"{}\" names two models; names must be unique", m.name),
                ));
            }
            models.push(m);
        }
        Ok(Scene { up, models })
    }

    /// The scene as JSON text (what [`Scene::from_json_str`] reads back).
    pub fn to_json_string(&self) -> String {
        let models: Vec<Value> = self
            .models
            .iter()
            .map(|m| {
                let p = &m.placement;
                let mut o = Map::new();
                o.insert("name".into(), json!(m.name));
                o.insert("model".into(), json!(m.model));
                o.insert("translate".into(), json!(p.translation.to_array()));
                o.insert("rotate".into(), json!(p.rotation.to_array()));
                o.insert("scale".into(), json!(p.scale));
                Value::Object(o)
            })
            .collect();
        let mut top = Map::new();
        top.insert("tessera_scene".into(), json!(SCENE_VERSION));
        if let Some(up) = self.up {
            top.insert("up".into(), json!(up.to_string()));
        }
        top.insert("models".into(), Value::Array(models));
        let mut s = serde_json::to_string_pretty(&Value::Object(top)).expect("JSON of a scene");
        s.push('\n');
        s
    }

    /// Where each model is, for a scene file in folder `base` (relative paths are
    /// relative to it; URLs stay as they are).
    pub fn resolve(&self, base: &Path) -> Vec<ModelLocation> {
        self.models
            .iter()
            .map(|m| {
                if is_url(&m.model) {
                    ModelLocation::Url(m.model.clone())
                } else {
                    let p = Path::new(&m.model);
                    ModelLocation::Path(if p.is_absolute() {
                        p.to_path_buf()
                    } else {
                        base.join(p)
                    })
                }
            })
            .collect()
    }
}

fn only_keys(obj: &Map<String, Value>, field: &str, known: &[&str]) -> Result<(), SceneError> {
    for k in obj.keys() {
        if !known.contains(&k.as_str()) {
            return Err(invalid(
                field,
                format!("unknown key \"{k}\" (known: {})", known.join(", ")),
            ));
        }
    }
    Ok(())
}

fn numbers<const N: usize>(v: &Value, field: &str) -> Result<[f64; N], SceneError> {
    let a = v
        .as_array()
        .filter(|a| a.len() == N)
        .ok_or_else(|| invalid(field, format!("a list of {N} numbers")))?;
    let mut out = [0.0; N];
    for (k, x) in a.iter().enumerate() {
        out[k] = x
            .as_f64()
            .filter(|x| x.is_finite())
            .ok_or_else(|| invalid(format!("{field}[{k}]"), "a finite number"))?;
    }
    Ok(out)
}

fn model_of(entry: &Value, field: &str) -> Result<SceneModel, SceneError> {
    let obj = entry
        .as_object()
        .ok_or_else(|| invalid(field, "a model is a JSON object"))?;
    only_keys(
        obj,
        field,
        &["name", "model", "translate", "rotate", "scale", "matrix"],
    )?;
    let text = |key: &str| -> Result<String, SceneError> {
        match obj.get(key) {
            Some(Value::String(s)) if !s.trim().is_empty() => Ok(s.clone()),
            _ => Err(invalid(
                format!("{field}.{key}"),
                "missing: a non-empty string",
            )),
        }
    };
    let name = text("name")?;
    let model = text("model")?;
    let placement = if let Some(m) = obj.get("matrix") {
        if ["translate", "rotate", "scale"]
            .iter()
            .any(|k| obj.contains_key(*k))
        {
            return Err(invalid(
                field,
                "give either \"matrix\" or \"translate\"/\"rotate\"/\"scale\", not both",
            ));
        }
        let m: [f64; 16] = numbers(m, &format!("{field}.matrix"))?;
        Placement::from_matrix(&m).map_err(|e| invalid(format!("{field}.matrix"), e))?
    } else {
        let translation = match obj.get("translate") {
            None => DVec3::ZERO,
            Some(v) => DVec3::from(numbers::<3>(v, &format!("{field}.translate"))?),
        };
        let rotation = match obj.get("rotate") {
            None => DQuat::IDENTITY,
            Some(v) => rotation_of(v, &format!("{field}.rotate"))?,
        };
        let scale = match obj.get("scale") {
            None => 1.0,
            Some(v) => v
                .as_f64()
                .filter(|s| s.is_finite() && *s > 0.0)
                .ok_or_else(|| invalid(format!("{field}.scale"), "a positive number"))?,
        };
        Placement::new(translation, rotation, scale).map_err(|e| invalid(field, e))?
    };
    Ok(SceneModel {
        name,
        model,
        placement,
    })
}

/// `[x, y, z, w]` (a quaternion, normalised) or `{ "axis": [x, y, z], "degrees": d }`.
fn rotation_of(v: &Value, field: &str) -> Result<DQuat, SceneError> {
    if v.is_array() {
        let q: [f64; 4] = numbers(v, field)?;
        let q = DQuat::from_array(q);
        if q.length() < 1e-12 {
            return Err(invalid(field, "the quaternion is zero"));
        }
        return Ok(q.normalize());
    }
    let obj = v.as_object().ok_or_else(|| {
        invalid(
            field,
            "a quaternion [x, y, z, w] or { \"axis\": [x, y, z], \"degrees\": d }",
        )
    })?;
    only_keys(obj, field, &["axis", "degrees"])?;
    let axis = DVec3::from(numbers::<3>(
        obj.get("axis").unwrap_or(&Value::Null),
        &format!("{field}.axis"),
    )?);
    if axis.length() < 1e-12 {
        return Err(invalid(format!("{field}.axis"), "the axis is zero"));
    }
    let degrees = obj
        .get("degrees")
        .and_then(Value::as_f64)
        .filter(|d| d.is_finite())
        .ok_or_else(|| invalid(format!("{field}.degrees"), "a finite number"))?;
    Ok(DQuat::from_axis_angle(
        axis.normalize(),
        degrees.to_radians(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(text: &str) -> String {
        Scene::from_json_str(text).unwrap_err().to_string()
    }

    #[test]
    fn reads_every_way_of_placing_a_model() {
        let s = Scene::from_json_str(
            r#"{ "tessera_scene": 1, "up": "+z", "models": [
                { "name": "a", "model": "a.tsr" },
                { "name": "b", "model": "sub/b.tsr", "translate": [1, 2, 3],
                  "rotate": { "axis": [0, 0, 2], "degrees": 90 }, "scale": 2 },
                { "name": "c", "model": "http://h:1/c.tsr", "rotate": [0, 0, 0, 3] },
                { "name": "d", "model": "/abs/d.tsr",
                  "matrix": [0, 2, 0, 0,  -2, 0, 0, 0,  0, 0, 2, 0,  1, 2, 3, 1] } ] }"#,
        )
        .unwrap();
        assert_eq!(s.up, Some(UpAxis::PosZ));
        assert!(s.models[0].placement.is_identity());
        let b = s.models[1].placement;
        // 90 degrees about +z, scale 2, then the translation: x -> 2y + t.
        let x = b.to_world(DVec3::X);
        assert!((x - DVec3::new(1.0, 4.0, 3.0)).length() < 1e-12, "{x}");
        let d = s.models[3].placement;
        assert!((d.to_world(DVec3::X) - x).length() < 1e-12);
        assert!(s.models[2].placement.is_identity());
        let at = s.resolve(Path::new("/scenes"));
        assert_eq!(at[1], ModelLocation::Path("/scenes/sub/b.tsr".into()));
        assert_eq!(at[2], ModelLocation::Url("http://h:1/c.tsr".into()));
        assert_eq!(at[3], ModelLocation::Path("/abs/d.tsr".into()));
        // Written and read back: the same scene.
        let again = Scene::from_json_str(&s.to_json_string()).unwrap();
        assert_eq!(again.models.len(), 4);
        for (a, b) in s.models.iter().zip(&again.models) {
            assert_eq!(a.name, b.name);
            let p = DVec3::new(0.3, -2.0, 5.0);
            assert!((a.placement.to_world(p) - b.placement.to_world(p)).length() < 1e-9);
        }
    }

    #[test]
    fn bad_scenes_say_what_is_wrong_and_where() {
        let cases = [
            ("[1]", "(top level): a scene file is a JSON object"),
            ("{", "not a scene file"),
            (r#"{"models": []}"#, "tessera_scene: missing"),
            (r#"{"tessera_scene": 7, "models": []}"#, "version 7"),
            (
                r#"{"tessera_scene": 1, "models": []}"#,
                "at least one model",
            ),
            (
                r#"{"tessera_scene": 1, "up": "sideways", "models": []}"#,
                "up:",
            ),
            (
                r#"{"tessera_scene": 1, "modles": []}"#,
                "unknown key \"modles\"",
            ),
            (
                r#"{"tessera_scene": 1, "models": [{"name": "a", "model": "a.tsr"}, {"name": "a", "model": "b.tsr"}]}"#,
                "models[1].name: \"a\" names two models",
            ),
            (
                r#"{"tessera_scene": 1, "models": [{"model": "a.tsr"}]}"#,
                "models[0].name: missing",
            ),
            (
                r#"{"tessera_scene": 1, "models": [{"name": "a", "model": "a.tsr", "scale": 0}]}"#,
                "models[0].scale: a positive number",
            ),
            (
                r#"{"tessera_scene": 1, "models": [{"name": "a", "model": "a.tsr", "translate": [1, "x", 2]}]}"#,
                "models[0].translate[1]: a finite number",
            ),
            (
                r#"{"tessera_scene": 1, "models": [{"name": "a", "model": "a.tsr", "translate": [1, 2]}]}"#,
                "models[0].translate: a list of 3 numbers",
            ),
            (
                r#"{"tessera_scene": 1, "models": [{"name": "a", "model": "a.tsr", "rotate": {"axis": [0, 0, 0], "degrees": 3}}]}"#,
                "models[0].rotate.axis: the axis is zero",
            ),
            (
                r#"{"tessera_scene": 1, "models": [{"name": "a", "model": "a.tsr", "rotate": [0, 0, 0, 0]}]}"#,
                "the quaternion is zero",
            ),
            (
                r#"{"tessera_scene": 1, "models": [{"name": "a", "model": "a.tsr", "matrix": [1, 0, 0, 0, 0, 3, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]}]}"#,
                "models[0].matrix: the matrix is not a similarity",
            ),
            (
                r#"{"tessera_scene": 1, "models": [{"name": "a", "model": "a.tsr", "scale": 2, "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]}]}"#,
                "not both",
            ),
        ];
        for (text, want) in cases {
            let got = err(text);
            assert!(got.contains(want), "{text}\n  gave: {got}\n  want: {want}");
        }
    }
}
