//! Fixtures shared by the workspace's tests (a dev-dependency only): the build options
//! that give small meshes deep hierarchies, a generated sphere built into a model in
//! its own temporary directory, the real scans of `../shared/data` with a message that
//! says where they come from, a mesh read whole into memory, a seeded [`Rng`], and the
//! committed fuzz inputs ([`fuzz`]). One copy instead of one per test file, so a fixture changed is
//! changed everywhere.

use std::path::{Path, PathBuf};

use tessera_build::{BuildOptions, NoProgress};
use tessera_gen::SphereOptions;
use tessera_mesh::{MeshError, MeshHeader, MeshVisitor, Vertex};

pub mod fuzz;

/// Small nodes (400-triangle leaves, 200-triangle patches), so that meshes of a few
/// tens of thousands of triangles give deep hierarchies; 256 MiB, 2 threads.
pub fn small_options() -> BuildOptions {
    BuildOptions {
        memory_bytes: 256 << 20,
        threads: Some(2),
        leaf_triangles: 400,
        node_triangles: 200,
        ..BuildOptions::default()
    }
}

/// A model built for a test (from a real scan or a generated sphere), in a temporary
/// directory that lives as long as this.
pub struct TestModel {
    pub dir: tempfile::TempDir,
    /// The mesh built: the scan given, or the generated PLY.
    pub input: PathBuf,
    /// The built `model.tsr`.
    pub path: PathBuf,
}

/// Builds `input` with `opts`, or, without one, the sphere `sphere` generated first.
pub fn build_model(input: Option<&Path>, sphere: &SphereOptions, opts: &BuildOptions) -> TestModel {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = match input {
        Some(p) => p.to_owned(),
        None => {
            let p = dir.path().join("sphere.ply");
            tessera_gen::write_sphere(&p, sphere, &tessera_gen::NoProgress)
                .expect("generate sphere");
            p
        }
    };
    let path = dir.path().join("model.tsr");
    tessera_build::build(&input, &path, opts, &NoProgress).expect("build");
    TestModel { dir, input, path }
}

/// The noisy sphere of `triangles` triangles most tests build (seed 7, noise 0.05, no
/// colours).
pub fn sphere(triangles: u64) -> SphereOptions {
    SphereOptions {
        triangles,
        seed: 7,
        colors: false,
        noise: 0.05,
    }
}

/// The real scan `name` of `../shared/data` (beside the repository); panics with where
/// the scans come from when it is missing.
pub fn shared_data(name: &str) -> PathBuf {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data")
        .join(name);
    assert!(
        p.exists(),
        "{} is missing: these tests need the real scans in ../shared/data beside the repository (CI has them)",
        p.display()
    );
    p
}

/// A mesh read whole into memory through a [`MeshVisitor`] (the test meshes are small).
#[derive(Default)]
pub struct MeshCollector {
    pub header: MeshHeader,
    pub vertices: Vec<Vertex>,
    pub triangles: Vec<[u32; 3]>,
}

impl MeshVisitor for MeshCollector {
    fn header(&mut self, header: &MeshHeader) -> Result<(), MeshError> {
        self.header = header.clone();
        Ok(())
    }
    fn vertex(&mut self, v: &Vertex) -> Result<(), MeshError> {
        self.vertices.push(*v);
        Ok(())
    }
    fn triangle(&mut self, t: [u32; 3]) -> Result<(), MeshError> {
        self.triangles.push(t);
        Ok(())
    }
}

/// xorshift64*: deterministic, dependency-free noise for test data and the mutations of
/// the adversarial corpora (the same inputs on every run and machine).
pub struct Rng(pub u64);

impl Rng {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    /// A number below `n` (0 for `n` = 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform integer in [-r, r].
    pub fn jitter(&mut self, r: i64) -> i64 {
        (self.next_u64() % (2 * r as u64 + 1)) as i64 - r
    }
}

/// FNV-1a (64-bit), to pin the exact bytes of a small file.
pub fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// SplitMix64: deterministic numbers in [0, 1) and directions, for the rays of the pick
/// tests and benchmark.
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    /// Uniform in [0, 1).
    pub fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
    /// A uniformly distributed unit vector (rejection sampling in the cube).
    pub fn unit_vector(&mut self) -> [f64; 3] {
        loop {
            let v = [self.next_f64(), self.next_f64(), self.next_f64()].map(|x| 2.0 * x - 1.0);
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if l > 1e-3 && l <= 1.0 {
                return v.map(|x| x / l);
            }
        }
    }
    /// A point uniformly distributed in the unit ball.
    pub fn in_ball(&mut self) -> [f64; 3] {
        let u = self.unit_vector();
        let s = self.next_f64().cbrt();
        u.map(|x| x * s)
    }
}
