//! `gems edi`: event-based double-integral deblurring of a scene's blurry images into a scene
//! folder an initialiser reads (thin layer over `gems_init::edi`).

use std::path::PathBuf;

use anyhow::Context;
use gems_init::edi::{
    EdiConfig, EdiMode, Linearisation, Reference, SearchConfig, Thresholds, deblur_scene,
    write_edi_scene,
};

/// How stored values relate to the light the events saw.
#[derive(Clone, Copy, clap::ValueEnum)]
pub enum LinearisationArg {
    /// Values are linear.
    Identity,
    /// sRGB-encoded values, blur in linear light.
    Srgb,
    /// `linear^(1/gamma)` values, blur in linear light.
    Gamma,
    /// Blur = mean of `linear^(1/gamma)` frames; exponent scaled by 1/gamma.
    EncodedAverage,
    /// Blur = mean of sRGB-encoded frames (`gems synth`, GeMS/BAD model); exact sRGB curve.
    SrgbEncodedAverage,
}

impl LinearisationArg {
    /// The library's linearisation, with `gamma` for the modes that take one.
    pub fn resolve(self, gamma: f32) -> Linearisation {
        match self {
            LinearisationArg::Identity => Linearisation::Identity,
            LinearisationArg::Srgb => Linearisation::Srgb,
            LinearisationArg::Gamma => Linearisation::Gamma(gamma),
            LinearisationArg::EncodedAverage => Linearisation::EncodedAverage(gamma),
            LinearisationArg::SrgbEncodedAverage => Linearisation::SrgbEncodedAverage,
        }
    }
}

/// Arguments of `gems edi`.
#[derive(clap::Args)]
pub struct Args {
    /// Scene folder with blurry images, events and per-view exposure windows (or bin counts).
    pub scene: PathBuf,
    /// Output scene folder (must not exist or be empty).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Contrast threshold for both polarities (overridden by --c-pos/--c-neg).
    #[arg(long, default_value_t = 0.2)]
    pub threshold: f32,
    /// ON threshold.
    #[arg(long)]
    pub c_pos: Option<f32>,
    /// OFF threshold.
    #[arg(long)]
    pub c_neg: Option<f32>,
    /// Estimate the threshold(s) on [0.1, 0.5] instead of using the given ones.
    #[arg(long)]
    pub estimate_threshold: bool,
    /// With --estimate-threshold: estimate ON and OFF thresholds separately.
    #[arg(long)]
    pub separate: bool,
    /// With --estimate-threshold: one estimate per view instead of one per scene.
    #[arg(long)]
    pub per_view: bool,
    /// Write all bins+1 frames per view (binned EDI) instead of one exact frame.
    #[arg(long)]
    pub bins: Option<usize>,
    /// Take the single output frame at the exposure start instead of mid-exposure.
    #[arg(long)]
    pub at_start: bool,
    /// Value linearisation.
    #[arg(long, value_enum, default_value_t = LinearisationArg::Identity)]
    pub linearisation: LinearisationArg,
    /// Gamma for --linearisation gamma / encoded-average.
    #[arg(long, default_value_t = 2.2)]
    pub gamma: f32,
    /// Upper clamp of the output.
    #[arg(long, default_value_t = 1.0)]
    pub upper_clamp: f32,
    /// The blurry images are the mean of N equally spaced sharp sub-frames (both exposure ends
    /// included), e.g. `gems synth`'s sub-frame count; default: a continuous exposure.
    #[arg(long)]
    pub exposure_samples: Option<usize>,
    /// Unit of the scene's event and exposure times (s, ms, us, ns) when their values leave it
    /// open; detected otherwise.
    #[arg(long)]
    pub time_unit: Option<gems_events::TimeUnit>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let opts = gems_data::OpenOptions {
        time_unit: args.time_unit,
        ..Default::default()
    };
    let scene = gems_data::open_scene(&args.scene, &opts)
        .with_context(|| format!("opening scene {}", args.scene.display()))?;
    let linearisation = args.linearisation.resolve(args.gamma);
    let cfg = EdiConfig {
        thresholds: Thresholds {
            c_pos: args.c_pos.unwrap_or(args.threshold),
            c_neg: args.c_neg.unwrap_or(args.threshold),
        },
        search: args.estimate_threshold.then(|| SearchConfig {
            separate: args.separate,
            per_view: args.per_view,
            ..SearchConfig::default()
        }),
        reference: if args.at_start {
            Reference::Start
        } else {
            Reference::Mid
        },
        mode: args
            .bins
            .map_or(EdiMode::Exact, |bins| EdiMode::Binned { bins }),
        linearisation,
        upper_clamp: args.upper_clamp,
        bayer: None,
        exposure_samples: args.exposure_samples,
    };
    let edi = deblur_scene(&scene, &cfg)?;
    write_edi_scene(&scene, &edi, &args.output)?;
    tracing::info!(
        views = edi.views.len(),
        skipped = edi.skipped.len(),
        output = %args.output.display(),
        "wrote EDI scene"
    );
    Ok(())
}
