//! One primitive of one instance delivered to the visitor: its vertices in chunks
//! through the instance's world transform (normals through the inverse transpose,
//! renormalised; UVs through the texture transform; colours times the base colour factor,
//! encoded to sRGB), then its triangles assembled from lists, strips or fans, every index
//! checked against the primitive's vertex count and the winding flipped under a mirror.
//! A `KHR_draco_mesh_compression` primitive goes the same way, its decoded attributes
//! read like accessors and its Draco faces as a triangle list.

use crate::common::{note_ignored, poll, PolygonEmitter};
use crate::{Attributes, ImportReport, MeshError, MeshVisitor, Vertex};

use super::accessor::Accessor;
use super::container::Views;
use super::draco::{Decoded, Role};
use super::material::srgb8;
use super::{scene, Draw, Mode, CHUNK};

/// Where a draw's vertices and triangles go: the visitor, through the polygon emitter
/// (which skips degenerate triangles), with the import's report.
pub(super) struct DrawSink<'a> {
    pub emitter: &'a mut PolygonEmitter,
    pub visitor: &'a mut dyn MeshVisitor,
    pub report: &'a mut ImportReport,
}

/// Deliver one draw into `sink`: its vertices (numbered from `base`, with the model's
/// `attributes`), then its triangles. Returns the number of vertices delivered.
/// `draco`: the draw's decoded Draco stream, for a draw read from one.
pub(super) fn emit_draw(
    views: &Views<'_>,
    d: &Draw,
    draco: Option<&Decoded>,
    attributes: Attributes,
    base: u64,
    sink: &mut DrawSink<'_>,
) -> Result<u64, MeshError> {
    let DrawSink {
        emitter,
        visitor,
        report,
    } = sink;
    let (emitter, visitor, report) = (&mut **emitter, &mut **visitor, &mut **report);
    let path = views.path;
    // From the Draco stream where it has the attribute, else from the accessor.
    let open = |role: Role, a: usize, what: &str, components: &[usize]| {
        let what = format!("{what} of {}", d.name);
        let decoded = draco.and_then(|x| x.attrs[role as usize].as_ref());
        match (decoded, draco) {
            (Some((c, values)), Some(x)) => {
                Accessor::decoded(views, a, &what, components, (*c, values), x.points)
            }
            _ => Accessor::open(views, a, &what, components),
        }
    };
    let pos = open(Role::Position, d.position, "POSITION", &[3])?;
    let normal = match d.normal {
        Some(a) if attributes.normals => Some(open(Role::Normal, a, "NORMAL", &[3])?),
        _ => None,
    };
    let uv = match d.uv {
        Some(a) => Some(open(
            Role::Uv,
            a,
            &format!("TEXCOORD_{}", d.material.uv_set),
            &[2],
        )?),
        None => None,
    };
    let color = match d.color {
        Some(a) => {
            let c = open(Role::Color, a, "COLOR_0", &[3, 4])?;
            if !c.is_float_or_normalized() {
                return Err(MeshError::malformed(
                    path,
                    &c.name,
                    "COLOR_0 must be FLOAT or normalized UNSIGNED_BYTE / UNSIGNED_SHORT",
                ));
            }
            Some(c)
        }
        None => None,
    };
    for a in [&normal, &uv, &color].into_iter().flatten() {
        if a.count < pos.count {
            return Err(MeshError::malformed(
                path,
                &a.name,
                format!("has {} elements, POSITION has {}", a.count, pos.count),
            ));
        }
    }
    let indices = match (draco, d.indices) {
        (Some(x), _) => Some(Accessor::decoded_indices(
            format!("faces of {} (from KHR_draco_mesh_compression)", d.name),
            &x.indices,
        )),
        (None, Some(a)) => {
            let acc = Accessor::open(views, a, &format!("indices of {}", d.name), &[1])?;
            acc.check_index_type(views)?;
            Some(acc)
        }
        (None, None) => None,
    };
    // Draco decodes faces: a triangle list whatever the primitive's mode.
    let mode = if draco.is_some() {
        Mode::Triangles
    } else {
        d.mode
    };

    // Vertices.
    let m = &d.world;
    let (nm, mirrored) = scene::normal_matrix(m);
    let factor = d.material.factor;
    let mut p = Vec::new();
    let mut n = Vec::new();
    let mut t = Vec::new();
    let mut c = Vec::new();
    let count = pos.count;
    let mut start = 0;
    while start < count {
        // An accessor may claim 3 x 10^9 zeros (no buffer view): Ctrl-C must still work.
        poll(visitor)?;
        let len = CHUNK.min(count - start);
        pos.read_f32(start, len, 0.0, &mut p);
        if let Some(a) = &normal {
            a.read_f32(start, len, 0.0, &mut n);
        }
        if let Some(a) = &uv {
            a.read_f32(start, len, 0.0, &mut t);
        }
        if let Some(a) = &color {
            a.read_f32(start, len, 1.0, &mut c);
        }
        for k in 0..len {
            let [x, y, z, _] = p[k].map(f64::from);
            let position: [f32; 3] = std::array::from_fn(|r| {
                (m[r] * x + m[4 + r] * y + m[8 + r] * z + m[12 + r]) as f32
            });
            if !position.iter().all(|v| v.is_finite()) {
                let why = if p[k][..3].iter().all(|v| v.is_finite()) {
                    "is finite, but not after its node's transform"
                } else {
                    "is not finite (NaN or infinity)"
                };
                return Err(MeshError::malformed(
                    path,
                    format!("{}, element {}", pos.name, start + k),
                    format!("position {:?} {why}", &p[k][..3]),
                ));
            }
            let mut v = Vertex {
                position,
                ..Vertex::default()
            };
            if uv.is_some() {
                v.texture = d.texture;
            }
            if normal.is_some() {
                let [x, y, z, _] = n[k].map(f64::from);
                let w: [f64; 3] =
                    std::array::from_fn(|r| nm[r * 3] * x + nm[r * 3 + 1] * y + nm[r * 3 + 2] * z);
                let l = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
                // A zero or broken normal stays zero: the builder replaces it.
                if l > 0.0 && l.is_finite() {
                    v.normal = w.map(|x| (x / l) as f32);
                }
            }
            if uv.is_some() {
                let [u, vv, _, _] = t[k];
                v.uv = match d.material.uv_transform {
                    Some([a, b, cc, dd, tx, ty]) => [a * u + cc * vv + tx, b * u + dd * vv + ty],
                    None => [u, vv],
                };
                if !v.uv.iter().all(|x| x.is_finite()) {
                    return Err(MeshError::malformed(
                        path,
                        format!("{}, element {}", t_name(&uv), start + k),
                        format!(
                            "texture coordinate {:?} is not finite (NaN or infinity)",
                            &t[k][..2]
                        ),
                    ));
                }
            }
            if attributes.colors {
                let rgba = if color.is_some() { c[k] } else { [1.0; 4] };
                v.color = [
                    srgb8(rgba[0] * factor[0]),
                    srgb8(rgba[1] * factor[1]),
                    srgb8(rgba[2] * factor[2]),
                    // Alpha is linear coverage, not a colour.
                    ((rgba[3] * factor[3]).clamp(0.0, 1.0) * 255.0 + 0.5) as u8,
                ];
            }
            visitor.vertex(&v)?;
        }
        report.vertices += len as u64;
        start += len;
    }

    // Triangles.
    let corner_count = indices.as_ref().map_or(count, |a| a.count);
    let mut buf = Vec::new();
    let mut asm = Assembler::new(mode);
    let check = |i: u32, k: usize| -> Result<u32, MeshError> {
        if (i as usize) < count {
            Ok(i)
        } else {
            Err(MeshError::IndexOutOfRange {
                path: path.to_path_buf(),
                line_or_offset: format!(
                    "{}, element {k}",
                    indices.as_ref().map_or("", |a| a.name.as_str())
                ),
                index: i64::from(i),
                vertex_count: count as u64,
            })
        }
    };
    let mut start = 0;
    while start < corner_count {
        poll(visitor)?;
        let len = (3 * CHUNK).min(corner_count - start);
        match &indices {
            Some(a) => a.read_indices(start, len, &mut buf),
            None => {
                buf.clear();
                buf.extend((start..start + len).map(|i| i as u32));
            }
        }
        for (k, &i) in buf.iter().enumerate() {
            let i = check(i, start + k)?;
            if let Some([a, b, c]) = asm.push(i) {
                let (b, c) = if mirrored { (c, b) } else { (b, c) };
                // `base + i` < the vertex total, which was checked to fit a u32.
                let corners = [a, b, c].map(|x| (base + u64::from(x)) as u32);
                emitter.emit(&corners, visitor, report)?;
            }
        }
        start += len;
    }
    if mode == Mode::Triangles && corner_count % 3 != 0 {
        note_ignored(report, "indices after the last whole triangle", 1);
    }
    Ok(count as u64)
}

fn t_name(a: &Option<Accessor<'_>>) -> String {
    a.as_ref().map_or_else(String::new, |a| a.name.clone())
}

/// Turns a stream of indices into triangles by primitive mode.
struct Assembler {
    mode: Mode,
    /// Corners so far (lists), or the strip's last two / the fan's first and last.
    held: [u32; 3],
    seen: u64,
}

impl Assembler {
    fn new(mode: Mode) -> Assembler {
        Assembler {
            mode,
            held: [0; 3],
            seen: 0,
        }
    }

    /// Take the next index; a triangle when one is complete (in the file's winding).
    fn push(&mut self, i: u32) -> Option<[u32; 3]> {
        let k = self.seen;
        self.seen += 1;
        match self.mode {
            Mode::Triangles => {
                self.held[(k % 3) as usize] = i;
                (k % 3 == 2).then_some(self.held)
            }
            Mode::Strip => {
                let [a, b, _] = self.held;
                self.held = [b, i, 0];
                // Triangle j = k - 2: (v_j, v_j+1, v_j+2) when even, (v_j, v_j+2, v_j+1)
                // when odd, so all keep the first triangle's winding.
                match k {
                    0 | 1 => None,
                    _ if (k - 2).is_multiple_of(2) => Some([a, b, i]),
                    _ => Some([a, i, b]),
                }
            }
            Mode::Fan => match k {
                0 => {
                    self.held[0] = i;
                    None
                }
                1 => {
                    self.held[1] = i;
                    None
                }
                _ => {
                    let t = [self.held[0], self.held[1], i];
                    self.held[1] = i;
                    Some(t)
                }
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(mode: Mode, n: u32) -> Vec<[u32; 3]> {
        let mut a = Assembler::new(mode);
        (0..n).filter_map(|i| a.push(i)).collect()
    }

    #[test]
    fn strips_and_fans_keep_one_winding() {
        assert_eq!(run(Mode::Triangles, 7), [[0, 1, 2], [3, 4, 5]]);
        assert_eq!(run(Mode::Strip, 5), [[0, 1, 2], [1, 3, 2], [2, 3, 4]]);
        assert_eq!(run(Mode::Fan, 5), [[0, 1, 2], [0, 2, 3], [0, 3, 4]]);
    }
}
