//! Network-aware paging of a remote model, through a real `tessera serve` behind a
//! counting, fault-injecting proxy (`common::Proxy`): coalesced and bounded requests,
//! wants the view dropped not fetched, and faults (connection reset, truncated body, a
//! `200` with the whole file, the server killed mid-stream) survived: frames go on with
//! what is resident, the outage is reported once, and everything loads once the server
//! is back, to the same image as the local model.

mod common;

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use common::{build, Fault, Proxy, Served};
use tessera_format::{Model, PatchReader};
use tessera_http::{RemoteModel, MAX_IN_FLIGHT, PREFIX_BYTES};
use tessera_page::{Pager, PagerOptions};
use tessera_render::{FrameStats, Mode, Viewer, ViewerOptions};
use tessera_select::{Camera, Orbit};
use tessera_stream::Answer;
use tracing_subscriber::layer::SubscriberExt;

fn camera(m: &dyn PatchReader) -> Camera {
    let b = m.index().header().bounding_sphere;
    Camera::orbit(&Orbit {
        center: [b[0], b[1], b[2]],
        radius: b[3] * 1.4,
        azimuth_deg: 30.0,
        elevation_deg: 20.0,
        width: 320,
        height: 240,
        ..Orbit::default()
    })
    .unwrap()
}

fn progressive(model: Arc<dyn PatchReader>, loaders: usize) -> Viewer {
    let opts = ViewerOptions {
        mode: Mode::Progressive,
        tolerance_px: 0.7,
        loader_threads: loaders,
        ..Default::default()
    };
    Viewer::new(model, opts).expect("viewer (lavapipe?)")
}

/// One progressive frame, which must not wait for the network.
fn frame(v: &mut Viewer, cam: &Camera) -> FrameStats {
    let t = Instant::now();
    let s = v.render(cam).unwrap();
    let took = t.elapsed();
    assert!(took < Duration::from_secs(3), "a frame took {took:?}");
    assert!(s.triangles > 0, "nothing drawn");
    s
}

/// Frames until nothing is pending or failed and the draw set stopped changing.
fn settle(v: &mut Viewer, cam: &Camera, limit: Duration) -> FrameStats {
    let start = Instant::now();
    let mut stable = 0;
    let mut last: Vec<u32> = Vec::new();
    loop {
        let s = frame(v, cam);
        let draw = v.scheduler().draw().to_vec();
        // No group blending in either (groups below one wait for it, the draw set
        // unchanged meanwhile).
        let quiet = s.pending_loads == 0
            && s.failed_patches == 0
            && s.patches_uploaded == 0
            && s.morph_blending == 0;
        stable = if quiet && draw == last { stable + 1 } else { 0 };
        last = draw;
        if stable >= 3 {
            return s;
        }
        assert!(
            start.elapsed() < limit,
            "not settled after {limit:?}: {s:?}"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn progressive_remote_render_is_coalesced_bounded_and_equals_local() {
    let dir = tempfile::tempdir().unwrap();
    let path = build(dir.path(), "p.tsr", 40_000, 21);
    let served = Served::start(&[path.clone()]);
    let proxy = Proxy::start(served.addr);
    proxy.set_delay(Duration::from_millis(20));
    let local: Arc<dyn PatchReader> = Arc::new(Model::open(&path).unwrap());
    let remote = Arc::new(RemoteModel::open(&proxy.url("p.tsr")).unwrap());
    let cam = camera(local.as_ref());
    let mut a = progressive(local, 1);
    // More loader threads than the source lets run: the bound holds.
    let mut b = progressive(remote.clone(), 6);
    let sa = settle(&mut a, &cam, Duration::from_secs(60));
    let sb = settle(&mut b, &cam, Duration::from_secs(60));
    assert_eq!(sa.triangles, sb.triangles);
    assert!(a.read_image().unwrap().rgba == b.read_image().unwrap().rgba);
    let (requests, patches) = (proxy.requests(), remote.patches_read());
    eprintln!(
        "progressive remote render: {requests} requests for {patches} patches, at most {} in flight",
        proxy.max_in_flight()
    );
    assert!(patches > 20, "{patches} patches: cut too coarse");
    assert!(
        requests * 2 <= patches,
        "{requests} requests for {patches} patches: not coalesced"
    );
    assert!(proxy.max_in_flight() as usize <= MAX_IN_FLIGHT);
    assert!(proxy.max_in_flight() >= 2, "requests never overlapped");
}

#[test]
fn wants_the_view_dropped_are_not_fetched() {
    let dir = tempfile::tempdir().unwrap();
    let path = build(dir.path(), "d.tsr", 40_000, 22);
    let served = Served::start(&[path.clone()]);
    let proxy = Proxy::start(served.addr);
    let remote = Arc::new(RemoteModel::open(&proxy.url("d.tsr")).unwrap());
    let opened = proxy.requests();
    proxy.set_delay(Duration::from_millis(150));
    let n = remote.index().nodes().len() as u32;
    let pager = Pager::new(remote.clone(), PagerOptions::default());
    // Every other node past the first request's prefix (no two adjacent: one request
    // each), then the view moves on and wants only the last node.
    let far = |i: &u32| remote.index().patch_range(*i as usize).unwrap().start >= PREFIX_BYTES;
    let wanted: Vec<(u32, f32)> = (0..n).filter(far).step_by(2).map(|i| (i, 1.0)).collect();
    assert!(wanted.len() > 20, "{} nodes wanted", wanted.len());
    pager.request(&wanted);
    let start = Instant::now();
    let mut got = Vec::new();
    while got.is_empty() {
        assert!(start.elapsed() < Duration::from_secs(20));
        got = pager.poll();
        std::thread::sleep(Duration::from_millis(5));
    }
    let last = n - 1;
    pager.request(&[(last, 5.0)]);
    while !got.iter().any(|a| a.node() == last) {
        assert!(start.elapsed() < Duration::from_secs(20));
        got.extend(pager.poll());
        std::thread::sleep(Duration::from_millis(5));
    }
    let (read, requests) = (remote.patches_read(), proxy.requests() - opened);
    eprintln!(
        "asked for {} nodes, then 1: {read} patches read, {requests} requests",
        wanted.len()
    );
    assert!(read <= 4, "{read} patches read: dropped wants were fetched");
    assert!(
        requests <= 4,
        "{requests} requests: dropped wants were fetched"
    );
    assert!(got.iter().all(|a| matches!(a, Answer::Loaded { .. })));
}

/// Counts WARN events of the current thread (the scheduler reports on the frame thread).
#[derive(Clone, Default)]
struct Warnings(Arc<Mutex<Vec<String>>>);

impl<S: tracing::Subscriber> tracing_subscriber::Layer<S> for Warnings {
    fn on_event(&self, e: &tracing::Event<'_>, _: tracing_subscriber::layer::Context<'_, S>) {
        if *e.metadata().level() <= tracing::Level::WARN {
            let mut text = String::new();
            e.record(&mut |f: &tracing::field::Field, v: &dyn std::fmt::Debug| {
                text.push_str(&format!("{}={v:?} ", f.name()));
            });
            self.0.lock().unwrap().push(text);
        }
    }
}

#[test]
fn faults_are_survived_reported_once_and_recovered() {
    let warnings = Warnings::default();
    let _guard =
        tracing::subscriber::set_default(tracing_subscriber::registry().with(warnings.clone()));
    let dir = tempfile::tempdir().unwrap();
    let path = build(dir.path(), "f.tsr", 40_000, 23);
    let served = Served::start(&[path.clone()]);
    let server_addr = served.addr;
    let proxy = Proxy::start(server_addr);
    proxy.set_delay(Duration::from_millis(30));
    let local: Arc<dyn PatchReader> = Arc::new(Model::open(&path).unwrap());
    let remote = Arc::new(RemoteModel::open(&proxy.url("f.tsr")).unwrap());
    let cam = camera(local.as_ref());
    let mut v = progressive(remote.clone(), 2);
    let first = frame(&mut v, &cam);
    assert!(first.pending_loads > 0, "nothing left to stream: {first:?}");

    // Each fault in turn, until the client has seen it fail a read; frames go on.
    let mut served = Some(served);
    for fault in [Fault::Reset, Fault::Truncate, Fault::Whole, Fault::Pass] {
        if fault == Fault::Pass {
            // The server killed mid-stream (requests in flight), nothing listening.
            served.take().unwrap().kill();
        }
        proxy.set_fault(fault);
        let seen = proxy.requests_with(fault);
        let failed_before = frame(&mut v, &cam).failed_patches;
        let start = Instant::now();
        loop {
            let s = frame(&mut v, &cam);
            if proxy.requests_with(fault) > seen + 2 && s.failed_patches > failed_before {
                break;
            }
            assert!(
                start.elapsed() < Duration::from_secs(30),
                "{fault:?}: no failed read seen ({s:?})"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
    // The server is back on the same address: every node loads, to the local image.
    let _served = Served::start_at(&[path.clone()], server_addr);
    let s = settle(&mut v, &cam, Duration::from_secs(90));
    let mut l = progressive(local, 1);
    let sl = settle(&mut l, &cam, Duration::from_secs(60));
    assert_eq!(s.triangles, sl.triangles);
    assert!(v.read_image().unwrap().rgba == l.read_image().unwrap().rgba);
    let w = warnings.0.lock().unwrap();
    eprintln!("warnings: {w:?}; {} requests", proxy.requests());
    assert_eq!(w.len(), 1, "the outage should be reported once: {w:?}");
    assert!(w[0].contains("unavailable"), "{w:?}");
}
