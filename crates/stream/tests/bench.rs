//! `tessera_stream::bench` on a built model: what `scripts/check-wasm` and
//! `scripts/bench-web` run in WebAssembly, checked natively.

use tessera_stream::bench::{run, Bench, BenchOptions};

#[test]
fn refines_past_the_roots_and_the_bench_settles() {
    let m = tessera_testkit::build_model(
        None,
        &tessera_testkit::sphere(20_000),
        &tessera_testkit::small_options(),
    );
    let bytes = std::fs::read(&m.path).unwrap();
    // check-wasm's assertion: past the roots (a model has 6 root tetrahedra).
    let last = run(&bytes, 30).expect("parses");
    assert!(
        last.selected_nodes > 6,
        "drew {} nodes",
        last.selected_nodes
    );
    assert!(
        run(&bytes[..bytes.len() - 1], 30).is_err(),
        "truncated model"
    );
    // The timing scheduler: warms up, then frames with nothing left to load.
    let opts = BenchOptions {
        frames: 8,
        ..BenchOptions::default()
    };
    let mut b = Bench::open(bytes, &opts).expect("parses");
    assert_eq!(b.frames(), 8);
    assert!(b.warm().is_some(), "the orbit did not settle");
    for k in 0..8 {
        let s = b.frame(k);
        assert!(s.selected_nodes > 6, "drew {} nodes", s.selected_nodes);
        assert_eq!((s.patches_uploaded, s.pending_loads), (0, 0));
    }
}
