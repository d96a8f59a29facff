//! `gems events …` (owned by the events stage; replaced when it lands).

/// Event-stream subcommands.
#[derive(clap::Subcommand)]
pub enum EventsCommand {
    /// Simulate events from a folder of timestamped sharp frames.
    Simulate {},
}

pub fn run(_cmd: EventsCommand) -> anyhow::Result<()> {
    anyhow::bail!("`gems events` is not available in this build yet")
}
