pub fn run(_a: Args) -> anyhow::Result<std::process::ExitCode> { anyhow::bail!("extract: not yet") }
#[derive(clap::Args)] pub struct Args {}
