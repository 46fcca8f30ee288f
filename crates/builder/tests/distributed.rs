//! Issue 36: a distributed build writes the single process's model byte for byte, for
//! any number of ranks, and a failure on one rank stops them all with nothing written.
//! Ranks here are threads of one process ([`LocalPeers`]); `crates/cli/tests/mpi.rs`
//! runs the same under mpirun.

use std::path::{Path, PathBuf};
use tessera_build::peers::{LocalPeers, Peers};
use tessera_build::{build, build_distributed, BuildError, BuildOptions, BuildReport, NoProgress};

fn sphere(dir: &Path, colors: bool) -> PathBuf {
    let input = dir.join(if colors { "color.ply" } else { "plain.ply" });
    tessera_gen::write_sphere(
        &input,
        &tessera_gen::SphereOptions {
            triangles: 40_000,
            colors,
            ..Default::default()
        },
        &tessera_gen::NoProgress,
    )
    .unwrap();
    input
}

fn small() -> BuildOptions {
    BuildOptions {
        leaf_triangles: 512,
        node_triangles: 256,
        threads: Some(2),
        ..Default::default()
    }
}

/// Runs `n` ranks as threads, rank r with `progress(r)`; returns each rank's result.
fn run_ranks(
    n: usize,
    input: &Path,
    output: &Path,
    opts: &BuildOptions,
    progress: impl Fn(usize) -> Box<dyn tessera_build::Progress + Send> + Sync,
) -> Vec<Result<BuildReport, BuildError>> {
    std::thread::scope(|s| {
        let hs: Vec<_> = LocalPeers::group(n)
            .into_iter()
            .map(|p| {
                let pr = progress(p.rank());
                s.spawn(move || build_distributed(input, output, opts, &*pr, &p))
            })
            .collect();
        hs.into_iter().map(|h| h.join().unwrap()).collect()
    })
}

#[test]
fn issue_36_same_bytes_for_any_rank_count() {
    let dir = tempfile::tempdir().unwrap();
    for colors in [false, true] {
        let input = sphere(dir.path(), colors);
        let single = dir.path().join("single.tsr");
        build(&input, &single, &small(), &NoProgress).unwrap();
        let reference = std::fs::read(&single).unwrap();
        for n in [1, 2, 3] {
            let out = dir.path().join(format!("ranks-{n}.tsr"));
            let results = run_ranks(n, &input, &out, &small(), |_| Box::new(NoProgress));
            for (rank, r) in results.iter().enumerate() {
                assert!(r.is_ok(), "rank {rank} of {n}: {:?}", r.as_ref().err());
            }
            let report = results[0].as_ref().unwrap();
            assert_eq!(report.ranks.len(), if n > 1 { n } else { 0 });
            if n > 1 {
                // Work was shared: every rank simplified some diamonds.
                for s in &report.ranks {
                    let d: u64 = s.levels.iter().map(|l| l.diamonds).sum();
                    assert!(d > 0, "rank {} of {n} simplified nothing", s.rank);
                }
                let sent: u64 = report
                    .ranks
                    .iter()
                    .flat_map(|s| &s.levels)
                    .map(|l| l.bytes_sent)
                    .sum();
                assert!(sent > 0);
            }
            assert!(
                std::fs::read(&out).unwrap() == reference,
                "{n} ranks (colours {colors}) wrote other bytes than one process"
            );
        }
    }
}

/// Cancelled once `after` diamonds of its own are done: a stop in the middle of the
/// hierarchy, on one rank only.
struct CancelAfter {
    done: std::sync::atomic::AtomicU64,
    in_hierarchy: std::sync::atomic::AtomicBool,
    after: u64,
}

impl tessera_build::Progress for CancelAfter {
    fn stage(&self, name: &str, _: u64) {
        if name == "simplify diamonds" {
            self.in_hierarchy
                .store(true, std::sync::atomic::Ordering::Relaxed);
        }
    }
    fn advance(&self, n: u64) {
        if self.in_hierarchy.load(std::sync::atomic::Ordering::Relaxed) {
            self.done.fetch_add(n, std::sync::atomic::Ordering::Relaxed);
        }
    }
    fn finish_stage(&self) {}
    fn cancelled(&self) -> bool {
        self.done.load(std::sync::atomic::Ordering::Relaxed) >= self.after
    }
}

#[test]
fn issue_36_one_rank_stopping_stops_all_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let input = sphere(dir.path(), false);
    let out = dir.path().join("never.tsr");
    // Rank 1 is interrupted in the middle of the hierarchy.
    let results = run_ranks(3, &input, &out, &small(), |rank| {
        if rank == 1 {
            Box::new(CancelAfter {
                done: 0.into(),
                in_hierarchy: false.into(),
                after: 20,
            })
        } else {
            Box::new(NoProgress)
        }
    });
    for (rank, r) in results.iter().enumerate() {
        let e = r.as_ref().expect_err("every rank fails");
        assert_eq!(e.to_string(), "interrupted", "rank {rank}");
    }
    assert!(!out.exists());
    // No temporary file or directory is left beside the output.
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

#[test]
fn issue_36_bad_input_fails_every_rank_with_the_single_process_error() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bad.ply");
    std::fs::write(
        &input,
        b"ply\nformat ascii 1.0\nelement vertex 3\nend_header\n0 0\n",
    )
    .unwrap();
    let out = dir.path().join("bad.tsr");
    let single = build(&input, &out, &small(), &NoProgress)
        .unwrap_err()
        .to_string();
    let results = run_ranks(2, &input, &out, &small(), |_| Box::new(NoProgress));
    for r in results {
        assert_eq!(r.unwrap_err().to_string(), single);
    }
    assert!(!out.exists());
}

#[test]
fn issue_36_input_unreadable_on_one_rank_stops_all_with_its_error() {
    // Why: the ranks read the input each; one that cannot (a node without the mount)
    // must not leave the others waiting at the first exchange.
    let dir = tempfile::tempdir().unwrap();
    let good = sphere(dir.path(), false);
    let missing = dir.path().join("not-mounted.ply");
    let out = dir.path().join("never.tsr");
    let single = build(&missing, &out, &small(), &NoProgress)
        .unwrap_err()
        .to_string();
    let results = std::thread::scope(|s| {
        let hs: Vec<_> = LocalPeers::group(3)
            .into_iter()
            .map(|p| {
                let input = if p.rank() == 1 { &missing } else { &good };
                let out = &out;
                s.spawn(move || build_distributed(input, out, &small(), &NoProgress, &p))
            })
            .collect();
        hs.into_iter()
            .map(|h| h.join().unwrap())
            .collect::<Vec<_>>()
    });
    for (rank, r) in results.into_iter().enumerate() {
        assert_eq!(r.unwrap_err().to_string(), single, "rank {rank}");
    }
    assert!(!out.exists());
}
