//! The remote reader against a real `tessera serve` on loopback, and against servers
//! that misbehave: the index and every patch equal the local file's, a remote render
//! equals the local one pixel for pixel, and faults give clear errors, never panics.

mod common;

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener};
use std::sync::Arc;

use common::{build, Served};

use tessera_format::{Model, PatchReader, HEADER_BYTES};
use tessera_http::{RemoteModel, PREFIX_BYTES};
use tessera_render::{Mode, Viewer, ViewerOptions};
use tessera_select::{Camera, Orbit};

fn cameras(m: &Model) -> Vec<Camera> {
    let b = m.header().bounding_sphere;
    (0..3)
        .map(|i| {
            Camera::orbit(&Orbit {
                center: [b[0], b[1], b[2]],
                radius: b[3] * (1.3 + 0.6 * i as f64),
                azimuth_deg: 50.0 * i as f64,
                elevation_deg: 15.0,
                width: 320,
                height: 240,
                ..Orbit::default()
            })
            .unwrap()
        })
        .collect()
}

#[test]
fn remote_index_and_patches_equal_the_local_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = build(dir.path(), "s.tsr", 30_000, 3);
    let local = Model::open(&path).unwrap();
    let served = Served::start(&[path.clone()]);
    let remote = RemoteModel::open(&served.url("s.tsr")).expect("remote open");
    // The index: one request when header + table fit the first PREFIX_BYTES.
    let index_bytes = local.header().index_bytes();
    let opened = remote.source().bytes_fetched();
    eprintln!(
        "opened with {} request(s), {opened} bytes (index {index_bytes} bytes, file {})",
        remote.source().requests(),
        local.header().file_bytes
    );
    assert!(opened <= PREFIX_BYTES.max(index_bytes + HEADER_BYTES));
    if index_bytes <= PREFIX_BYTES {
        assert_eq!(remote.source().requests(), 1);
    }
    assert_eq!(
        bytemuck_header(remote.index().header()),
        bytemuck_header(local.header())
    );
    assert_eq!(remote.index().nodes(), local.nodes());
    for i in 0..local.nodes().len() {
        assert_eq!(
            remote.decode_patch(i).unwrap(),
            local.decode_patch(i).unwrap(),
            "node {i}"
        );
    }
}

fn bytemuck_header(h: &tessera_format::Header) -> Vec<u8> {
    // Header is Pod; compare its bytes (it has float fields).
    let p = h as *const tessera_format::Header as *const u8;
    // SAFETY: Header is #[repr(C)] Pod of HEADER_BYTES bytes.
    unsafe { std::slice::from_raw_parts(p, HEADER_BYTES as usize) }.to_vec()
}

#[test]
fn remote_render_equals_local_pixel_for_pixel() {
    let dir = tempfile::tempdir().unwrap();
    let path = build(dir.path(), "r.tsr", 30_000, 5);
    let local: Arc<Model> = Arc::new(Model::open(&path).unwrap());
    let served = Served::start(&[path.clone()]);
    let remote = Arc::new(RemoteModel::open(&served.url("r.tsr")).unwrap());
    let opts = ViewerOptions {
        mode: Mode::Complete,
        tolerance_px: 0.7,
        ..Default::default()
    };
    let mut a = Viewer::new(local.clone(), opts.clone()).expect("viewer (lavapipe?)");
    let mut b = Viewer::new(remote.clone(), opts).expect("viewer");
    for (i, cam) in cameras(&local).iter().enumerate() {
        let sa = a.render(cam).unwrap();
        let sb = b.render(cam).unwrap();
        assert_eq!(sa.triangles, sb.triangles, "camera {i}");
        assert!(
            sa.triangles > 2_000,
            "camera {i}: cut too coarse ({})",
            sa.triangles
        );
        let (ia, ib) = (a.read_image().unwrap(), b.read_image().unwrap());
        assert!(
            ia.rgba == ib.rgba,
            "camera {i}: remote frame differs from the local one"
        );
    }
    let (requests, patches) = (remote.source().requests(), remote.patches_read());
    eprintln!(
        "remote render: {requests} requests for {patches} patches, {} bytes of a {}-byte file",
        remote.source().bytes_fetched(),
        local.header().file_bytes
    );
    // Coalescing: siblings are adjacent in the file and come with one request.
    assert!(
        requests * 2 <= patches,
        "{requests} requests for {patches} patches: adjacent patches not coalesced"
    );
}

/// A one-shot HTTP server thread answering every request with `respond(request)`.
fn fake_server(respond: impl Fn(&str) -> Vec<u8> + Send + 'static) -> SocketAddr {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = l.local_addr().unwrap();
    std::thread::spawn(move || {
        for s in l.incoming().take(16) {
            let Ok(mut s) = s else { continue };
            let mut buf = vec![0u8; 8192];
            let mut got = 0;
            while got < buf.len() {
                match s.read(&mut buf[got..]) {
                    Ok(0) | Err(_) => break,
                    Ok(n) => got += n,
                }
                if buf[..got].windows(4).any(|w| w == b"\r\n\r\n") {
                    break;
                }
            }
            let req = String::from_utf8_lossy(&buf[..got]).to_string();
            let _ = s.write_all(&respond(&req));
        }
    });
    addr
}

#[test]
fn faults_give_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = build(dir.path(), "f.tsr", 10_000, 9);
    let bytes = std::fs::read(&path).unwrap();

    // A server that ignores Range and sends the whole file with 200.
    let whole = bytes.clone();
    let addr = fake_server(move |_| {
        let mut r = format!(
            "HTTP/1.1 200 OK\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
            whole.len()
        )
        .into_bytes();
        r.extend_from_slice(&whole);
        r
    });
    let e = RemoteModel::open(&format!("http://{addr}/f.tsr"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("ignores HTTP range requests"), "{e}");

    // A truncated 206: fewer body bytes than announced, every time.
    let addr = fake_server(move |_| {
        b"HTTP/1.1 206 Partial Content\r\nContent-Range: bytes 0-65535/70000\r\nContent-Length: 65536\r\nConnection: close\r\n\r\nshort".to_vec()
    });
    let e = RemoteModel::open(&format!("http://{addr}/f.tsr"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("attempts"), "{e}");

    // Nothing listening.
    let free = TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let e = RemoteModel::open(&format!("http://{free}/f.tsr"))
        .unwrap_err()
        .to_string();
    assert!(e.contains(&free.to_string()), "{e}");

    // A name the server does not serve; https; a file that is not a model.
    let junk = dir.path().join("junk.bin");
    std::fs::write(&junk, vec![7u8; 5000]).unwrap();
    let served = Served::start(&[path.clone()]);
    let e = RemoteModel::open(&served.url("nope.tsr"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("not found"), "{e}");
    let e = RemoteModel::open("https://127.0.0.1:1/x.tsr")
        .unwrap_err()
        .to_string();
    assert!(e.contains("https"), "{e}");
    let raw = fake_server(move |_| {
        b"HTTP/1.1 206 Partial Content\r\nContent-Range: bytes 0-4999/5000\r\nContent-Length: 5000\r\nConnection: close\r\n\r\n"
            .iter()
            .copied()
            .chain(std::iter::repeat_n(7u8, 5000))
            .collect()
    });
    let e = RemoteModel::open(&format!("http://{raw}/junk.bin"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("not a Tessera model"), "{e}");

    // The model replaced on the server after opening: reads fail cleanly, naming it.
    let remote = RemoteModel::open(&served.url("f.tsr")).unwrap();
    let other = build(dir.path(), "g.tsr", 12_000, 11);
    let tmp = dir.path().join(".f.tsr.swap");
    std::fs::copy(&other, &tmp).unwrap();
    std::fs::rename(&tmp, &path).unwrap();
    let last = remote.index().nodes().len() - 1;
    let e = remote.decode_patch(last).unwrap_err().to_string();
    assert!(e.contains("changed on the server"), "{e}");
}
