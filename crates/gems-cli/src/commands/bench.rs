//! `gems bench` (owned by the stage that implements it; replaced when that stage lands).

/// Arguments of `gems bench`.
#[derive(clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`gems bench` is not available in this build yet")
}
