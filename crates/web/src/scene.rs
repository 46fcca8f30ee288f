//! Scene files in the browser (`web/scene.html`): the page's scene file read and checked
//! by the same code as the desktop's (`tessera_scene`, docs/scene.md), handed to the page
//! as each model's name, reference and placement matrix (column-major, three.js's
//! `Matrix4.fromArray` order); the page resolves references against the scene's URL and
//! places one three.js `TesseraModel` per entry.

use serde_json::{json, Value};

/// The scene in `text` as the page uses it: `{"up": "+z" | null, "models": [{"name",
/// "model", "matrix": [16 numbers]}]}`; a bad scene: the message naming the field.
pub fn scene_for_page(text: &str) -> Result<Value, String> {
    let scene = tessera_scene::Scene::from_json_str(text).map_err(|e| e.to_string())?;
    let models: Vec<Value> = scene
        .models
        .iter()
        .map(|m| {
            json!({
                "name": m.name,
                "model": m.model,
                "matrix": m.placement.matrix().to_cols_array(),
            })
        })
        .collect();
    Ok(json!({
        "up": scene.up.map(|u| u.to_string()),
        "models": models,
    }))
}

/// [`scene_for_page`] for JavaScript: the JSON text, or an `Error` with the message.
#[cfg(target_arch = "wasm32")]
#[wasm_bindgen::prelude::wasm_bindgen(js_name = parseScene)]
pub fn parse_scene(text: &str) -> Result<String, wasm_bindgen::JsError> {
    scene_for_page(text)
        .map(|v| v.to_string())
        .map_err(|e| wasm_bindgen::JsError::new(&format!("scene file: {e}")))
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_page_gets_matrices_and_messages() {
        let v = super::scene_for_page(
            r#"{"tessera_scene": 1, "models": [{"name": "a", "model": "a.tsr",
                "translate": [1, 2, 3], "scale": 2}]}"#,
        )
        .unwrap();
        let m: Vec<f64> = serde_json::from_value(v["models"][0]["matrix"].clone()).unwrap();
        assert_eq!(
            m,
            [2., 0., 0., 0., 0., 2., 0., 0., 0., 0., 2., 0., 1., 2., 3., 1.]
        );
        assert!(v["up"].is_null());
        let e = super::scene_for_page(r#"{"tessera_scene": 1, "models": [{"name": "a"}]}"#)
            .unwrap_err();
        assert!(e.contains("models[0].model"), "{e}");
    }
}
