//! Static hosting: a model is a plain file, and the remote reader works against any
//! server with Range support. This starts Debian's nginx (no root paths: prefix, temp
//! dirs, logs and pid in a tempdir, `daemon off`) on a free loopback port, serving a
//! model built here, and checks that `tessera info URL` and complete renders equal the
//! local ones. nginx must be installed (`apt-get install -y nginx-light`; CI does).

mod common;
mod remote;

use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

fn tessera() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tessera"))
}

/// The nginx binary: on PATH or in /usr/sbin (not on a plain user's PATH).
fn nginx_binary() -> PathBuf {
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

/// nginx serving `root` on a free loopback port; stopped when dropped.
struct Nginx {
    child: Child,
    addr: SocketAddr,
    _dir: tempfile::TempDir,
}

impl Nginx {
    fn start(root: &Path) -> Nginx {
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
        let mut n = Nginx {
            child,
            addr,
            _dir: dir,
        };
        let start = Instant::now();
        while TcpStream::connect(addr).is_err() {
            if let Some(status) = n.child.try_wait().unwrap() {
                let log =
                    std::fs::read_to_string(n._dir.path().join("error.log")).unwrap_or_default();
                panic!("nginx exited ({status}): {log}");
            }
            assert!(
                start.elapsed() < Duration::from_secs(20),
                "nginx does not listen on {addr}"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        n
    }
}

impl Drop for Nginx {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
fn info_and_render_through_nginx_equal_the_local_ones() {
    let built = common::build_sphere(20_000, 8, true, &common::small_options());
    let www = tempfile::tempdir().unwrap();
    std::fs::create_dir(www.path().join("models")).unwrap();
    let served = www.path().join("models").join("n.tsr");
    std::fs::copy(&built.model_path, &served).unwrap();
    let nginx = Nginx::start(www.path());
    let url = format!("http://{}/models/n.tsr", nginx.addr);
    let local = served.to_str().unwrap();

    assert_eq!(remote::info_json(&url), remote::info_json(local));
    remote::assert_same_renders(local, &url);

    // A name nginx does not have: one clear error.
    let o = tessera()
        .args(["info", &format!("http://{}/models/missing.tsr", nginx.addr)])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("not found") && !err.contains("panicked"),
        "{err}"
    );
}
