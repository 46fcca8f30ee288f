//! What a glTF material gives the vertices of its primitives: its base colour factor
//! (multiplied into `COLOR_0`, or the colour of a primitive without one; the fallback
//! colour of a textured one), the texture coordinate set of its base colour texture and
//! that texture's `KHR_texture_transform`, applied to the UVs so they are the ones a
//! renderer samples. Its texture itself is resolved in [`super::texture`].

use std::path::Path;

use ::gltf::json;

use crate::MeshError;

/// What a primitive's material contributes to its vertices.
#[derive(Clone, Debug)]
pub(super) struct MaterialUse {
    /// `None`: the default material.
    pub(super) index: Option<usize>,
    /// Linear RGBA.
    pub(super) factor: [f32; 4],
    pub(super) textured: bool,
    /// The texture coordinate set the base colour texture uses (0 without one).
    pub(super) uv_set: u32,
    /// `KHR_texture_transform` of the base colour texture, as `[a, b, c, d, tx, ty]`:
    /// `u' = a u + c v + tx`, `v' = b u + d v + ty`.
    pub(super) uv_transform: Option<[f32; 6]>,
}

impl MaterialUse {
    pub(super) fn of(
        path: &Path,
        root: &json::Root,
        index: Option<usize>,
    ) -> Result<MaterialUse, MeshError> {
        let Some(i) = index else {
            return Ok(MaterialUse {
                index: None,
                factor: [1.0; 4],
                textured: false,
                uv_set: 0,
                uv_transform: None,
            });
        };
        let m = root.materials.get(i).ok_or_else(|| {
            MeshError::malformed(
                path,
                format!("material {i}"),
                format!(
                    "does not exist (the file has {} materials)",
                    root.materials.len()
                ),
            )
        })?;
        let pbr = &m.pbr_metallic_roughness;
        let factor = pbr.base_color_factor.0.map(|x| {
            if x.is_finite() {
                x.clamp(0.0, 1.0)
            } else {
                1.0
            }
        });
        let tex = pbr.base_color_texture.as_ref();
        let transform = tex
            .and_then(|t| t.extensions.as_ref())
            .and_then(|e| e.texture_transform.as_ref());
        let uv_set = transform
            .and_then(|t| t.tex_coord)
            .or(tex.map(|t| t.tex_coord))
            .unwrap_or(0);
        let uv_transform = transform.map(|t| {
            // As three.js and CesiumJS apply it (the order the specification's sample
            // model checks): scale, then rotate, then offset.
            let (s, c) = t.rotation.0.sin_cos();
            let [sx, sy] = t.scale.0;
            let [ox, oy] = t.offset.0;
            [c * sx, -s * sx, s * sy, c * sy, ox, oy]
        });
        Ok(MaterialUse {
            index: Some(i),
            factor,
            textured: tex.is_some(),
            uv_set,
            uv_transform,
        })
    }
}

/// Linear 0..1 to an 8-bit sRGB value.
pub(super) fn srgb8(linear: f32) -> u8 {
    let x = if linear.is_finite() {
        linear.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let s = if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_encoding_keeps_the_ends() {
        assert_eq!(srgb8(0.0), 0);
        assert_eq!(srgb8(1.0), 255);
        assert_eq!(srgb8(0.5), 188);
        assert_eq!(srgb8(f32::NAN), 0);
    }
}
