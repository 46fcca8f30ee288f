//! `tessera verify`: prints what `tessera_build::verify::verify_model` finds (the format's
//! structural checks plus the forest's diamond rules); exits 0 only on a valid model.

use anyhow::Context;
use std::path::PathBuf;
use std::process::ExitCode;
use tessera_format::Model;

#[derive(clap::Args)]
pub struct Args {
    /// The model file (.tsr) to check: every checksum, link, sphere and diamond rule.
    model: PathBuf,
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    let m = Model::open(&a.model).with_context(|| format!("{}", a.model.display()))?;
    let r = tessera_build::verify::verify_model(&m);
    if r.is_valid() {
        println!(
            "{}: valid ({} nodes checked)",
            a.model.display(),
            r.checked_nodes
        );
        return Ok(ExitCode::SUCCESS);
    }
    for p in &r.problems {
        println!("{}: {p}", a.model.display());
    }
    eprintln!(
        "error: {}: INVALID, {} problem(s)",
        a.model.display(),
        r.problem_count
    );
    Ok(ExitCode::FAILURE)
}
