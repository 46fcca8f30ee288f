//! The browser client's fetch plan, natively: the index read through a sparse byte
//! source equals the index read from the whole file; patches fetched in coalesced range
//! requests (at most 3 in flight, at most 16 patches / 512 KiB each) and answered out of
//! order stream a real model to the same converged cut as a source that answers at
//! once; failed requests come back as unavailable and are asked again.

use std::ops::Range;
use std::sync::Arc;

use tessera_format::ModelIndex;
use tessera_select::{Camera, Orbit};
use tessera_stream::{Answer, CountingStore, PatchSource, Scheduler, SchedulerOptions};
use tessera_web::plan::{
    parse_content_range, range_header, Attempt, Fetcher, Request, SparseBytes, COALESCE_MAX_BYTES,
    COALESCE_MAX_PATCHES, MAX_IN_FLIGHT, PREFIX_BYTES,
};

/// A generated sphere built with small nodes and small index pages (a deep tree whose
/// index is read in several steps).
fn model(dir: &std::path::Path) -> Vec<u8> {
    let ply = dir.join("s.ply");
    let tsr = dir.join("s.tsr");
    tessera_gen::write_sphere(
        &ply,
        &tessera_gen::SphereOptions {
            triangles: 60_000,
            ..Default::default()
        },
        &tessera_gen::NoProgress,
    )
    .unwrap();
    let opts = tessera_build::BuildOptions {
        leaf_triangles: 400,
        node_triangles: 200,
        index_page_nodes: 16,
        threads: Some(2),
        ..Default::default()
    };
    tessera_build::build(&ply, &tsr, &opts, &tessera_build::NoProgress).unwrap();
    std::fs::read(&tsr).unwrap()
}

/// Runs `f` over a sparse copy of `file`, fetching what it lacks; returns the result
/// and the ranges fetched.
fn read_sparse<T>(
    file: &[u8],
    sparse: &mut SparseBytes,
    f: impl Fn(&SparseBytes) -> Result<T, tessera_format::FormatError>,
) -> (T, Vec<Range<u64>>) {
    let mut fetched = Vec::new();
    loop {
        match sparse.attempt(&f) {
            Attempt::Done(v) => return (v, fetched),
            Attempt::Failed(e) => panic!("read failed: {e}"),
            Attempt::Need(r) => {
                assert!(fetched.len() < 16, "too many reads: {fetched:?}");
                sparse.insert(r.start, file[r.start as usize..r.end as usize].to_vec());
                fetched.push(r);
            }
        }
    }
}

#[test]
fn content_range_and_range_headers() {
    assert_eq!(
        parse_content_range("bytes 0-65535/1000000"),
        Some((Some((0, 65535)), 1000000))
    );
    assert_eq!(parse_content_range("bytes */42"), Some((None, 42)));
    assert_eq!(parse_content_range("items 0-1/2"), None);
    assert_eq!(range_header(&(10..20)), "bytes=10-19");
}

#[test]
fn index_read_through_sparse_bytes_equals_the_whole_file_s() {
    let dir = tempfile::tempdir().unwrap();
    let file = model(dir.path());
    let whole = ModelIndex::read(file.as_slice()).unwrap();
    let top_direct = ModelIndex::read_top(file.as_slice(), 1).unwrap();

    let mut sparse = SparseBytes::new(file.len() as u64);
    let prefix = (PREFIX_BYTES as usize).min(file.len());
    sparse.insert(0, file[..prefix].to_vec());
    let (top, fetched) = read_sparse(&file, &mut sparse, |s| ModelIndex::read_top(s, 1));
    assert_eq!(top.nodes(), top_direct.nodes());
    assert!(top.nodes().len() < whole.nodes().len(), "the top is a part");
    eprintln!(
        "top: {} of {} nodes, {} extra reads after the {prefix}-byte prefix",
        top.nodes().len(),
        whole.nodes().len(),
        fetched.len()
    );
    // Grown page by page (doubling) to the whole index.
    let mut ix = top;
    let mut steps = 0;
    while !ix.is_complete() {
        let pages = 2 * ix.loaded_pages();
        let (next, _) = read_sparse(&file, &mut sparse, |s| ix.grown(s, pages));
        assert!(next.nodes().len() >= ix.nodes().len());
        ix = next;
        steps += 1;
        assert!(steps < 40);
    }
    assert_eq!(ix.nodes(), whole.nodes());

    // A real error (not missing bytes) is reported as such.
    let mut bad = file.clone();
    bad[0] ^= 0xff;
    let mut sparse = SparseBytes::new(bad.len() as u64);
    sparse.insert(0, bad[..prefix].to_vec());
    match sparse.attempt(|s| ModelIndex::read_top(s, 1)) {
        Attempt::Failed(e) => assert!(e.to_string().contains("magic"), "{e}"),
        other => panic!("expected a failure, got {other:?}"),
    }
}

/// The fetcher as the scheduler's source, with a fake transport that answers requests
/// in reverse order one frame later, failing every `fail_every`-th.
struct Fake<'a> {
    file: &'a [u8],
    fetcher: Fetcher,
    in_flight: Vec<Request>,
    sent: Vec<Request>,
    fail_every: u64,
    /// Decode workers: fetched patches go out as jobs and come back one poll later,
    /// in reverse order; the `worker_dies_every`-th job's worker dies (its job given
    /// back, everything decoded here from then on, as the viewer does).
    workers: bool,
    jobs: Vec<(u32, Vec<u8>)>,
    worker_dies_every: usize,
    jobs_run: usize,
    /// Polls a request stays in flight before its answer comes (0: the next poll), and
    /// each request's age.
    latency_polls: u32,
    ages: Vec<u32>,
    /// Requests aborted (cancelled by the fetcher while in flight).
    aborted: Vec<Request>,
}

impl<'a> Fake<'a> {
    /// Failing every `fail_every`-th request (0: none); with decode workers when
    /// `worker_dies_every` is given (0: they never die).
    fn new(
        file: &'a [u8],
        index: &Arc<ModelIndex>,
        fail_every: u64,
        worker_dies_every: Option<usize>,
    ) -> Fake<'a> {
        Fake {
            file,
            fetcher: Fetcher::new(index.clone()),
            in_flight: Vec::new(),
            sent: Vec::new(),
            fail_every,
            workers: worker_dies_every.is_some(),
            jobs: Vec::new(),
            worker_dies_every: worker_dies_every.unwrap_or(0),
            jobs_run: 0,
            latency_polls: 0,
            ages: Vec::new(),
            aborted: Vec::new(),
        }
    }

    fn pump(&mut self) {
        while let Some(r) = self.fetcher.next_request() {
            assert!(self.fetcher.in_flight() <= MAX_IN_FLIGHT);
            self.sent.push(r.clone());
            self.in_flight.push(r);
            self.ages.push(0);
        }
    }
    fn deliver(&mut self) {
        for a in &mut self.ages {
            *a += 1;
        }
        // Answered newest first (out of order), once old enough.
        let mut due = Vec::new();
        for i in (0..self.in_flight.len()).rev() {
            if self.ages[i] > self.latency_polls {
                self.ages.remove(i);
                due.push(self.in_flight.remove(i));
            }
        }
        for r in due {
            let body = if self.fail_every > 0 && r.id % self.fail_every == self.fail_every - 1 {
                Err("connection reset".to_string())
            } else {
                Ok(self.file[r.range.start as usize..r.range.end as usize].to_vec())
            };
            self.fetcher.complete(r.id, body);
        }
    }
}

impl PatchSource for Fake<'_> {
    fn request(&mut self, wanted: &[(u32, f32)]) {
        self.fetcher.set_wanted(wanted);
        // As the viewer: abort what the fetcher cancels.
        for id in self.fetcher.take_cancelled() {
            let i = self
                .in_flight
                .iter()
                .position(|r| r.id == id)
                .expect("a cancelled request is in flight");
            self.ages.remove(i);
            self.aborted.push(self.in_flight.remove(i));
        }
        self.pump();
    }
    fn poll(&mut self, out: &mut Vec<Answer>) {
        self.deliver();
        if self.workers {
            // As the viewer: while the workers run, nothing is decoded here; once one
            // dies, its job and everything after are.
            while let Some((node, job)) = self.jobs.pop() {
                self.jobs_run += 1;
                if self.worker_dies_every > 0 && self.jobs_run % self.worker_dies_every == 0 {
                    self.fetcher.requeue(node, job);
                    self.workers = false;
                    continue;
                }
                let reply = tessera_web::wire::run_job(&job, |_, _, _| Vec::new(), || 0.0);
                let (answer, ms) = tessera_web::wire::read_reply(node, &reply[..]).unwrap();
                self.fetcher.deliver(answer, ms, 0.0);
            }
        }
        if self.workers {
            let jobs = self.fetcher.take_jobs(8, 64 << 20, true, Some(4096));
            self.jobs.extend(jobs);
            self.fetcher.drain_settled(out);
        } else {
            self.fetcher.drain(out, 1e9, || 0.0);
        }
        self.pump();
    }
    fn pending(&self) -> usize {
        self.fetcher.pending()
    }
}

/// A source answering every request at the next poll from the bytes.
struct Direct<'a> {
    index: &'a ModelIndex,
    file: &'a [u8],
    wanted: Vec<u32>,
}

impl PatchSource for Direct<'_> {
    fn request(&mut self, wanted: &[(u32, f32)]) {
        self.wanted = wanted.iter().map(|w| w.0).collect();
    }
    fn poll(&mut self, out: &mut Vec<Answer>) {
        for n in self.wanted.drain(..) {
            out.push(Answer::from_result(
                n,
                self.index.read_patch(self.file, n as usize),
            ));
        }
    }
    fn pending(&self) -> usize {
        self.wanted.len()
    }
}

fn camera(index: &ModelIndex) -> Camera {
    camera_at(index, 30.0, 1.6)
}

fn camera_at(index: &ModelIndex, azimuth_deg: f64, radii: f64) -> Camera {
    let b = index.header().bounding_sphere;
    Camera::orbit(&Orbit {
        center: [b[0], b[1], b[2]],
        radius: b[3] * radii,
        azimuth_deg,
        elevation_deg: 20.0,
        width: 640,
        height: 480,
        ..Orbit::default()
    })
    .unwrap()
}

/// The cut a source answering at once converges to, and the frames it takes.
fn direct_cut(index: &ModelIndex, file: &[u8]) -> (Vec<u32>, u32) {
    converge(
        index,
        &mut Direct {
            index,
            file,
            wanted: Vec::new(),
        },
    )
}

fn converge<S: PatchSource>(index: &ModelIndex, src: &mut S) -> (Vec<u32>, u32) {
    converge_at(index, src, &camera(index))
}

fn converge_at<S: PatchSource>(index: &ModelIndex, src: &mut S, cam: &Camera) -> (Vec<u32>, u32) {
    let mut sched = Scheduler::new(
        index,
        SchedulerOptions {
            prefetch: false,
            clock: || 0.0,
            ..Default::default()
        },
    );
    let mut store = CountingStore::default();
    for f in 0..400u32 {
        let st = sched.frame(cam, f as f64 / 60.0, src, &mut store);
        if f > 2 && st.pending_loads == 0 && st.cache_misses == 0 {
            let mut d = sched.draw().to_vec();
            d.sort_unstable();
            return (d, f);
        }
    }
    panic!("did not converge in 400 frames");
}

#[test]
fn coalesced_out_of_order_fetches_converge_to_the_direct_cut() {
    let dir = tempfile::tempdir().unwrap();
    let file = model(dir.path());
    let index = Arc::new(ModelIndex::read(file.as_slice()).unwrap());

    let (direct, direct_frames) = direct_cut(&index, &file);
    let mut fake = Fake::new(&file, &index, 0, None);
    let (fetched, frames) = converge(&index, &mut fake);
    assert_eq!(fetched, direct, "the fetched cut differs");
    assert!(direct.len() > 50, "a deep cut: {} nodes", direct.len());
    let sent = &fake.sent;
    let patches: usize = sent.iter().map(|r| r.nodes.len()).sum();
    for r in sent {
        assert!(r.nodes.len() <= COALESCE_MAX_PATCHES);
        assert!(r.nodes.len() == 1 || r.range.end - r.range.start <= COALESCE_MAX_BYTES);
        // The range covers exactly its nodes' patches, first to last.
        let first = index.patch_range(r.nodes[0] as usize).unwrap();
        let last = index
            .patch_range(*r.nodes.last().unwrap() as usize)
            .unwrap();
        assert_eq!(r.range, first.start..last.end);
    }
    assert!(
        sent.len() * 3 < patches,
        "coalescing: {} requests for {patches} patches",
        sent.len()
    );
    let s = fake.fetcher.stats();
    assert_eq!(s.decoded as usize, patches);
    eprintln!(
        "{patches} patches in {} requests, {} frames (direct: {direct_frames}), {} bytes",
        sent.len(),
        frames,
        s.bytes
    );

    // Every third request fails: those nodes come back unavailable and are asked again
    // after the scheduler's backoff; with a clock that moves, the cut still converges.
    let mut flaky = Fake::new(&file, &index, 3, None);
    let mut sched = Scheduler::new(
        &index,
        SchedulerOptions {
            prefetch: false,
            clock: fake_clock,
            ..Default::default()
        },
    );
    let mut store = CountingStore::default();
    let cam = camera(&index);
    let mut done = false;
    for f in 0..3000u32 {
        CLOCK.with(|c| c.set(f as f64 * 50.0));
        let st = sched.frame(&cam, f as f64 / 20.0, &mut flaky, &mut store);
        if f > 2 && st.pending_loads == 0 && st.cache_misses == 0 {
            done = true;
            break;
        }
        // After a while, the network heals.
        if f == 200 {
            flaky.fail_every = 0;
        }
    }
    assert!(done, "the flaky source did not converge");
    let mut d = sched.draw().to_vec();
    d.sort_unstable();
    assert_eq!(d, direct);
    assert!(flaky.fetcher.stats().failed_requests > 0);
}

/// Requests take 6 frames; the camera looks at one side of the model close up for
/// [`TURN_AT`] frames, then turns to the other side: the requests for the side it left are
/// cancelled (aborted) a few frames later, none of them is answered, and the view
/// converges to the direct cut of where it looks, fetching fewer bytes than without
/// cancelling. A request whose nodes come back into the view in time is not cancelled.
const TURN_AT: u32 = 80;

#[test]
fn a_turned_view_cancels_the_requests_it_no_longer_wants() {
    let dir = tempfile::tempdir().unwrap();
    let file = model(dir.path());
    let index = Arc::new(ModelIndex::read(file.as_slice()).unwrap());
    let away = camera_at(&index, 30.0, 1.05);
    let back = camera_at(&index, 210.0, 1.6);
    let (direct, _) = converge_at(
        &index,
        &mut Direct {
            index: &index,
            file: &file,
            wanted: Vec::new(),
        },
        &back,
    );

    let run = |cancel: bool| {
        let mut fake = Fake::new(&file, &index, 0, None);
        fake.latency_polls = 6;
        fake.fetcher.set_cancel(cancel);
        let mut sched = Scheduler::new(
            &index,
            SchedulerOptions {
                prefetch: false,
                clock: || 0.0,
                ..Default::default()
            },
        );
        let mut store = CountingStore::default();
        // Long enough for a few levels under the close-up's side to be asked for.
        for f in 0..TURN_AT {
            sched.frame(&away, f as f64 / 60.0, &mut fake, &mut store);
        }
        let sent_away = fake.sent.len();
        let mut converged = None;
        for f in TURN_AT..600u32 {
            let st = sched.frame(&back, f as f64 / 60.0, &mut fake, &mut store);
            if st.pending_loads == 0 && st.cache_misses == 0 && fake.fetcher.in_flight() == 0 {
                converged = Some(f);
                break;
            }
        }
        let f = converged.expect("the turned view converges");
        let mut d = sched.draw().to_vec();
        d.sort_unstable();
        assert_eq!(d, direct, "the cut after the turn (cancel: {cancel})");
        (fake, sent_away, f)
    };
    let (with, sent_away, frames) = run(true);
    let (without, _, frames_without) = run(false);
    let s = with.fetcher.stats();
    assert!(sent_away > 0);
    assert!(
        s.cancelled_requests > 0,
        "nothing was cancelled: {s:?}, {sent_away} sent before the turn"
    );
    assert_eq!(s.cancelled_requests as usize, with.aborted.len());
    // Only requests sent for the view it left were cancelled.
    assert!(with.aborted.iter().all(|r| r.id < sent_away as u64));
    assert_eq!(without.fetcher.stats().cancelled_requests, 0);
    assert!(without.aborted.is_empty());
    let (b_with, b_without) = (s.bytes, without.fetcher.stats().bytes);
    assert!(
        b_with < b_without,
        "bytes received: {b_with} with cancelling, {b_without} without"
    );
    eprintln!(
        "turned view: {} of {sent_away} requests cancelled ({} bytes not fetched); received \
         {b_with} bytes against {b_without} without cancelling; converged at frame {frames} \
         (without: {frames_without})",
        s.cancelled_requests, s.cancelled_bytes
    );

    // Nodes wanted again within CANCEL_AFTER_WANTS sets keep their request.
    use tessera_web::plan::{CANCEL_AFTER_WANTS, MAX_IN_FLIGHT};
    let [a, b, c, d] = [direct[0], direct[1], direct[2], direct[3]];
    let mut f = Fetcher::new(index.clone());
    f.set_wanted(&[(a, 1.0)]);
    let r = f.next_request().unwrap();
    assert_eq!(r.nodes, vec![a]);
    for _ in 1..CANCEL_AFTER_WANTS {
        f.set_wanted(&[]);
    }
    f.set_wanted(&[(a, 1.0)]);
    for _ in 1..CANCEL_AFTER_WANTS {
        f.set_wanted(&[]);
    }
    assert!(f.take_cancelled().is_empty());
    // Unwanted long enough, but nothing waits for its slot: it finishes.
    f.set_wanted(&[]);
    assert!(f.take_cancelled().is_empty());
    // Every slot taken, then another node wanted: the oldest unwanted request goes.
    let mut ids = Vec::new();
    for n in [b, c] {
        f.set_wanted(&[(n, 1.0)]);
        let q = f.next_request().unwrap();
        assert_eq!(q.nodes, vec![n]);
        ids.push(q.id);
    }
    assert_eq!(f.in_flight(), MAX_IN_FLIGHT);
    for _ in 0..CANCEL_AFTER_WANTS {
        f.set_wanted(&[(d, 1.0)]);
    }
    assert_eq!(
        f.take_cancelled(),
        vec![r.id],
        "one slot is needed, the oldest's"
    );
    assert_eq!(f.in_flight(), MAX_IN_FLIGHT - 1);
    assert_eq!(f.next_request().unwrap().nodes, vec![d]);
    // Its answer, if it still comes, is dropped; the node can be asked for again.
    f.complete(
        r.id,
        Ok(file[r.range.start as usize..r.range.end as usize].to_vec()),
    );
    assert_eq!(f.undecoded(), 0);
    assert!(f.take_cancelled().is_empty(), "nothing waits");
    // Asked for again: b's request (unwanted, the oldest now) makes room for it.
    f.set_wanted(&[(a, 1.0)]);
    assert_eq!(f.take_cancelled(), vec![ids[0]]);
    let again = f.next_request().unwrap();
    assert_eq!(again.nodes, r.nodes);
    assert_ne!(again.id, r.id);
}

/// Decoding in workers (jobs out, replies back a frame later, out of order, some
/// workers dying and their jobs decoded here instead) converges to the same cut, and
/// every reply is the patch the file holds.
#[test]
fn decode_workers_converge_to_the_direct_cut() {
    let dir = tempfile::tempdir().unwrap();
    let file = model(dir.path());
    let index = Arc::new(ModelIndex::read(file.as_slice()).unwrap());
    let (direct, _) = direct_cut(&index, &file);
    let mut fake = Fake::new(&file, &index, 0, Some(40));
    let (fetched, _) = converge(&index, &mut fake);
    assert_eq!(fetched, direct, "the cut decoded by workers differs");
    let s = fake.fetcher.stats();
    assert!(
        s.worker_decoded > 0 && s.worker_decoded < s.decoded,
        "{s:?}"
    );
    assert_eq!(fake.fetcher.undecoded(), 0);

    // Every node's reply is its patch, bit for bit; a corrupted patch is its error.
    for n in 0..index.nodes().len() as u32 {
        let range = index.patch_range(n as usize).unwrap();
        let bytes = &file[range.start as usize..range.end as usize];
        let job = tessera_web::wire::Job::of(&index, n, false, Some(4096)).unwrap();
        let reply = tessera_web::wire::run_job(&job.to_bytes(bytes), |_, _, _| Vec::new(), || 0.0);
        match tessera_web::wire::read_reply(n, &reply[..]).unwrap().0 {
            Answer::Loaded { node, patch } => {
                assert_eq!(node, n);
                assert_eq!(
                    *patch,
                    index.read_patch(file.as_slice(), n as usize).unwrap()
                );
            }
            a => panic!("node {n}: {a:?}"),
        }
    }
    let range = index.patch_range(5).unwrap();
    let mut bad = file[range.start as usize..range.end as usize].to_vec();
    bad[10] ^= 1;
    let job = tessera_web::wire::Job::of(&index, 5, false, Some(4096)).unwrap();
    let reply = tessera_web::wire::run_job(&job.to_bytes(&bad), |_, _, _| Vec::new(), || 0.0);
    match tessera_web::wire::read_reply(5, &reply[..]).unwrap().0 {
        Answer::Failed { node: 5, error } => assert!(error.contains("checksum"), "{error}"),
        a => panic!("{a:?}"),
    }
}

thread_local! {
    static CLOCK: std::cell::Cell<f64> = const { std::cell::Cell::new(0.0) };
}

fn fake_clock() -> f64 {
    CLOCK.with(|c| c.get())
}

/// A full-resolution pick through [`PickReader`] (patches fetched batch by batch as the
/// walk reaches them) finds exactly the hit of the pick over the whole file, fetching a
/// few batches of the leaves under the ray, not the model.
#[test]
fn a_pick_fetching_as_it_goes_equals_the_pick_over_the_whole_file() {
    use tessera_web::plan::{PickAttempt, PickReader};
    let dir = tempfile::tempdir().unwrap();
    let file = model(dir.path());
    let path = dir.path().join("copy.tsr");
    std::fs::write(&path, &file).unwrap();
    let whole = tessera_format::Model::open(&path).unwrap();
    let index = Arc::new(ModelIndex::read(file.as_slice()).unwrap());
    let leaves = index
        .nodes()
        .iter()
        .filter(|n| n.children.iter().all(|&c| c == tessera_format::NO_NODE))
        .count();
    let cam = camera(&index);
    let mut hits = 0;
    for (x, y) in [
        (320.5, 240.5),
        (300.5, 200.5),
        (400.5, 300.5),
        (5.5, 5.5),
        (250.5, 260.5),
    ] {
        let ray = tessera_pick::Ray::through_pixel(&cam, x, y);
        let (want, _) = tessera_pick::pick(&whole, &ray).unwrap();
        let reader = PickReader::new(index.clone());
        let (mut rounds, mut fetched) = (0, 0);
        let got = loop {
            rounds += 1;
            assert!(rounds < 64, "the pick does not end");
            match reader.attempt(&ray).unwrap() {
                PickAttempt::Done(hit, stats) => {
                    assert!(stats.skipped.is_empty(), "{stats:?}");
                    break hit;
                }
                PickAttempt::Need(ranges) => {
                    for (r, nodes) in ranges {
                        assert!(
                            r.end - r.start <= tessera_web::plan::COALESCE_MAX_BYTES
                                || nodes.len() == 1
                        );
                        fetched += nodes.len();
                        reader.insert(r.start, &file[r.start as usize..r.end as usize], &nodes);
                    }
                }
            }
        };
        assert_eq!(got, want, "pixel ({x}, {y})");
        if let Some(h) = got {
            hits += 1;
            assert!(h.exact);
            assert!(fetched < leaves / 2, "{fetched} of {leaves} leaves fetched");
        }
        eprintln!("pick at ({x}, {y}): {rounds} passes, {fetched} patches fetched of {leaves} leaves, {} bytes held, hit {:?}", reader.held_bytes(), got.map(|h| h.point));
    }
    assert!(hits >= 3, "the rays miss the model");
    assert!(hits < 5, "the corner ray should miss");
}

/// A view needing more than its budget settles on what fits: the requests stop (no
/// patch fetched again and again, decoded, refused and asked for once more).
#[test]
fn an_over_budget_view_settles_and_stops_fetching() {
    let dir = tempfile::tempdir().unwrap();
    let file = model(dir.path());
    let index = Arc::new(ModelIndex::read(file.as_slice()).unwrap());
    let cam = camera_at(&index, 30.0, 1.05);
    let wanted = {
        let mut fake = Fake::new(&file, &index, 0, None);
        let mut sched = Scheduler::new(
            &index,
            SchedulerOptions {
                clock: || 0.0,
                ..Default::default()
            },
        );
        let mut store = CountingStore::default();
        let mut w = 0;
        for f in 0..300u32 {
            w = sched
                .frame(&cam, f as f64 / 60.0, &mut fake, &mut store)
                .wanted_bytes;
        }
        w
    };
    // The store short of the view's cut, with RAM for a third of it, for a twentieth
    // (less than the groups the view asks for), with and without prefetching; and the
    // store shorter still.
    for (store_frac, ram_frac, prefetch) in [
        (0.6, 0.3, true),
        (0.6, 0.05, false),
        (0.6, 0.05, true),
        (0.3, 0.3, true),
    ] {
        let mut fake = Fake::new(&file, &index, 0, None);
        fake.latency_polls = 3;
        let mut sched = Scheduler::new(
            &index,
            SchedulerOptions {
                clock: || 0.0,
                store_budget_bytes: (wanted as f64 * store_frac) as u64,
                ram_budget_bytes: (wanted as f64 * ram_frac) as u64,
                prefetch,
                ..Default::default()
            },
        );
        let mut store = CountingStore::default();
        let mut sent = Vec::new();
        let mut last = None;
        for f in 0..1200u32 {
            last = Some(sched.frame(&cam, f as f64 / 60.0, &mut fake, &mut store));
            if f % 200 == 199 {
                sent.push(fake.sent.len());
            }
        }
        let st = last.unwrap();
        // How often the most fetched patch was fetched.
        let mut counts = rustc_hash::FxHashMap::<u32, u32>::default();
        for r in &fake.sent {
            for &n in &r.nodes {
                *counts.entry(n).or_default() += 1;
            }
        }
        let most = counts.values().copied().max().unwrap_or(0);
        eprintln!(
            "store {store_frac} and RAM {ram_frac} of the view's {wanted} bytes, prefetch \
             {prefetch}: requests by 200 frames {sent:?} (a patch fetched {most} times at \
             most), pending {}, in flight {}",
            st.pending_loads,
            fake.fetcher.in_flight()
        );
        assert_eq!(
            sent[sent.len() - 1],
            sent[sent.len() - 2],
            "requests go on: {sent:?}"
        );
    }
}
