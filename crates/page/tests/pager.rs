//! End-to-end pager tests on a real model file built in a temp dir.

use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use tessera_format::Model;
use tessera_page::{cache::decoded_bytes, Event, Pager, PagerOptions};

/// Builds the shared test model once per test binary.
fn model_path() -> &'static Path {
    static DIR: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    &DIR.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let ply = dir.path().join("sphere.ply");
        let tsr = dir.path().join("sphere.tsr");
        tessera_gen::write_sphere(
            &ply,
            &tessera_gen::SphereOptions {
                triangles: 50_000,
                ..Default::default()
            },
        )
        .unwrap();
        tessera_build::build(
            &ply,
            &tsr,
            &tessera_build::BuildOptions {
                leaf_triangles: 400,
                node_triangles: 200,
                ..Default::default()
            },
            &tessera_build::NoProgress,
        )
        .unwrap();
        (dir, tsr)
    })
    .1
}

fn open() -> Arc<Model> {
    Arc::new(Model::open(model_path()).unwrap())
}

/// Polls until `done(events so far)` or a 60 s timeout; returns all events.
fn wait(p: &Pager, mut done: impl FnMut(&[Event]) -> bool) -> Vec<Event> {
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
    assert!(ev.iter().all(|e| matches!(e, Event::Loaded { .. })));
    for i in 0..n as u32 {
        let got = p.get(i).expect("resident");
        let want = m.decode_patch(i as usize).unwrap();
        assert_eq!(*got, want, "node {i}");
        assert!(ev.contains(&Event::Loaded {
            node: i,
            bytes: decoded_bytes(&want)
        }));
    }
    let s = p.stats();
    assert_eq!(s.resident_patches, n);
    assert_eq!(s.loads, n as u64);
    assert_eq!(
        (s.hits, s.misses, s.evictions, s.failures, s.pending),
        (n as u64, 0, 0, 0, 0)
    );
    // Re-requesting resident nodes queues nothing.
    p.request(&wanted);
    assert_eq!(p.stats().pending, 0);
    assert!(p.get(u32::MAX).is_none());
    assert_eq!(p.stats().misses, 1);
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
            Event::Loaded { node, .. } => *node,
            other => panic!("unexpected {other:?}"),
        })
        .collect();
    assert_eq!(order, vec![7, 2, 1, 3, 5]);
}

#[test]
fn budget_respected_and_pins_kept() {
    let m = open();
    let n = m.nodes().len();
    let sizes: Vec<u64> = (0..n)
        .map(|i| decoded_bytes(&m.decode_patch(i).unwrap()))
        .collect();
    let total: u64 = sizes.iter().sum();
    let largest = *sizes.iter().max().unwrap();
    let budget = total / 3;
    let p = Pager::new(
        m.clone(),
        PagerOptions {
            ram_budget_bytes: budget,
            threads: 2,
            ..Default::default()
        },
    );
    // Load a small pinned set first.
    let mut pinned = Vec::new();
    let mut acc = 0;
    for i in 0..n as u32 {
        if acc + sizes[i as usize] > budget / 4 {
            break;
        }
        acc += sizes[i as usize];
        pinned.push(i);
    }
    assert!(!pinned.is_empty());
    p.request(&pinned.iter().map(|&i| (i, 1.0)).collect::<Vec<_>>());
    wait(&p, |e| e.len() == pinned.len());
    p.pin(&pinned);
    // Then everything else, checking the budget as loads come in.
    let rest: Vec<(u32, f32)> = (0..n as u32)
        .filter(|i| !pinned.contains(i))
        .map(|i| (i, i as f32))
        .collect();
    p.request(&rest);
    let mut seen = 0;
    wait(&p, |e| {
        seen = e.len();
        let s = p.stats();
        assert!(
            s.resident_bytes <= budget + largest,
            "{s:?} budget {budget}"
        );
        seen == rest.len()
    });
    let s = p.stats();
    assert!(s.evictions > 0, "{s:?}");
    assert!(s.resident_bytes <= budget + largest);
    assert_eq!(s.loads, n as u64);
    for &i in &pinned {
        assert!(p.is_resident(i), "pinned node {i} was evicted");
    }
    // Unpinning lets them go under pressure: request the evicted ones again.
    p.pin(&[]);
    let evicted: Vec<(u32, f32)> = (0..n as u32)
        .filter(|&i| !p.is_resident(i))
        .map(|i| (i, 1.0))
        .collect();
    p.request(&evicted);
    wait(&p, |e| e.len() == evicted.len());
    assert!(p.stats().resident_bytes <= budget + largest);
    assert!(pinned.iter().any(|&i| !p.is_resident(i)));
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
        for &(i, _) in &wanted {
            let t = Instant::now();
            let _ = p.get(i);
            worst = worst.max(t.elapsed());
        }
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
    let failed: Vec<&Event> = ev
        .iter()
        .filter(|e| matches!(e, Event::Failed { .. }))
        .collect();
    assert_eq!(failed.len(), 1, "{failed:?}");
    assert!(matches!(failed[0], Event::Failed { node, .. } if *node == bad));
    assert!(!p.is_resident(bad));
    assert!(p.get(bad).is_none());
    for i in (0..n as u32).filter(|&i| i != bad) {
        assert!(p.is_resident(i));
    }
    // Asking again does not retry it.
    p.request(&wanted);
    assert_eq!(p.stats().pending, 0);
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
    assert!(p.stats().pending > 0);
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
