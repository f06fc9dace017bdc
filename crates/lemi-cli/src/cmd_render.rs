//! `lemi render` (not yet wired).

#[derive(clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`lemi render` is not available in this build")
}
