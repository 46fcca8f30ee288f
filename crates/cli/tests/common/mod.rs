//! Helpers shared by the integration tests of `tessera-cli`: generate and build test
//! models through the library crates, decode and merge cuts, read meshes back, run the
//! `tessera` binary, and look for leftover temporary files.
#![allow(dead_code)]

use std::collections::HashMap;
use std::net::{SocketAddr, TcpListener};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};

use tessera_build::{BuildOptions, BuildReport, NoProgress};
use tessera_format::{Header, Model, PatchData};
use tessera_mesh::{MeshError, MeshHeader, MeshVisitor, Vertex};
use tessera_select::{edge_report, merge_patches, CutMesh, EdgeReport, PatchRef};

#[allow(unused_imports)]
pub use tessera_testkit::small_options;

/// A generated sphere built into a model, in its own temporary directory.
pub struct Built {
    pub dir: tempfile::TempDir,
    pub input: PathBuf,
    pub model_path: PathBuf,
    pub report: BuildReport,
    pub model: Model,
}

/// Generates a noisy closed sphere of about `triangles` triangles and builds it.
pub fn build_sphere(triangles: u64, seed: u64, colors: bool, opts: &BuildOptions) -> Built {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = dir.path().join(format!("sphere-{triangles}-{seed}.ply"));
    tessera_gen::write_sphere(
        &input,
        &tessera_gen::SphereOptions {
            triangles,
            seed,
            colors,
            noise: 0.05,
        },
        &tessera_gen::NoProgress,
    )
    .expect("generate sphere");
    build_file(dir, input, opts)
}

/// Builds `input` (inside `dir`) into `dir/model.tsr`.
pub fn build_file(dir: tempfile::TempDir, input: PathBuf, opts: &BuildOptions) -> Built {
    let model_path = dir.path().join("model.tsr");
    let report = tessera_build::build(&input, &model_path, opts, &NoProgress)
        .unwrap_or_else(|e| panic!("building {}: {e}", input.display()));
    let model = Model::open(&model_path).expect("open built model");
    Built {
        dir,
        input,
        model_path,
        report,
        model,
    }
}

/// Every patch of a model, decoded once.
pub fn decode_all(m: &Model) -> Vec<PatchData> {
    (0..m.nodes().len())
        .map(|i| {
            m.decode_patch(i)
                .unwrap_or_else(|e| panic!("node {i}: {e}"))
        })
        .collect()
}

/// Merges the patches of `nodes` (from pre-decoded `patches`) into one mesh.
pub fn merge(patches: &[PatchData], nodes: &[u32]) -> CutMesh {
    merge_patches(nodes.iter().map(|&i| PatchRef::from(&patches[i as usize])))
}

/// Edge report of the merged cut.
pub fn cut_report(patches: &[PatchData], nodes: &[u32]) -> (CutMesh, EdgeReport) {
    let mesh = merge(patches, nodes);
    let r = edge_report(&mesh.indices, &mesh.positions);
    (mesh, r)
}

/// A detailed description of where the open / non-manifold edges of a cut are: for the
/// first few offending edges, the grid positions of their ends and the (node, level) of
/// every selected patch that uses them.
/// Boundary edges for which `allowed_boundary` holds are not counted as bad.
pub fn describe_bad_edges(
    m: &Model,
    patches: &[PatchData],
    nodes: &[u32],
    limit: usize,
    allowed_boundary: &dyn Fn([u32; 3], [u32; 3]) -> bool,
) -> String {
    let mut uses: HashMap<([u32; 3], [u32; 3]), Vec<u32>> = HashMap::new();
    for &n in nodes {
        let p = &patches[n as usize];
        for t in p.indices.chunks_exact(3) {
            let c = [
                p.positions[t[0] as usize],
                p.positions[t[1] as usize],
                p.positions[t[2] as usize],
            ];
            if c[0] == c[1] || c[1] == c[2] || c[2] == c[0] {
                continue;
            }
            for (a, b) in [(c[0], c[1]), (c[1], c[2]), (c[2], c[0])] {
                let key = if a < b { (a, b) } else { (b, a) };
                uses.entry(key).or_default().push(n);
            }
        }
    }
    let mut bad: Vec<_> = uses
        .into_iter()
        .filter(|((a, b), v)| v.len() > 2 || (v.len() == 1 && !allowed_boundary(*a, *b)))
        .collect();
    bad.sort();
    let mut by_node: HashMap<u32, usize> = HashMap::new();
    for (_, v) in &bad {
        for &n in v {
            *by_node.entry(n).or_default() += 1;
        }
    }
    let mut nodes_hit: Vec<_> = by_node.into_iter().collect();
    nodes_hit.sort_by_key(|&(n, c)| (std::cmp::Reverse(c), n));
    let all = m.nodes();
    let mut s = format!(
        "{} bad edges; patches touching them (node/level/bad edges): ",
        bad.len()
    );
    for (n, c) in nodes_hit.iter().take(12) {
        s += &format!("{n}/L{}/{c} ", all[*n as usize].level);
    }
    for ((a, b), v) in bad.iter().take(limit) {
        let lv: Vec<String> = v
            .iter()
            .map(|&n| format!("{n}(L{})", all[n as usize].level))
            .collect();
        s += &format!(
            "\n    edge {a:?}-{b:?} used {} times by {}",
            v.len(),
            lv.join(", ")
        );
    }
    s
}

/// The triangles of an input mesh, as read back by `tessera_mesh`.
#[derive(Default)]
pub struct InputMesh {
    pub attributes: tessera_mesh::Attributes,
    pub positions: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    pub colors: Vec<[u8; 4]>,
    pub triangles: Vec<[u32; 3]>,
}

impl MeshVisitor for InputMesh {
    fn header(&mut self, h: &MeshHeader) -> Result<(), MeshError> {
        self.attributes = h.attributes;
        Ok(())
    }
    fn vertex(&mut self, v: &Vertex) -> Result<(), MeshError> {
        self.positions.push(v.position);
        self.normals.push(v.normal);
        self.colors.push(v.color);
        Ok(())
    }
    fn triangle(&mut self, t: [u32; 3]) -> Result<(), MeshError> {
        self.triangles.push(t);
        Ok(())
    }
}

pub fn read_input(path: &Path) -> InputMesh {
    let mut m = InputMesh::default();
    tessera_mesh::read_mesh(path, &mut m)
        .unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
    m
}

/// The builder's quantisation (its own `Grid::quantize`) on the grid the header records.
pub fn quantize(h: &Header, p: [f32; 3]) -> [u32; 3] {
    tessera_build::partition::Grid {
        origin: h.cube_origin,
        size: h.cube_size,
        bits: h.quant_bits,
    }
    .quantize(p)
}

/// A triangle of grid points rotated so that its smallest corner comes first
/// (orientation kept).
pub fn canonical_triangle(t: [[u32; 3]; 3]) -> [[u32; 3]; 3] {
    let k = (0..3).min_by_key(|&k| t[k]).unwrap_or(0);
    [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
}

/// Sorted canonical triangles of grid positions.
pub fn triangle_set(
    positions: &[[u32; 3]],
    indices: impl Iterator<Item = [u32; 3]>,
) -> Vec<[[u32; 3]; 3]> {
    let mut v: Vec<_> = indices
        .map(|t| {
            canonical_triangle([
                positions[t[0] as usize],
                positions[t[1] as usize],
                positions[t[2] as usize],
            ])
        })
        .collect();
    v.sort_unstable();
    v
}

/// Squared distance from `p` to triangle `abc` (Ericson, Real-Time Collision Detection 5.1.5).
pub fn point_triangle_dist2(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    let sub = |x: [f64; 3], y: [f64; 3]| [x[0] - y[0], x[1] - y[1], x[2] - y[2]];
    let dot = |x: [f64; 3], y: [f64; 3]| x[0] * y[0] + x[1] * y[1] + x[2] * y[2];
    let at = |o: [f64; 3], u: [f64; 3], s: f64, v: [f64; 3], t: f64| {
        [
            o[0] + u[0] * s + v[0] * t,
            o[1] + u[1] * s + v[1] * t,
            o[2] + u[2] * s + v[2] * t,
        ]
    };
    let d2 = |q: [f64; 3]| {
        let d = sub(p, q);
        dot(d, d)
    };
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2_) = (dot(ab, ap), dot(ac, ap));
    if d1 <= 0.0 && d2_ <= 0.0 {
        return d2(a);
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return d2(b);
    }
    let vc = d1 * d4 - d3 * d2_;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return d2(at(a, ab, v, ac, 0.0));
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return d2(c);
    }
    let vb = d5 * d2_ - d1 * d6;
    if vb <= 0.0 && d2_ >= 0.0 && d6 <= 0.0 {
        let w = d2_ / (d2_ - d6);
        return d2(at(a, ab, 0.0, ac, w));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        let bc = sub(c, b);
        return d2(at(b, bc, w, bc, 0.0));
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    d2(at(a, ab, v, ac, w))
}

/// A tiny deterministic RNG (xorshift64*).
pub struct XorShift(pub u64);

impl XorShift {
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    /// Uniform direction on the unit sphere.
    pub fn direction(&mut self) -> [f64; 3] {
        loop {
            let v = [
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
            ];
            let l2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
            if l2 > 1e-4 && l2 <= 1.0 {
                let l = l2.sqrt();
                return [v[0] / l, v[1] / l, v[2] / l];
            }
        }
    }
}

/// The `tessera` binary.
pub fn tessera() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_tessera"));
    c.env_remove("TESSERA_LOG");
    c
}

/// Runs `tessera ARGS`, returning (exit code, stdout, stderr).
pub fn run_tessera(args: &[&std::ffi::OsStr]) -> (i32, String, String) {
    let Output {
        status,
        stdout,
        stderr,
    } = tessera().args(args).output().expect("run tessera");
    (
        status.code().unwrap_or(-1),
        String::from_utf8_lossy(&stdout).into_owned(),
        String::from_utf8_lossy(&stderr).into_owned(),
    )
}

/// Convenience: arguments as OsStr from anything path-like or string-like.
#[macro_export]
macro_rules! args {
    ($($a:expr),* $(,)?) => { &[$(std::ffi::OsStr::new(&$a)),*] };
}

/// Names in `dir` that look like leftovers of a failed build or write: the builder's
/// `.tessera-build-*` directories and the writers' `.NAME.tmp-*` files.
pub fn leftovers(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| {
                    n.starts_with(".tessera-build-") || (n.starts_with('.') && n.contains(".tmp-"))
                })
                .collect()
        })
        .unwrap_or_default()
}

/// The nginx binary: on PATH or in /usr/sbin (not on a plain user's PATH).
pub fn nginx_binary() -> PathBuf {
    let on_path = std::env::var_os("PATH")
        .map(|p| {
            std::env::split_paths(&p)
                .map(|d| d.join("nginx"))
                .collect::<Vec<_>>()
        })
        .unwrap_or_default();
    on_path
        .into_iter()
        .chain([PathBuf::from("/usr/sbin/nginx")])
        .find(|p| p.is_file())
        .unwrap_or_else(|| {
            panic!(
                "nginx is not installed: this test needs it (apt-get install -y nginx-light; \
                 .ci/run installs it)"
            )
        })
}

/// Debian's nginx (no root paths: prefix, temp dirs, logs and pid in a tempdir, `daemon
/// off`) serving `root` as static files on a free loopback port, with the content types
/// a browser needs for an ES module and WebAssembly; stopped when dropped.
pub struct Nginx {
    child: Child,
    pub addr: SocketAddr,
    dir: tempfile::TempDir,
}

impl Nginx {
    pub fn start(root: &Path) -> Nginx {
        let bin = nginx_binary();
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path().display();
        let addr = TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap();
        let conf = format!(
            "daemon off;\nmaster_process off;\nworker_processes 1;\npid {d}/nginx.pid;\n\
             error_log {d}/error.log;\nevents {{ worker_connections 64; }}\n\
             http {{\n  access_log {d}/access.log;\n\
             client_body_temp_path {d}/body;\n  proxy_temp_path {d}/proxy;\n\
             fastcgi_temp_path {d}/fastcgi;\n  uwsgi_temp_path {d}/uwsgi;\n\
             scgi_temp_path {d}/scgi;\n  default_type application/octet-stream;\n\
             types {{ text/html html; text/javascript js; application/wasm wasm; application/json json; }}\n\
             server {{ listen {addr}; root {}; }}\n}}\n",
            root.display()
        );
        let conf_path = dir.path().join("nginx.conf");
        std::fs::write(&conf_path, conf).unwrap();
        let child = Command::new(&bin)
            .arg("-p")
            .arg(dir.path())
            .arg("-e")
            .arg(dir.path().join("error.log"))
            .arg("-c")
            .arg(&conf_path)
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {}: {e}", bin.display()));
        let mut n = Nginx { child, addr, dir };
        let start = std::time::Instant::now();
        while std::net::TcpStream::connect(addr).is_err() {
            if let Some(status) = n.child.try_wait().unwrap() {
                let log =
                    std::fs::read_to_string(n.dir.path().join("error.log")).unwrap_or_default();
                panic!("nginx exited ({status}): {log}");
            }
            assert!(
                start.elapsed().as_secs() < 20,
                "nginx does not listen on {addr}"
            );
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        n
    }

    /// Requests with a Range header answered 206 (from nginx's access log).
    pub fn ranges_answered(&self) -> usize {
        std::fs::read_to_string(self.dir.path().join("access.log"))
            .unwrap_or_default()
            .lines()
            .filter(|l| l.contains("\" 206 "))
            .count()
    }
}

impl Drop for Nginx {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A child process killed and reaped on drop (a server a test started).
pub struct Running(pub Child);

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `tessera serve ARGS --addr 127.0.0.1:0`; the address from its first line (the rest
/// of its output is drained on a thread).
pub fn serve_tessera(args: &[&std::ffi::OsStr]) -> (Running, SocketAddr) {
    use std::io::BufRead;
    let mut child = Running(
        tessera()
            .arg("serve")
            .args(args)
            .args(["--addr", "127.0.0.1:0"])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let mut out = std::io::BufReader::new(child.0.stdout.take().unwrap());
    let mut line = String::new();
    out.read_line(&mut line).unwrap();
    let addr: SocketAddr = line
        .trim()
        .rsplit_once(" at http://")
        .and_then(|(_, a)| a.trim_end_matches('/').parse().ok())
        .unwrap_or_else(|| panic!("unexpected first line of tessera serve: {line}"));
    std::thread::spawn(move || std::io::copy(&mut out, &mut std::io::sink()));
    (child, addr)
}

/// Percent-encodes everything but unreserved bytes (a URL query value or segment).
pub fn encode(s: &str) -> String {
    s.bytes()
        .map(|b| {
            if b.is_ascii_alphanumeric() || b"-._~".contains(&b) {
                (b as char).to_string()
            } else {
                format!("%{b:02X}")
            }
        })
        .collect()
}

/// `tessera render --complete` of one camera (JSON, docs/camera.md) at `width` x
/// `height` with `extra` arguments, frames into the directory `out`: the frame and its
/// triangles.
pub fn render_complete(
    model: &Path,
    camera: &str,
    out: &Path,
    (width, height): (u32, u32),
    extra: &[&str],
) -> (tessera_image::Image, u64) {
    let path = out.with_extension("json");
    let stats = out.with_extension("stats.json");
    std::fs::write(
        &path,
        format!(r#"{{"frames": 1, "keyframes": [{camera}]}}"#),
    )
    .unwrap();
    let mut argv: Vec<std::ffi::OsString> = vec![
        "render".into(),
        model.into(),
        "--path".into(),
        path.into(),
        "--complete".into(),
        "--out".into(),
        out.into(),
        "--width".into(),
        width.to_string().into(),
        "--height".into(),
        height.to_string().into(),
        "--stats".into(),
        stats.clone().into(),
    ];
    argv.extend(extra.iter().map(|a| a.into()));
    let argv: Vec<&std::ffi::OsStr> = argv.iter().map(|a| a.as_os_str()).collect();
    let (code, _, stderr) = run_tessera(&argv);
    assert_eq!(code, 0, "{stderr}");
    let stats: serde_json::Value = serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
    (
        tessera_image::Image::load_png(&out.join("frame_00000.png")).unwrap(),
        stats["frames"][0]["triangles"].as_u64().unwrap(),
    )
}
