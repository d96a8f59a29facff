//! `gems train`: joint optimisation of Gaussians and per-image exposure trajectories from blurry
//! images, with periodic atomic checkpoints and `--resume`, then `point_cloud.ply` (input frame),
//! the trained model, metrics, trajectories and report. The run is gems-pipeline's
//! `train_scene`; this command maps its arguments to a `TrainRequest` and prints the figures.

use std::path::PathBuf;

use anyhow::Context;

use gems_pipeline::Init;
use gems_train::TrainConfig;

use super::edi::LinearisationArg;

/// Arguments of `gems train`.
#[derive(clap::Args)]
pub struct Args {
    /// Scene folder (any layout `gems info` reads, or a folder of photos), or a video (its
    /// frames are extracted into `<output>/frames` with the user's ffmpeg).
    pub scene: PathBuf,
    #[command(flatten)]
    pub video: super::VideoArgs,
    /// Output folder.
    #[arg(short, long)]
    pub output: PathBuf,
    /// TOML configuration (missing fields take the defaults; see gems-train's TrainConfig).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// A published protocol by name: sets the downscale, hold-out, steps and initialisation its
    /// tables were made with (each can still be given explicitly) and is recorded in the
    /// report. deblur-nerf-real: ×4, hold 7, the dataset's COLMAP model; deblur-nerf-synthetic:
    /// ×1, hold 8; exblurf: ×2, per-scene holds; e2nerf: the dataset's split; gems: ×2, built-in
    /// SfM. All train 7000 steps.
    #[arg(long, value_enum)]
    pub protocol: Option<gems_pipeline::Protocol>,
    /// Where poses and points come from; the built-in blur-robust SfM by default (the scene
    /// needs no poses, no sharp images and no COLMAP); `colmap` takes the scene's own COLMAP
    /// model, else its poses file.
    #[arg(long, value_enum)]
    pub init: Option<Init>,
    /// COLMAP model folder for --init colmap (default: the scene's sparse/0).
    #[arg(long)]
    pub colmap_model: Option<PathBuf>,
    /// Translation noise σ (normalised units) for --init gt-noisy.
    #[arg(long, default_value_t = 0.01)]
    pub noise_translation: f64,
    /// Rotation noise σ (radians) for --init gt-noisy.
    #[arg(long, default_value_t = 0.01)]
    pub noise_rotation: f64,
    /// Override the number of steps.
    #[arg(long)]
    pub steps: Option<usize>,
    /// Override the seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Image downscale factor (default 1, or the protocol's: GeMS/PRISM3D on ExBluRF 2,
    /// Deblur-NeRF real 4). The scene's own `images_<f>/` is used when it exists; otherwise
    /// copies are made in the cache.
    #[arg(long)]
    pub downscale: Option<u32>,
    /// Hold-out interval overriding the scene's `hold=<n>` marker (n < 1: no hold-out), e.g. an
    /// ExBluRF scene's llffhold when the folder has no marker.
    #[arg(long, allow_negative_numbers = true)]
    pub hold: Option<i64>,
    /// Folder for downscaled or undistorted copies the scene lacks (default: `<output>/cache`).
    /// Nothing is ever written into the scene folder.
    #[arg(long)]
    pub cache_dir: Option<PathBuf>,
    /// Unit of the scene's event and exposure times (s, ms, us, ns) when their values leave it
    /// open; detected otherwise.
    #[arg(long)]
    pub time_unit: Option<gems_events::TimeUnit>,
    /// Continue from the checkpoint in the output folder.
    #[arg(long)]
    pub resume: bool,
    /// Use the scene's events: EDI-deblurred images (written to `<output>/edi`) feed the SfM
    /// initialisation only; training is still supervised by the blurry images. Runs the built-in
    /// SfM on them, or COLMAP with --init colmap-cli.
    #[arg(long)]
    pub events: bool,
    /// Focal length in pixels at full image size, for --init sfm / colmap-cli when the camera is
    /// calibrated (held fixed). Default: from the photos' EXIF when they carry it (refined by the
    /// built-in SfM under the prior `init.exif_focal_prior`), else estimated by the SfM.
    #[arg(long)]
    pub focal: Option<f64>,
    /// The COLMAP executable for --init colmap-cli.
    #[arg(long, default_value = "colmap")]
    pub colmap_binary: PathBuf,
    /// Event contrast threshold for EDI (the simulator's or camera's C).
    #[arg(long, default_value_t = 0.2)]
    pub event_threshold: f32,
    /// How the blurry images relate to the light the events saw, for EDI. The default is the
    /// trainer's own blur model (a blurry image is the mean of sRGB-encoded sharp frames, as in
    /// GeMS, BAD-Gaussians and `gems synth`); `srgb` for cameras that blur in linear light.
    #[arg(long, value_enum, default_value_t = LinearisationArg::SrgbEncodedAverage)]
    pub event_linearisation: LinearisationArg,
    /// Gamma for --event-linearisation gamma / encoded-average.
    #[arg(long, default_value_t = 2.2)]
    pub event_gamma: f32,
    /// Skip evaluation and report (train and export only).
    #[arg(long)]
    pub no_eval: bool,
    /// LPIPS weights for the evaluation (see `gems eval --help`).
    #[arg(long, num_args = 1..)]
    pub lpips: Vec<PathBuf>,
    /// Where the splatting runs: `auto` takes a hardware GPU when there is one and the CPU
    /// otherwise; `gpu` any GPU adapter (software ones such as Mesa lavapipe included), an error
    /// when there is none; `cpu` the CPU.
    #[arg(long, default_value = "auto")]
    pub device: gems_gpu::DeviceChoice,
    /// Time every GPU kernel of the training steps (GPU timestamps) and write where each
    /// training pass's time went, per kernel and against the wall clock, to `gpu_profile.txt`
    /// in its output folder. Needs a GPU that can time compute passes; each step then ends by
    /// waiting for the GPU and reading its timestamps.
    #[arg(long)]
    pub gpu_profile: bool,
}

/// The protocol's settings with what the user gave explicitly put over them.
pub struct Resolved {
    pub downscale: u32,
    pub hold: Option<i64>,
    pub steps: Option<usize>,
    pub init: Init,
}

/// `--protocol` merged with the explicit `--downscale`, `--hold`, `--steps` and `--init`.
pub fn resolve(
    protocol: Option<gems_pipeline::Protocol>,
    scene: &std::path::Path,
    downscale: Option<u32>,
    hold: Option<i64>,
    steps: Option<usize>,
    init: Option<Init>,
) -> Resolved {
    let p = protocol.map(|p| p.settings(scene));
    Resolved {
        downscale: downscale.or(p.map(|p| p.downscale)).unwrap_or(1),
        hold: hold.or(p.and_then(|p| p.hold)),
        steps: steps.or(p.map(|p| p.steps)),
        init: init.or(p.map(|p| p.init)).unwrap_or(Init::Sfm),
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    crate::console::log_to(&args.output)?;
    let mut cfg = match &args.config {
        Some(p) => TrainConfig::from_toml_file(p)?,
        None => TrainConfig::default(),
    };
    let scene = args.video.scene(&args.scene, &args.output)?;
    let settings = resolve(
        args.protocol,
        &scene,
        args.downscale,
        args.hold,
        args.steps,
        args.init,
    );
    if let Some(s) = settings.steps {
        cfg.steps = s;
    }
    if let Some(s) = args.seed {
        cfg.seed = s;
    }
    let open = gems_data::OpenOptions {
        downscale: settings.downscale,
        cache_dir: Some(
            args.cache_dir
                .clone()
                .unwrap_or_else(|| args.output.join("cache")),
        ),
        time_unit: args.time_unit,
        hold: settings.hold,
        ..Default::default()
    };
    let init = gems_pipeline::InitRequest {
        init: settings.init,
        colmap_model: args.colmap_model,
        noise_translation: args.noise_translation,
        noise_rotation: args.noise_rotation,
        events: args.events.then(|| gems_pipeline::EventInit {
            threshold: args.event_threshold,
            linearisation: args.event_linearisation.resolve(args.event_gamma),
            time_unit: args.time_unit,
        }),
        focal_px: args.focal,
        // A focal from EXIF gets `init.exif_focal_prior` in `train_scene`; a given one is held.
        focal_prior: None,
        colmap_binary: args.colmap_binary,
    };
    let engine = super::open_engine(args.device)?;
    let engine = if args.gpu_profile {
        engine.profiled().context("--gpu-profile")?
    } else {
        engine
    };
    let run = gems_pipeline::train_scene(gems_pipeline::TrainRequest {
        scene,
        output: args.output,
        init,
        cfg,
        open,
        resume: args.resume,
        evaluate: !args.no_eval,
        lpips: args.lpips,
        engine,
        progress: true,
        protocol: args.protocol,
    })?;
    if let Some(m) = &run.metrics {
        super::print_splits(m);
    }
    if let Some(report) = run.report {
        println!("report: {}", report.display());
    }
    Ok(())
}
