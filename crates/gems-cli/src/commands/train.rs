//! `gems train`: joint optimisation of Gaussians and per-image exposure trajectories from blurry
//! images (gems-train), with periodic atomic checkpoints and `--resume`, then `point_cloud.ply`
//! (input frame), the trained model, and gems-eval's metrics, trajectories and report.

use std::path::{Path, PathBuf};

use anyhow::Context;
use gems_train::TrainConfig;
use gems_train::prepare::InitMode;

use super::edi::LinearisationArg;
use super::pipeline::{TrainJob, train_and_report};

/// Initialisation of poses and points.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Init {
    /// The scene's COLMAP sparse model (or the one given with --colmap-model).
    Colmap,
    /// Ground-truth poses.
    Gt,
    /// Ground-truth poses perturbed by seeded noise (labelled as such in the outputs).
    GtNoisy,
    /// Built-in blur-robust SfM on the scene's images (written to `<output>/sfm`).
    Sfm,
    /// A user-installed COLMAP (feature extractor, exhaustive matcher, mapper) run as a
    /// subprocess on the scene's images; its largest model is imported (`<output>/colmap`).
    ColmapCli,
}

/// Arguments of `gems train`.
#[derive(clap::Args)]
pub struct Args {
    /// Scene folder (GeMS/PRISM3D, LLFF or nerfstudio layout).
    pub scene: PathBuf,
    /// Output folder.
    #[arg(short, long)]
    pub output: PathBuf,
    /// TOML configuration (missing fields take the defaults; see gems-train's TrainConfig).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Where poses and points come from; the built-in blur-robust SfM by default (the scene
    /// needs no poses, no sharp images and no COLMAP).
    #[arg(long, value_enum, default_value_t = Init::Sfm)]
    pub init: Init,
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
    /// Image downscale factor (GeMS/PRISM3D on ExBluRF: 2; Deblur-NeRF real: 4). The scene's own
    /// `images_<f>/` is used when it exists; otherwise copies are made in the cache.
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
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
    /// calibrated. Default: from the photos' EXIF when they carry it, else estimated by the SfM.
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
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut cfg = match &args.config {
        Some(p) => TrainConfig::from_toml_file(p)?,
        None => TrainConfig::default(),
    };
    if let Some(s) = args.steps {
        cfg.steps = s;
    }
    if let Some(s) = args.seed {
        cfg.seed = s;
    }
    cfg.validate()
        .map_err(|e| anyhow::anyhow!("invalid configuration: {e}"))?;
    let open = gems_data::OpenOptions {
        downscale: args.downscale,
        cache_dir: Some(
            args.cache_dir
                .clone()
                .unwrap_or_else(|| args.output.join("cache")),
        ),
        time_unit: args.time_unit,
        hold: args.hold,
        ..Default::default()
    };
    // Validate the whole scene (every image decoded, poses, events) before any long work.
    let scene = gems_data::open_scene(&args.scene, &open)
        .with_context(|| format!("opening scene {}", args.scene.display()))?;
    let problems = gems_data::check::check_scene(&scene);
    if !problems.is_empty() {
        let lines: Vec<String> = problems.iter().map(ToString::to_string).collect();
        anyhow::bail!(
            "the scene has {} problem(s) (see `gems info --check`):\n{}",
            problems.len(),
            lines.join("\n")
        );
    }
    let focal = args.focal.or_else(|| {
        gems_data::exif::scene_focal(&scene).map(|f| {
            tracing::info!(focal_px = f.focal_px, source = %f.source, image = %f.image.display(), "focal for the SfM");
            f.focal_px
        })
    });
    let init = match (args.events, args.init) {
        (true, Init::Colmap | Init::Gt | Init::GtNoisy) => anyhow::bail!(
            "--events deblurs the images for an initialiser that reads them: use it with --init sfm \
             (the default) or --init colmap-cli"
        ),
        (_, init) => init,
    };
    // With events, the initialiser sees the EDI-deblurred images instead of the blurry ones.
    let init_images = || -> anyhow::Result<PathBuf> {
        if args.events {
            edi_images(
                &args.scene,
                &args.output,
                args.event_threshold,
                args.event_linearisation.resolve(args.event_gamma),
                args.time_unit,
            )
        } else {
            Ok(args.scene.clone())
        }
    };
    let mode = match init {
        Init::Colmap => InitMode::Colmap(args.colmap_model.clone()),
        Init::Gt => InitMode::Gt,
        Init::GtNoisy => InitMode::GtNoisy {
            translation_std: args.noise_translation,
            rotation_std: args.noise_rotation,
        },
        // A resumed run keeps the model its checkpoint was initialised from.
        Init::Sfm | Init::ColmapCli
            if args.resume && earlier_model(&args.output, init).is_some() =>
        {
            InitMode::Colmap(earlier_model(&args.output, init))
        }
        Init::Sfm => InitMode::Colmap(Some(run_sfm(
            &init_images()?,
            &args.output.join("sfm"),
            cfg.seed,
            focal,
        )?)),
        Init::ColmapCli => InitMode::Colmap(Some(run_colmap(
            &init_images()?,
            &args.output.join("colmap"),
            &args.colmap_binary,
            focal,
        )?)),
    };
    let report = train_and_report(TrainJob {
        scene: &args.scene,
        output: &args.output,
        mode,
        cfg,
        open,
        resume: args.resume,
        evaluate: !args.no_eval,
        lpips: &args.lpips,
        device: args.device,
    })?;
    if let Some(report) = report {
        println!("report: {}", report.display());
    }
    Ok(())
}

/// The model an earlier run with the same initialiser wrote into `output`, if any.
fn earlier_model(output: &Path, init: Init) -> Option<PathBuf> {
    let dir = match init {
        Init::Sfm => output.join("sfm"),
        Init::ColmapCli => output.join("colmap"),
        Init::Colmap | Init::Gt | Init::GtNoisy => return None,
    }
    .join("sparse")
    .join("0");
    dir.join("images.bin").is_file().then_some(dir)
}

/// EDI-deblurs the scene's blurry images with its events into `<output>/edi` (a scene folder)
/// and returns that folder. An existing folder from an earlier run is reused.
pub fn edi_images(
    scene: &Path,
    output: &Path,
    threshold: f32,
    linearisation: gems_init::edi::Linearisation,
    time_unit: Option<gems_events::TimeUnit>,
) -> anyhow::Result<PathBuf> {
    let dir = output.join("edi");
    if dir.join("images").is_dir() {
        tracing::info!(dir = %dir.display(), "reusing EDI images");
        return Ok(dir);
    }
    let opts = gems_data::OpenOptions {
        time_unit,
        ..Default::default()
    };
    let s = gems_data::open_scene(scene, &opts)
        .with_context(|| format!("opening scene {}", scene.display()))?;
    if s.events.stream.is_none() && s.events.bin_counts.is_none() {
        anyhow::bail!(
            "--events: {} has no event stream or event bins",
            scene.display()
        );
    }
    let cfg = gems_init::edi::EdiConfig {
        thresholds: gems_init::edi::Thresholds::equal(threshold),
        linearisation,
        ..Default::default()
    };
    let edi = gems_init::edi::deblur_scene(&s, &cfg)?;
    gems_init::edi::write_edi_scene(&s, &edi, &dir)?;
    tracing::info!(dir = %dir.display(), views = edi.views.len(), "EDI images written");
    Ok(dir)
}

/// Runs the built-in SfM on `images` (a scene folder or an image folder), writes its outputs to
/// `out` and returns the COLMAP model folder. `focal_px` fixes a known focal (calibrated camera). Views it could not register are reported by name.
pub fn run_sfm(
    images: &Path,
    out: &Path,
    seed: u64,
    focal_px: Option<f64>,
) -> anyhow::Result<PathBuf> {
    let imgs = gems_init::sfm::load_images(images)?;
    let opts = gems_init::sfm::SfmOptions {
        seed,
        focal_px,
        ..Default::default()
    };
    tracing::info!(images = imgs.len(), "structure from motion");
    let result = gems_init::sfm::run_sfm(&imgs, &opts)?;
    gems_init::sfm::write_outputs(&result, out)?;
    let st = &result.stats;
    tracing::info!(
        registered = st.registered,
        total = st.total,
        points = st.points,
        reprojection_px = st.mean_reprojection_error,
        "sfm done"
    );
    if !st.unregistered.is_empty() {
        tracing::warn!(
            "SfM could not register {} of {} views: {}",
            st.unregistered.len(),
            st.total,
            st.unregistered.join(", ")
        );
    }
    Ok(out.join("sparse").join("0"))
}

/// Runs a user-installed COLMAP on `images` (a scene folder with `images/`, or an image folder),
/// writes the imported model to `<out>/sparse/0` and returns that folder. Views COLMAP did not
/// register are named and skipped when training prepares its views.
pub fn run_colmap(
    images: &Path,
    out: &Path,
    binary: &Path,
    focal_px: Option<f64>,
) -> anyhow::Result<PathBuf> {
    let img_dir = if images.join("images").is_dir() {
        images.join("images")
    } else {
        images.to_path_buf()
    };
    let opts = gems_init::sfm::ColmapCliOptions {
        binary: binary.to_path_buf(),
        focal_px,
        use_gpu: false,
    };
    tracing::info!(images = %img_dir.display(), colmap = %binary.display(), "running COLMAP");
    let (model, _) = gems_init::sfm::run_colmap_cli(&img_dir, &out.join("work"), &opts)?;
    let sparse = out.join("sparse").join("0");
    gems_data::colmap::write_model(&sparse, &model, gems_data::colmap::ModelFormat::Binary)
        .context("writing the imported COLMAP model")?;
    // Views COLMAP left out are named by the trainer's preparation, which skips them.
    tracing::info!(
        registered = model.images.len(),
        points = model.points.len(),
        "COLMAP model imported"
    );
    Ok(sparse)
}
