//! `gems synth`: write a procedural extreme-blur scene (or the blur-level study) with perfect
//! ground truth. The work is in gems-synth; this file maps flags onto a `SynthConfig`.

use std::path::PathBuf;

use anyhow::Context;
use gems_synth::{EventOptions, Preset, SynthConfig};

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub(crate) enum PresetArg {
    /// 96×64, 8 views, 12 px blur (sub-second).
    Tiny,
    /// 240×160, 16 views, 30 px blur (a few seconds; the demo scene).
    Small,
    /// 400×270, 24 views, 45 px blur (ExBluRF size at data factor 2).
    Medium,
}

impl PresetArg {
    pub(crate) fn preset(self) -> Preset {
        match self {
            PresetArg::Tiny => Preset::Tiny,
            PresetArg::Small => Preset::Small,
            PresetArg::Medium => Preset::Medium,
        }
    }
}

/// Arguments of `gems synth`.
#[derive(clap::Args)]
pub struct Args {
    /// Output scene folder (must not exist or be empty, unless --force).
    #[arg(short, long)]
    output: PathBuf,
    /// Starting point for every setting below.
    #[arg(long, value_enum, default_value = "small")]
    preset: PresetArg,
    /// Image width in pixels.
    #[arg(long)]
    width: Option<u32>,
    /// Image height in pixels.
    #[arg(long)]
    height: Option<u32>,
    /// Number of views (blurry images). Default with --blur-levels: 20, as in the paper's study.
    #[arg(long)]
    views: Option<usize>,
    /// Blur strength: mean pixel distance scene points travel during one exposure.
    #[arg(long)]
    blur: Option<f64>,
    /// Sharp sub-frames averaged per blurry image.
    #[arg(long)]
    subframes: Option<usize>,
    /// Antialiasing samples per pixel.
    #[arg(long)]
    spp: Option<u32>,
    /// Boxes and spheres in the scene.
    #[arg(long)]
    objects: Option<usize>,
    /// Horizontal field of view in degrees.
    #[arg(long)]
    fov: Option<f64>,
    /// Hold-out interval written as the `hold=<n>` marker (< 1: no novel-view split).
    #[arg(long, allow_negative_numbers = true)]
    hold: Option<i32>,
    /// Event contrast threshold (both polarities).
    #[arg(long)]
    threshold: Option<f32>,
    /// σ of the per-pixel threshold mismatch (event noise).
    #[arg(long)]
    threshold_sigma: Option<f32>,
    /// Event refractory period in µs.
    #[arg(long)]
    refractory_us: Option<i64>,
    /// Write no events.
    #[arg(long)]
    no_events: bool,
    /// Write the paper's blur-level study instead: folders blur_01 … blur_11 averaging 1…11
    /// frames of an 11-frame burst per view (--blur is the blur of the full burst; no events).
    #[arg(long)]
    blur_levels: bool,
    /// Seed: same seed and settings give byte-identical files.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Delete an existing output folder first.
    #[arg(long)]
    force: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut cfg = SynthConfig::preset(args.preset.preset());
    cfg.seed = args.seed;
    cfg.width = args.width.unwrap_or(cfg.width);
    cfg.height = args.height.unwrap_or(cfg.height);
    cfg.views = args
        .views
        .unwrap_or(if args.blur_levels { 20 } else { cfg.views });
    cfg.blur_px = args.blur.unwrap_or(cfg.blur_px);
    cfg.subframes = args.subframes.unwrap_or(cfg.subframes);
    cfg.spp = args.spp.unwrap_or(cfg.spp);
    cfg.objects = args.objects.unwrap_or(cfg.objects);
    cfg.fov_x_deg = args.fov.unwrap_or(cfg.fov_x_deg);
    cfg.hold = args.hold.unwrap_or(cfg.hold);
    if args.no_events {
        cfg.events = None;
    } else {
        let ev = cfg.events.get_or_insert_with(EventOptions::default);
        if let Some(c) = args.threshold {
            ev.threshold_pos = c;
            ev.threshold_neg = c;
        }
        ev.threshold_sigma = args.threshold_sigma.unwrap_or(ev.threshold_sigma);
        ev.refractory_us = args.refractory_us.unwrap_or(ev.refractory_us);
    }
    if args.force && args.output.exists() {
        std::fs::remove_dir_all(&args.output)
            .with_context(|| format!("removing {}", args.output.display()))?;
    }
    let mut progress = |done: usize, total: usize| tracing::info!("rendered view {done}/{total}");
    let start = std::time::Instant::now();
    if args.blur_levels {
        let summaries = gems_synth::generate_blur_levels(&cfg, &args.output, &mut progress)?;
        for s in &summaries {
            let mean = s.blur_px.iter().sum::<f64>() / s.blur_px.len().max(1) as f64;
            println!(
                "{}: {} views, {} frames averaged, blur {mean:.1} px",
                s.out_dir.display(),
                s.views,
                s.subframes
            );
        }
    } else {
        let s = gems_synth::generate_with_progress(&cfg, &args.output, &mut progress)?;
        let mean = s.blur_px.iter().sum::<f64>() / s.blur_px.len().max(1) as f64;
        println!(
            "{}: {} views {}×{}, {} sub-frames, blur {mean:.1} px (requested {}), {} events",
            s.out_dir.display(),
            s.views,
            s.width,
            s.height,
            s.subframes,
            s.blur_px_requested,
            s.events
        );
    }
    tracing::info!("done in {:.1} s", start.elapsed().as_secs_f64());
    Ok(())
}
