//! `tessera serve`: the model server, on axum + tokio + hyper + tower-http.
//!
//! [`Server::bind`] takes model files and directories (every visible `*.tsr` in a
//! directory, not recursive) and serves:
//!
//! - `GET|HEAD /models/NAME.tsr`: the file, with range requests done right: `206` with
//!   the exact bytes and `Content-Range`, suffix (`bytes=-N`) and open-ended (`bytes=N-`)
//!   ranges, `416` with `Content-Range: bytes */LEN` when no range is satisfiable,
//!   `Accept-Ranges: bytes`. A malformed `Range` header, or one in another unit, is
//!   ignored (RFC 9110): `200` with the whole file. `Range` is defined for `GET` only, so a
//!   `HEAD` always gets the `200`'s headers (with the full `Content-Length`).
//! - **Multi-range requests are answered** as `multipart/byteranges` (one part per range,
//!   each with its `Content-Range`). Overlapping and adjacent ranges are merged first and
//!   the parts come in ascending order (RFC 9110 allows both); if only one range is left it
//!   is a plain `206`. More than [`MAX_PARTS`] parts after merging are refused with `416`
//!   (the RFC's "many small ranges" case), as is a header with more than 1024 specs.
//! - Validators: a strong `ETag` derived from the file's identity (device, inode, size,
//!   modification time: a new build renamed over the old one gets a new tag) and
//!   `Last-Modified`; `If-None-Match` / `If-Modified-Since` give `304`, `If-Match` /
//!   `If-Unmodified-Since` give `412`, and `If-Range` with a stale ETag (or date) makes a
//!   range request get the whole current file with `200`. `Cache-Control: no-cache`.
//! - Each request opens the file afresh (so a replaced model is picked up without a
//!   restart), stats that one descriptor for length and ETag, and reads every byte of the
//!   answer from it: bytes of two builds are never mixed. A file changed under a running
//!   response in place (not renamed) ends that response early rather than sending
//!   wrong bytes.
//! - Bodies are never compressed (no `Content-Encoding` at all).
//! - `GET /api/models`: the JSON catalogue `{"models": [{name, url, bytes, triangles,
//!   bounding_sphere: {center, radius}, format_version, nodes, etag}]}` from each file's
//!   header, cached: a catalogue request stats the served directories and files and
//!   rescans only when one changed (a new build renamed in changes its directory), and
//!   everything is rescanned every [`ServeOptions::rescan_interval`] (in-place
//!   rewrites). 1,000 models: 25-34 ms a request and 2.1 s for 100 concurrent ones when
//!   each rescanned, well under a millisecond a request cached (issue 29; the test
//!   `issue_29_catalogue_of_1000_models_is_cached` measures it). A file that is not a valid model,
//!   a name that cannot be served (control characters, `\`, a leading `.`) and anything
//!   that is not a regular file (a FIFO, a device, a socket: classified by `stat` and
//!   opened with `O_NONBLOCK`, so it never blocks a scan or a request) are skipped with
//!   one warning each, not repeated by later scans.
//! - `OPTIONS` (CORS preflight or not) answers with `Allow: GET, HEAD, OPTIONS`.
//! - With [`ServeOptions::web_dir`] (`tessera serve --web DIR`): the browser viewer's
//!   static files, `GET /` its `index.html`, `GET /NAME` (also in subdirectories) the
//!   file of that name under the directory, each path segment percent-decoded and
//!   checked like a model name, resolved inside the directory only (`404` otherwise),
//!   with its content type (`application/wasm` for `.wasm`) and `Cache-Control:
//!   no-cache`. Without it, the same files of the viewer built into the binary
//!   ([`EMBEDDED_WEB`]: `build.rs` embeds `web/dist` when `scripts/build-web` has built
//!   it), unless [`ServeOptions::embedded_web`] is off; with neither, `/` answers one
//!   line of text. A client that accepts gzip gets a file's gzipped copy with
//!   `Content-Encoding: gzip` where there is one (`NAME.gz`, written by
//!   `scripts/build-web` beside the files that compress: embedded as
//!   [`EMBEDDED_WEB_GZIP`], or beside the file in the directory when at least as new;
//!   the `.wasm` goes out at about a third of its size), `Vary: Accept-Encoding` on
//!   every one. Models are never compressed (range requests address their bytes).
//! - With [`ServeOptions::tiles`] (`tessera serve --tiles DIR`): a 3D Tiles tileset
//!   directory (`tessera export-tiles`) at `/tiles/NAME/` (`NAME` the directory's
//!   name): `tileset.json` as `application/json`, the tiles as `model/gltf-binary`,
//!   resolved and checked like the web directory's files, with the same CORS. Models
//!   are optional then.
//! - CORS for embedding: `Access-Control-Allow-Origin: *`, methods `GET, HEAD, OPTIONS`,
//!   the `Range`, `If-Range` and other conditional request headers allowed,
//!   `Content-Range`, `Content-Length`, `ETag`, `Accept-Ranges`, `Last-Modified` exposed.
//!
//! Only the files it was given: a request names a model, the name is percent-decoded
//! once and looked up in the served set (never joined onto a path); names with `/`,
//! `\`, control characters or a leading dot are refused with `400`, anything else not in
//! the set is `404`. A symbolic link in a served directory is served only if it points
//! inside that directory; directory entries are opened with `O_NOFOLLOW` on their
//! canonical path.
//!
//! Bounded: at most [`ServeOptions::max_connections`] connections (more wait in the
//! kernel's backlog), HTTP/1.1 request heads of at most
//! [`ServeOptions::max_header_bytes`] (`431` beyond), a header read timeout that also
//! closes idle keep-alive connections (slowloris), a write-stall timeout (a client that
//! stops reading is dropped), a request handling timeout, graceful shutdown that finishes
//! in-flight responses (bounded by [`ServeOptions::shutdown_grace`]), and an access log
//! through `tracing` (target `tessera_serve::access`, level info: method, path, status,
//! bytes sent, milliseconds). Failing accepts (descriptors exhausted) are logged at most
//! once a second with a count and back off (50 ms doubling to 1 s) until one succeeds.

mod body;
mod conn;
#[doc(hidden)]
pub mod fuzzing;
mod http;
mod models;
mod range;
#[doc(hidden)]
pub mod testing;

pub use range::MAX_PARTS;

use std::future::Future;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

/// Settings of a server; `Default` is what `tessera serve` uses (without `--web`).
#[derive(Clone, Debug)]
pub struct ServeOptions {
    /// Address to listen on (`127.0.0.1:8080`); port 0 picks a free port.
    pub addr: SocketAddr,
    /// Most connections served at once (512).
    pub max_connections: usize,
    /// A request head must arrive within this, and an idle keep-alive connection is
    /// closed after it (10 s).
    pub header_read_timeout: Duration,
    /// A response that cannot write anything for this long is dropped (30 s).
    pub write_timeout: Duration,
    /// Most time to produce a response's head (30 s; `503` beyond).
    pub request_timeout: Duration,
    /// Most bytes of a request head (16 KiB; hyper's minimum is 8 KiB).
    pub max_header_bytes: usize,
    /// How often served directories are rescanned for new or removed models (2 s).
    pub rescan_interval: Duration,
    /// How long shutdown waits for in-flight responses (10 s).
    pub shutdown_grace: Duration,
    /// A directory of static files (the browser viewer built by `scripts/build-web`,
    /// `web/dist`) served at `/`: `GET /` is its `index.html`, `GET /NAME` its file
    /// `NAME` (None: the viewer built into the binary, see `embedded_web`).
    pub web_dir: Option<PathBuf>,
    /// Without `web_dir`: serve the browser viewer built into the binary
    /// ([`EMBEDDED_WEB`], when `scripts/build-web` ran before it was built) at `/`
    /// (true). Without either, `/` answers a line of text.
    pub embedded_web: bool,
    /// 3D Tiles tileset directories (`tessera export-tiles` output, each holding a
    /// `tileset.json`), served at `/tiles/NAME/` with `NAME` the directory's name
    /// (`tessera serve --tiles DIR`).
    pub tiles: Vec<PathBuf>,
}

impl Default for ServeOptions {
    fn default() -> Self {
        ServeOptions {
            addr: SocketAddr::from(([127, 0, 0, 1], 8080)),
            max_connections: 512,
            header_read_timeout: Duration::from_secs(10),
            write_timeout: Duration::from_secs(30),
            request_timeout: Duration::from_secs(30),
            max_header_bytes: 16 << 10,
            rescan_interval: Duration::from_secs(2),
            shutdown_grace: Duration::from_secs(10),
            web_dir: None,
            embedded_web: true,
            tiles: Vec::new(),
        }
    }
}

include!(concat!(env!("OUT_DIR"), "/embedded_web.rs"));

/// Why the server could not start (or stopped with an error).
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    #[error("address {addr} is already in use; pick another with --addr HOST:PORT (--addr 127.0.0.1:0 picks a free port)")]
    AddrInUse { addr: SocketAddr },
    #[error("cannot listen on {addr}: {source}")]
    Bind {
        addr: SocketAddr,
        source: std::io::Error,
    },
    #[error("{}: {source}", path.display())]
    Input {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("two models named {name}: {} and {}; rename one", first.display(), second.display())]
    NameClash {
        name: String,
        first: PathBuf,
        second: PathBuf,
    },
    #[error("no valid model to serve{}", if skipped.is_empty() { " (no .tsr file in the given directories)".to_string() } else { format!(": {}", skipped.join("; ")) })]
    NoModels { skipped: Vec<String> },
    #[error("{0}")]
    Io(#[from] std::io::Error),
}

/// A bound server, ready to [`run`](Server::run).
pub struct Server {
    listener: tokio::net::TcpListener,
    shared: Arc<http::Shared>,
    opts: ServeOptions,
}

impl Server {
    /// Checks the inputs (files and directories), reads the models' headers and binds the
    /// address. Errors: a missing input, two models with one name, no valid model at all,
    /// the address in use.
    pub async fn bind(inputs: &[PathBuf], opts: ServeOptions) -> Result<Server, ServeError> {
        let tiles = tilesets(&opts.tiles)?;
        let inputs = inputs.to_vec();
        if inputs.is_empty() && tiles.is_empty() {
            return Err(ServeError::NoModels {
                skipped: Vec::new(),
            });
        }
        let models = tokio::task::spawn_blocking(move || models::Models::open(&inputs))
            .await
            .map_err(std::io::Error::other)?
            .map_err(|e| match e {
                models::StartError::Input { path, source } => ServeError::Input { path, source },
                models::StartError::NameClash {
                    name,
                    first,
                    second,
                } => ServeError::NameClash {
                    name,
                    first,
                    second,
                },
                models::StartError::NoModels { skipped } => ServeError::NoModels { skipped },
            })?;
        let listener = match tokio::net::TcpListener::bind(opts.addr).await {
            Ok(l) => l,
            Err(e) if e.kind() == std::io::ErrorKind::AddrInUse => {
                return Err(ServeError::AddrInUse { addr: opts.addr })
            }
            Err(source) => {
                return Err(ServeError::Bind {
                    addr: opts.addr,
                    source,
                })
            }
        };
        let web = match &opts.web_dir {
            None if opts.embedded_web && !EMBEDDED_WEB.is_empty() => {
                http::Web::Embedded(EMBEDDED_WEB, EMBEDDED_WEB_GZIP)
            }
            None => http::Web::None,
            Some(d) => {
                let canon = std::fs::canonicalize(d).map_err(|source| ServeError::Input {
                    path: d.clone(),
                    source,
                })?;
                if !canon.join("index.html").is_file() {
                    return Err(ServeError::Input {
                        path: d.clone(),
                        source: std::io::Error::other(
                            "no index.html in the --web directory (build it with scripts/build-web)",
                        ),
                    });
                }
                http::Web::Dir(canon)
            }
        };
        Ok(Server {
            listener,
            shared: Arc::new(http::Shared {
                models,
                request_timeout: opts.request_timeout,
                web,
                tiles,
            }),
            opts,
        })
    }

    /// The address actually bound (the port chosen for port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.listener.local_addr().unwrap_or(self.opts.addr)
    }

    /// URL names (`NAME.tsr`) of the models served now.
    pub fn model_names(&self) -> Vec<String> {
        self.shared.models.snapshot().into_keys().collect()
    }

    /// Serves until `shutdown` completes, then stops accepting, lets in-flight responses
    /// finish (at most [`ServeOptions::shutdown_grace`]) and returns.
    pub async fn run(self, shutdown: impl Future<Output = ()> + Send) -> Result<(), ServeError> {
        let app = http::router(self.shared.clone());
        let rescan = {
            let shared = self.shared.clone();
            let every = self.opts.rescan_interval;
            tokio::spawn(async move {
                let mut t = tokio::time::interval(every.max(Duration::from_millis(100)));
                t.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
                t.tick().await;
                loop {
                    t.tick().await;
                    let s = shared.clone();
                    let _ = tokio::task::spawn_blocking(move || s.models.rescan()).await;
                }
            })
        };
        let r = conn::accept_loop(self.listener, app, &self.opts, shutdown).await;
        rescan.abort();
        r.map_err(ServeError::Io)
    }
}

/// The tileset directories' URL names and canonical paths: each must be a directory
/// holding `tileset.json`, and no two may share a name.
fn tilesets(dirs: &[PathBuf]) -> Result<Vec<(String, PathBuf)>, ServeError> {
    let mut out: Vec<(String, PathBuf)> = Vec::new();
    for d in dirs {
        let input = |msg: &str| ServeError::Input {
            path: d.clone(),
            source: std::io::Error::other(msg.to_string()),
        };
        let canon = std::fs::canonicalize(d).map_err(|source| ServeError::Input {
            path: d.clone(),
            source,
        })?;
        if !canon.join("tileset.json").is_file() {
            return Err(input(
                "no tileset.json in the --tiles directory (write one with tessera export-tiles)",
            ));
        }
        let name = canon
            .file_name()
            .and_then(|n| n.to_str())
            .filter(|n| http::decode_name(n).as_deref() == Some(*n))
            .ok_or_else(|| input("the --tiles directory's name cannot be served in a URL"))?
            .to_string();
        if let Some((_, first)) = out.iter().find(|(n, _)| *n == name) {
            return Err(ServeError::NameClash {
                name,
                first: first.clone(),
                second: canon,
            });
        }
        out.push((name, canon));
    }
    Ok(out)
}

/// Binds and serves `inputs` until Ctrl-C (or SIGTERM).
pub async fn serve(inputs: &[PathBuf], opts: ServeOptions) -> Result<(), ServeError> {
    let server = Server::bind(inputs, opts).await?;
    server.run(shutdown_signal()).await
}

/// For the command line: a tokio runtime, [`Server::bind`], `on_ready` (to print the
/// bound address), then serving until Ctrl-C or SIGTERM; a second signal during the
/// graceful drain stops at once.
pub fn serve_blocking(
    inputs: &[PathBuf],
    opts: ServeOptions,
    on_ready: impl FnOnce(&Server),
) -> Result<(), ServeError> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .thread_name("tessera-serve")
        .build()?;
    rt.block_on(async {
        let server = Server::bind(inputs, opts).await?;
        on_ready(&server);
        let (tx, rx) = tokio::sync::oneshot::channel::<()>();
        let signals = tokio::spawn(async move {
            shutdown_signal().await;
            tracing::info!(
                "shutting down: finishing in-flight responses (Ctrl-C again to stop now)"
            );
            let _ = tx.send(());
            shutdown_signal().await;
        });
        let run = server.run(async {
            let _ = rx.await;
        });
        tokio::select! {
            r = run => r,
            _ = signals => Ok(()),
        }
    })?;
    // Blocking reads still queued are not waited for.
    rt.shutdown_timeout(Duration::from_millis(100));
    Ok(())
}

async fn shutdown_signal() {
    #[cfg(unix)]
    {
        let term = async {
            match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
                Ok(mut s) => {
                    s.recv().await;
                }
                Err(_) => std::future::pending::<()>().await,
            }
        };
        tokio::select! {
            _ = tokio::signal::ctrl_c() => {}
            _ = term => {}
        }
    }
    #[cfg(not(unix))]
    {
        let _ = tokio::signal::ctrl_c().await;
    }
}
