//! A remote model opened with only the top of its paged index: the first frame reads a
//! few kilobytes of index, the index grows as the view asks for detail, and every cut
//! the scheduler reaches through the grown index equals the cut it reaches over the whole
//! index, read locally.

mod common;

use std::sync::Arc;
use std::time::Duration;

use tessera_format::{Model, PatchReader};
use tessera_http::RemoteModel;
use tessera_page::{Pager, PagerOptions};
use tessera_select::{Camera, Orbit};
use tessera_stream::{CountingStore as Counting, Scheduler, SchedulerOptions};

/// Frames of `camera` until nothing is pending; a paged remote index is grown (here,
/// at once, to keep the test deterministic) whenever the scheduler asks for it.
/// Returns the converged cut, sorted.
fn converge(
    sched: &mut Scheduler,
    pager: &mut Pager,
    store: &mut Counting,
    camera: &Camera,
    remote: Option<&RemoteModel>,
) -> Vec<u32> {
    for i in 0..4000 {
        // Time advances (60 frames a second): late groups blend in over 0.25 s.
        let s = sched.frame(camera, f64::from(i) / 60.0, pager, store);
        let mut grew = false;
        if let Some(r) = remote.filter(|_| s.index_wants > 0) {
            assert!(r.grow_index(), "asked for more index, but none came");
            sched.set_index(&r.latest_index().unwrap(), store);
            grew = true;
        }
        if !grew
            && s.pending_loads == 0
            && s.cache_misses == 0
            && s.patches_uploaded == 0
            && s.morph_blending == 0
        {
            let mut d = sched.draw().to_vec();
            d.sort_unstable();
            return d;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    panic!("did not converge");
}

#[test]
fn the_paged_index_reads_little_first_and_reaches_the_same_cuts() {
    let dir = tempfile::tempdir().unwrap();
    // Small index pages, so this small model has many and the index grows in steps.
    let path = common::build_paged(dir.path(), "m.tsr", 60_000, 7, 8);
    let local = Arc::new(Model::open(&path).unwrap());
    let h = *local.header();
    let nodes = local.nodes().len();
    assert!(h.page_count > 20, "{} pages", h.page_count);
    let served = common::Served::start(std::slice::from_ref(&path));
    let remote = Arc::new(RemoteModel::open_paged(&served.url("m.tsr")).unwrap());
    let top = remote.index();
    assert!(
        top.nodes().len() < nodes / 4,
        "{} of {nodes} shown",
        top.nodes().len()
    );
    assert!(top.nodes().len() >= h.root_count as usize);
    // The open read one prefix request: header, block table, directory and the top pages.
    let (opened, requests) = remote.transfer().unwrap();
    assert_eq!(requests, 1);
    println!(
        "paged open: {opened} bytes, {} of {nodes} nodes shown",
        top.nodes().len()
    );

    let opts = SchedulerOptions {
        tolerance_px: 1.0,
        store_budget_bytes: 1 << 30,
        ram_budget_bytes: 1 << 28,
        ..SchedulerOptions::default()
    };
    let mut full = Scheduler::new(local.index(), opts.clone());
    let mut paged = Scheduler::new(top, opts);
    let mut full_pager = Pager::new(local.clone(), PagerOptions::default());
    let mut paged_pager = Pager::new(remote.clone(), PagerOptions::default());
    let (mut full_store, mut paged_store) = (Counting::default(), Counting::default());
    let b = h.bounding_sphere;
    // From far to close, around the model: coarse cuts first, then ever more detail.
    for (k, dist) in [6.0, 3.0, 1.6, 1.15, 1.03].into_iter().enumerate() {
        let cam = Camera::orbit(&Orbit {
            center: [b[0], b[1], b[2]],
            radius: b[3] * dist,
            azimuth_deg: 40.0 * k as f64,
            elevation_deg: 20.0,
            width: 320,
            height: 240,
            ..Orbit::default()
        })
        .unwrap();
        let want = converge(&mut full, &mut full_pager, &mut full_store, &cam, None);
        let got = converge(
            &mut paged,
            &mut paged_pager,
            &mut paged_store,
            &cam,
            Some(&remote),
        );
        assert_eq!(got, want, "camera {k} at {dist} radii: the cuts differ");
        println!(
            "camera {k}: {} nodes drawn, index shows {} of {nodes}, {} bytes fetched",
            got.len(),
            paged.node_count(),
            remote.transfer().unwrap().0
        );
    }
    assert!(
        paged.node_count() > top.nodes().len(),
        "the index never grew"
    );
}
