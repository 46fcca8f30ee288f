//! `tessera serve`: serve models over HTTP (ranges, ETags, CORS, a JSON catalogue) with
//! `tessera_serve`; runs until Ctrl-C.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(clap::Args)]
pub struct Args {
    /// Model files (.tsr) and directories (every .tsr in them, rescanned for new builds).
    #[arg(required_unless_present = "tiles", value_name = "MODEL_OR_DIR")]
    inputs: Vec<PathBuf>,
    /// Address to listen on; port 0 picks a free port (the bound address is printed).
    #[arg(long, default_value = "127.0.0.1:8080")]
    addr: SocketAddr,
    /// Most connections served at once (more wait in the listen backlog).
    #[arg(long, default_value_t = 512)]
    max_connections: usize,
    /// Serve the browser viewer from DIR at / instead of the one built into this
    /// binary (`scripts/build-web` writes it to web/dist, which the next build of
    /// tessera embeds): http://ADDR/ opens the first model, /?model=URL another.
    #[arg(long, value_name = "DIR", conflicts_with = "no_web")]
    web: Option<PathBuf>,
    /// Serve no viewer page: only the models and the catalogue.
    #[arg(long)]
    no_web: bool,
    /// A 3D Tiles tileset directory (`tessera export-tiles` output) to serve at
    /// /tiles/NAME/tileset.json, NAME the directory's name (repeatable).
    #[arg(long, value_name = "DIR")]
    tiles: Vec<PathBuf>,
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    let opts = tessera_serve::ServeOptions {
        addr: a.addr,
        max_connections: a.max_connections,
        web_dir: a.web.clone(),
        embedded_web: !a.no_web,
        tiles: a.tiles.clone(),
        ..Default::default()
    };
    let embedded = !tessera_serve::EMBEDDED_WEB.is_empty();
    let web = a.web.is_some() || (!a.no_web && embedded);
    tessera_serve::serve_blocking(&a.inputs, opts, |server| {
        let addr = server.local_addr();
        let names = server.model_names();
        let s = if names.len() == 1 { "" } else { "s" };
        println!("serving {} model{s} at http://{addr}/", names.len());
        if web {
            println!("viewer: http://{addr}/ (?model=/models/NAME.tsr picks a model)");
        } else if !a.no_web {
            println!("no viewer: this binary was built without it (run scripts/build-web, then build tessera again, or pass --web DIR)");
        }
        for n in &names {
            println!("  http://{addr}/models/{n}");
        }
        for t in &a.tiles {
            let name = std::fs::canonicalize(t)
                .ok()
                .and_then(|c| c.file_name().map(|n| n.to_string_lossy().into_owned()))
                .unwrap_or_default();
            println!("  tileset http://{addr}/tiles/{name}/tileset.json");
        }
        println!("catalogue: http://{addr}/api/models (Ctrl-C stops; TESSERA_LOG=info logs every request)");
    })?;
    Ok(ExitCode::SUCCESS)
}
