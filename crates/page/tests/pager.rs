//! End-to-end pager tests on a real model file built in a temp dir.

use std::path::Path;
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use tessera_format::Model;
use tessera_page::{Pager, PagerOptions};
use tessera_stream::{Answer, PatchSource};

/// Builds the shared test model once per test binary.
fn model_path() -> &'static Path {
    static MODEL: OnceLock<tessera_testkit::TestModel> = OnceLock::new();
    &MODEL
        .get_or_init(|| {
            tessera_testkit::build_model(
                None,
                &tessera_gen::SphereOptions {
                    triangles: 50_000,
                    ..Default::default()
                },
                &tessera_build::BuildOptions {
                    leaf_triangles: 400,
                    node_triangles: 200,
                    ..Default::default()
                },
            )
        })
        .path
}

fn open() -> Arc<Model> {
    Arc::new(Model::open(model_path()).unwrap())
}

/// Polls until `done(events so far)` or a 60 s timeout; returns all events.
fn wait(p: &Pager, mut done: impl FnMut(&[Answer]) -> bool) -> Vec<Answer> {
    let start = Instant::now();
    let mut all = Vec::new();
    loop {
        all.extend(p.poll());
        if done(&all) {
            return all;
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "timed out; events {all:?}"
        );
        std::thread::sleep(Duration::from_millis(1));
    }
}

fn all_nodes(m: &Model) -> Vec<u32> {
    (0..m.nodes().len() as u32).collect()
}

#[test]
fn loads_everything_and_matches_decode() {
    let m = open();
    let n = m.nodes().len();
    assert!(n > 10, "model too small: {n} nodes");
    let p = Pager::new(
        m.clone(),
        PagerOptions {
            threads: 2,
            ..Default::default()
        },
    );
    let wanted: Vec<(u32, f32)> = all_nodes(&m).into_iter().map(|i| (i, 1.0)).collect();
    p.request(&wanted);
    let ev = wait(&p, |e| e.len() == n);
    let mut seen = vec![false; n];
    for a in &ev {
        let Answer::Loaded { node, patch } = a else {
            panic!("unexpected {a:?}");
        };
        assert!(!seen[*node as usize], "node {node} answered twice");
        seen[*node as usize] = true;
        assert_eq!(
            **patch,
            m.decode_patch(*node as usize).unwrap(),
            "node {node}"
        );
    }
    let s = p.stats();
    assert_eq!(
        (s.loads, s.failures, s.queued, s.in_flight),
        (n as u64, 0, 0, 0)
    );
    // Blocking reads answer in the order asked, with the same patches.
    let order: Vec<u32> = (0..n as u32).rev().collect();
    let now = p.read_blocking(&order);
    for (a, &want) in now.iter().zip(&order) {
        let Answer::Loaded { node, patch } = a else {
            panic!("unexpected {a:?}");
        };
        assert_eq!(*node, want);
        assert_eq!(**patch, m.decode_patch(want as usize).unwrap());
    }
    assert!(matches!(
        p.read_blocking(&[u32::MAX])[0],
        Answer::Failed { .. }
    ));
}

#[test]
fn higher_priority_loads_first() {
    let m = open();
    let p = Pager::new(
        m.clone(),
        PagerOptions {
            read_delay: Some(Duration::from_millis(20)),
            ..Default::default()
        },
    );
    // Priorities deliberately not in node order; duplicates ignored.
    let wanted = [
        (3u32, 0.5f32),
        (7, 9.0),
        (1, 2.0),
        (5, -1.0),
        (2, 4.0),
        (7, 0.0),
    ];
    p.request(&wanted);
    let ev = wait(&p, |e| e.len() == 5);
    let order: Vec<u32> = ev
        .iter()
        .map(|e| match e {
            Answer::Loaded { node, .. } => *node,
            other => panic!("unexpected {other:?}"),
        })
        .collect();
    assert_eq!(order, vec![7, 2, 1, 3, 5]);
}

#[test]
fn frame_never_waits_on_slow_disk() {
    let m = open();
    let n = m.nodes().len() as u32;
    let p = Pager::new(
        m.clone(),
        PagerOptions {
            read_delay: Some(Duration::from_millis(200)),
            ..Default::default()
        },
    );
    let wanted: Vec<(u32, f32)> = (0..n.min(4)).map(|i| (i, 1.0)).collect();
    let limit = Duration::from_millis(5);
    let mut worst = Duration::ZERO;
    let mut loaded = 0;
    let start = Instant::now();
    // Simulated frames: request, get everything wanted, poll.
    while loaded < wanted.len() {
        assert!(start.elapsed() < Duration::from_secs(30));
        let t = Instant::now();
        p.request(&wanted);
        worst = worst.max(t.elapsed());
        let t = Instant::now();
        let _ = PatchSource::pending(&p);
        worst = worst.max(t.elapsed());
        let t = Instant::now();
        loaded += p.poll().len();
        worst = worst.max(t.elapsed());
        std::thread::sleep(Duration::from_millis(2));
    }
    assert!(worst < limit, "a frame call took {worst:?}");
    // Loads trickled in: 4 x 200 ms on one thread.
    assert!(start.elapsed() >= Duration::from_millis(700));
}

#[test]
fn corrupt_patch_fails_once_others_load() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.tsr");
    let good = Model::open(model_path()).unwrap();
    let n = good.nodes().len();
    let bad = (n / 2) as u32;
    let rec = good.nodes()[bad as usize];
    assert!(rec.patch_bytes > 0);
    let mut bytes = std::fs::read(model_path()).unwrap();
    let at = rec.patch_offset as usize + rec.patch_bytes as usize / 2;
    bytes[at] ^= 0x5a;
    std::fs::write(&path, &bytes).unwrap();
    drop(good);

    let m = Arc::new(Model::open(&path).unwrap());
    let p = Pager::new(
        m.clone(),
        PagerOptions {
            threads: 2,
            ..Default::default()
        },
    );
    let wanted: Vec<(u32, f32)> = (0..n as u32).map(|i| (i, 1.0)).collect();
    p.request(&wanted);
    let ev = wait(&p, |e| e.len() == n);
    let failed: Vec<&Answer> = ev
        .iter()
        .filter(|e| matches!(e, Answer::Failed { .. }))
        .collect();
    assert_eq!(failed.len(), 1, "{failed:?}");
    assert!(matches!(failed[0], Answer::Failed { node, .. } if *node == bad));
    assert_eq!(ev.len(), n);
    // Asking again for the failed node does not retry it.
    p.request(&[(bad, 1.0)]);
    assert_eq!(p.stats().queued, 0);
    std::thread::sleep(Duration::from_millis(50));
    assert!(p.poll().is_empty());
    assert_eq!(p.stats().failures, 1);
}

#[test]
fn drop_with_pending_work_is_prompt() {
    let m = open();
    let n = m.nodes().len() as u32;
    let p = Pager::new(
        m,
        PagerOptions {
            read_delay: Some(Duration::from_millis(200)),
            threads: 2,
            ..Default::default()
        },
    );
    p.request(&(0..n).map(|i| (i, 1.0)).collect::<Vec<_>>());
    std::thread::sleep(Duration::from_millis(30)); // loaders are inside the delay now
    assert!(p.stats().queued > 0);
    let t = Instant::now();
    drop(p);
    assert!(
        t.elapsed() < Duration::from_millis(100),
        "drop took {:?}",
        t.elapsed()
    );
}

#[test]
fn advise_is_cheap_and_harmless() {
    let m = open();
    let n = m.nodes().len() as u32;
    let p = Pager::new(m, PagerOptions::default());
    let all: Vec<u32> = (0..n).chain([u32::MAX]).collect();
    let t = Instant::now();
    p.advise(&all);
    assert!(t.elapsed() < Duration::from_millis(50));
    assert!(p.poll().is_empty());
    assert_eq!(p.stats().loads, 0);
}
