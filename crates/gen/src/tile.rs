//! K translated copies of a real scan, to make big inputs with real-world geometry.

use std::path::Path;

use tessera_mesh::{
    read_mesh, Attributes, MeshError, MeshHeader, MeshVisitor, PlyWriter, PlyWriterOptions, Vertex,
};

use crate::{GenError, GenReport, Progress, Ticker};

/// Options of [`write_tiled`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TileOptions {
    /// Number of copies, at least 1.
    pub copies: u32,
}

impl Default for TileOptions {
    fn default() -> Self {
        TileOptions { copies: 4 }
    }
}

/// Write `opts.copies` copies of the mesh at `input` (any format `tessera_mesh::read_mesh`
/// reads) to `output` (binary PLY, atomic).
///
/// Contract: the input is read into memory (it should be small: up to ~1M triangles).
/// Copy `c` (0-based) sits in column `c % cols`, row `c / cols` of a grid with
/// `cols = ceil(sqrt(copies))`: it is the input translated by `(col * dx, row * dy, 0)`
/// where `dx`, `dy` are 1.1 times the input's bounding-box size along x and y (a zero size
/// falls back to 1.1 times the largest size, or 1). Copy 0 is the input unchanged. The
/// output has `copies * V` vertices and `copies * T` triangles (V, T as read; degenerate
/// faces the reader skips are not copied): copy `c` holds vertices `c V .. (c + 1) V` in
/// input order and the input's triangles shifted by `c V`, so copies share no vertex. The
/// input's attributes (normals, colours, uvs) are kept. Fails with
/// [`GenError::InvalidArgument`] when `copies` is 0 or the output would have more than
/// `u32::MAX` vertices, with [`GenError::Mesh`] when the input cannot be read.
///
/// Reports one `generate` stage to `progress` (see [`crate::Progress`]).
pub fn write_tiled(
    input: &Path,
    output: &Path,
    opts: &TileOptions,
    progress: &dyn Progress,
) -> Result<GenReport, GenError> {
    if opts.copies == 0 {
        return Err(GenError::InvalidArgument(
            "tile: copies must be at least 1".into(),
        ));
    }
    let mut mesh = Collect::default();
    read_mesh(input, &mut mesh)?;
    if mesh.triangles.is_empty() {
        return Err(MeshError::Empty {
            path: input.to_path_buf(),
        }
        .into());
    }
    let copies = u64::from(opts.copies);
    let v_in = mesh.vertices.len() as u64;
    let t_in = mesh.triangles.len() as u64;
    let vertex_count = copies * v_in;
    let face_count = copies * t_in;
    if vertex_count > u64::from(u32::MAX) {
        return Err(GenError::InvalidArgument(format!(
            "tile: {copies} copies of {v_in} vertices exceed {} vertices",
            u32::MAX
        )));
    }

    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for v in &mesh.vertices {
        for k in 0..3 {
            lo[k] = lo[k].min(f64::from(v.position[k]));
            hi[k] = hi[k].max(f64::from(v.position[k]));
        }
    }
    let size = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    let largest = size[0].max(size[1]).max(size[2]);
    let spacing = |s: f64| {
        if s > 0.0 {
            1.1 * s
        } else if largest > 0.0 {
            1.1 * largest
        } else {
            1.0
        }
    };
    let (dx, dy) = (spacing(size[0]), spacing(size[1]));
    let cols = ceil_sqrt(copies);

    let source = input
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let writer_opts = PlyWriterOptions {
        attributes: mesh.attributes,
        vertex_count,
        face_count,
        comments: vec![format!("tessera-gen tile copies={copies} source={source}")],
    };
    let mut w = PlyWriter::create(output, &writer_opts)?;
    let mut ticker = Ticker::new(progress, vertex_count, face_count);

    for c in 0..copies {
        let off = [(c % cols) as f64 * dx, (c / cols) as f64 * dy];
        for v in &mesh.vertices {
            let mut t = *v;
            t.position[0] = (f64::from(v.position[0]) + off[0]) as f32;
            t.position[1] = (f64::from(v.position[1]) + off[1]) as f32;
            w.write_vertex(&t)?;
        }
        ticker.add_vertices(v_in);
    }
    for c in 0..copies {
        let base = (c * v_in) as u32;
        for t in &mesh.triangles {
            w.write_triangle([t[0] + base, t[1] + base, t[2] + base])?;
        }
        ticker.add_triangles(t_in);
    }
    w.finish()?;
    ticker.finish();
    Ok(GenReport {
        vertices: vertex_count,
        triangles: face_count,
    })
}

/// Smallest `c` with `c * c >= k`.
fn ceil_sqrt(k: u64) -> u64 {
    let mut c = (k as f64).sqrt() as u64;
    while c * c < k {
        c += 1;
    }
    while c > 1 && (c - 1) * (c - 1) >= k {
        c -= 1;
    }
    c.max(1)
}

#[derive(Default)]
struct Collect {
    attributes: Attributes,
    vertices: Vec<Vertex>,
    triangles: Vec<[u32; 3]>,
}

impl MeshVisitor for Collect {
    fn header(&mut self, header: &MeshHeader) -> Result<(), MeshError> {
        self.attributes = header.attributes;
        if let Some(n) = header.vertex_count {
            self.vertices.reserve(n.min(1 << 24) as usize);
        }
        if let Some(n) = header.face_count {
            self.triangles.reserve(n.min(1 << 24) as usize);
        }
        Ok(())
    }

    fn vertex(&mut self, vertex: &Vertex) -> Result<(), MeshError> {
        self.vertices.push(*vertex);
        Ok(())
    }

    fn triangle(&mut self, indices: [u32; 3]) -> Result<(), MeshError> {
        self.triangles.push(indices);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ceil_sqrt_small() {
        let expect = [
            (1, 1),
            (2, 2),
            (4, 2),
            (5, 3),
            (9, 3),
            (10, 4),
            (16, 4),
            (17, 5),
        ];
        for (k, c) in expect {
            assert_eq!(ceil_sqrt(k), c, "{k}");
        }
    }
}
