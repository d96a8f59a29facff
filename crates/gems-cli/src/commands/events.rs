//! `gems events …`: event-stream tools (thin layer over `gems-events`).

use std::path::PathBuf;

use anyhow::Context;
use gems_events::{FrameEncoding, ReadOptions, SimConfig};

/// Event-stream subcommands.
#[derive(clap::Subcommand)]
pub enum EventsCommand {
    /// Simulate events (ESIM model) from a folder of timestamped sharp frames.
    ///
    /// The folder holds `timestamps.txt`/`images.txt` (`<t seconds> <image>` per line), or ESIM's
    /// `images.csv` (`<t ns>, <image>`), or images named by their time in microseconds
    /// (`000000.png`, `001000.png`, …).
    Simulate(SimulateArgs),
    /// Convert an event file (.txt/.csv, .npy/.npz, .aedat4) to .npz or .txt.
    Convert(ConvertArgs),
}

/// Arguments of `gems events simulate`.
#[derive(clap::Args)]
pub struct SimulateArgs {
    /// Folder of timestamped sharp frames.
    pub frames: PathBuf,
    /// Output event file (.npz or .txt).
    #[arg(short, long)]
    pub output: PathBuf,
    /// ON contrast threshold (log-intensity step per positive event).
    #[arg(long, default_value_t = 0.2)]
    pub c_pos: f32,
    /// OFF contrast threshold.
    #[arg(long, default_value_t = 0.2)]
    pub c_neg: f32,
    /// Per-pixel threshold mismatch σ (applied to both polarities).
    #[arg(long, default_value_t = 0.0)]
    pub sigma: f32,
    /// Refractory period in microseconds.
    #[arg(long, default_value_t = 0)]
    pub refractory_us: i64,
    /// ε in log(Y + ε).
    #[arg(long, default_value_t = 1e-3)]
    pub log_eps: f32,
    /// Frames already hold linear light (default: sRGB-encoded PNG/JPEG).
    #[arg(long)]
    pub linear: bool,
    /// Seed of the threshold mismatch.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Unit of the timestamps file (s, ms, us, ns); detected from its values when omitted.
    #[arg(long)]
    pub time_unit: Option<gems_events::TimeUnit>,
}

/// Arguments of `gems events convert`.
#[derive(clap::Args)]
pub struct ConvertArgs {
    /// Input event file.
    pub input: PathBuf,
    /// Output event file (.npz or .txt).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Sensor size WIDTHxHEIGHT when the input does not store it.
    #[arg(long, value_parser = parse_size)]
    pub size: Option<(u16, u16)>,
    /// Unit of the input's timestamps (s, ms, us, ns); detected from its values when omitted.
    #[arg(long)]
    pub time_unit: Option<gems_events::TimeUnit>,
}

fn parse_size(s: &str) -> Result<(u16, u16), String> {
    let (w, h) = s
        .split_once('x')
        .ok_or("expected WIDTHxHEIGHT, e.g. 346x260")?;
    Ok((
        w.parse().map_err(|e| format!("width: {e}"))?,
        h.parse().map_err(|e| format!("height: {e}"))?,
    ))
}

fn write(path: &std::path::Path, events: &gems_events::EventStream) -> anyhow::Result<()> {
    match path.extension().and_then(|e| e.to_str()) {
        Some("npz") => gems_events::write_events_npz(path, events)?,
        Some("txt") => gems_events::write_events_text(path, events)?,
        _ => anyhow::bail!("{}: output must end in .npz or .txt", path.display()),
    }
    Ok(())
}

pub fn run(cmd: EventsCommand) -> anyhow::Result<()> {
    match cmd {
        EventsCommand::Simulate(a) => {
            let config = SimConfig {
                c_pos: a.c_pos,
                c_neg: a.c_neg,
                sigma_pos: a.sigma,
                sigma_neg: a.sigma,
                refractory_us: a.refractory_us,
                log_eps: a.log_eps,
                seed: a.seed,
            };
            let encoding = if a.linear {
                FrameEncoding::Linear
            } else {
                FrameEncoding::Srgb
            };
            let events = gems_events::simulate_folder(&a.frames, &config, encoding, a.time_unit)
                .with_context(|| format!("simulating events from {}", a.frames.display()))?;
            write(&a.output, &events)?;
            tracing::info!(events = events.len(), output = %a.output.display(), "wrote simulated events");
        }
        EventsCommand::Convert(a) => {
            let unit = match a.time_unit {
                Some(u) => Some(u),
                None => gems_events::event_time_summary(&a.input)?
                    .map(|s| gems_events::detect_units(&[s]))
                    .transpose()
                    .map_err(anyhow::Error::msg)
                    .with_context(|| a.input.display().to_string())?
                    .map(|u| u[0]),
            };
            let opts = match unit {
                Some(u) => ReadOptions::in_unit(a.size, u),
                None => ReadOptions {
                    size: a.size,
                    ..ReadOptions::default()
                },
            };
            let events = gems_events::read_events(&a.input, &opts)?;
            write(&a.output, &events)?;
            tracing::info!(events = events.len(), output = %a.output.display(), "converted");
        }
    }
    Ok(())
}
