//! `gems render` (owned by the stage that implements it; replaced when that stage lands).

/// Arguments of `gems render`.
#[derive(clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`gems render` is not available in this build yet")
}
