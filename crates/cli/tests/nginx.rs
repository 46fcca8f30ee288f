//! Static hosting: a model is a plain file, and the remote reader works against any
//! server with Range support. This starts Debian's nginx (no root paths: prefix, temp
//! dirs, logs and pid in a tempdir, `daemon off`) on a free loopback port, serving a
//! model built here, and checks that `tessera info URL` and complete renders equal the
//! local ones. nginx must be installed (`apt-get install -y nginx-light`; CI does).

mod common;
mod remote;

use std::process::Command;

use common::Nginx;

fn tessera() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tessera"))
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
