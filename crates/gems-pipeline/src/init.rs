//! Where a run's poses and points come from: the choice ([`Init`], [`InitRequest`]) and the
//! initialisers that write a COLMAP model for training to start from.

use std::path::{Path, PathBuf};

use gems_init::edi::Linearisation;
use gems_train::InitMode;

use crate::PipelineError;

/// Initialisation of poses and points. With the `clap` feature it is also a clap value enum
/// (the doc lines below are then the command line's help).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
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

/// GeMS-E: the scene's events deblur the blurry images by EDI, and the initialiser (built-in SfM
/// or COLMAP) reads those instead; training is still supervised by the blurry images.
#[derive(Clone, Copy, Debug)]
pub struct EventInit {
    /// Event contrast threshold (the simulator's or camera's C), both polarities.
    pub threshold: f32,
    /// How the blurry images relate to the light the events saw.
    pub linearisation: Linearisation,
    /// Unit of the scene's event and exposure times when their values leave it open.
    pub time_unit: Option<gems_events::TimeUnit>,
}

/// The initialisation a run asks for.
#[derive(Clone, Debug)]
pub struct InitRequest {
    pub init: Init,
    /// COLMAP model folder for [`Init::Colmap`] (default: the scene's `sparse/0`).
    pub colmap_model: Option<PathBuf>,
    /// Translation noise σ (normalised units) for [`Init::GtNoisy`].
    pub noise_translation: f64,
    /// Rotation noise σ (radians) for [`Init::GtNoisy`].
    pub noise_rotation: f64,
    /// Deblur the images with the scene's events first (only for [`Init::Sfm`] and
    /// [`Init::ColmapCli`], the initialisers that read images).
    pub events: Option<EventInit>,
    /// Focal length in pixels at full image size for the SfM or COLMAP (calibrated camera);
    /// `None` lets them estimate it.
    pub focal_px: Option<f64>,
    /// The COLMAP executable for [`Init::ColmapCli`].
    pub colmap_binary: PathBuf,
}

impl InitRequest {
    /// `init` with the command line's defaults for everything else (noise σ 0.01, no events,
    /// focal estimated, `colmap` on the `PATH`).
    pub fn new(init: Init) -> Self {
        Self {
            init,
            colmap_model: None,
            noise_translation: 0.01,
            noise_rotation: 0.01,
            events: None,
            focal_px: None,
            colmap_binary: PathBuf::from("colmap"),
        }
    }
}

/// Runs the initialiser `req` asks for (SfM, COLMAP, EDI; their outputs go under `output`) and
/// returns the training's initialisation. `seed` seeds the SfM. With `resume`, a model an earlier
/// run of the same initialiser wrote into `output` is reused, so a resumed run keeps the model
/// its checkpoint was initialised from.
pub fn resolve_init(
    scene: &Path,
    output: &Path,
    req: &InitRequest,
    seed: u64,
    resume: bool,
) -> Result<InitMode, PipelineError> {
    if req.events.is_some() && matches!(req.init, Init::Colmap | Init::Gt | Init::GtNoisy) {
        return Err(PipelineError::EventsNeedImageInit);
    }
    // With events, the initialiser sees the EDI-deblurred images instead of the blurry ones.
    let init_images = || -> Result<PathBuf, PipelineError> {
        match &req.events {
            Some(ev) => edi_images(scene, output, ev),
            None => Ok(scene.to_path_buf()),
        }
    };
    Ok(match req.init {
        Init::Colmap => InitMode::Colmap(req.colmap_model.clone()),
        Init::Gt => InitMode::Gt,
        Init::GtNoisy => InitMode::GtNoisy {
            translation_std: req.noise_translation,
            rotation_std: req.noise_rotation,
        },
        Init::Sfm | Init::ColmapCli if resume && earlier_model(output, req.init).is_some() => {
            InitMode::Colmap(earlier_model(output, req.init))
        }
        Init::Sfm => InitMode::Colmap(Some(run_sfm(
            &init_images()?,
            &output.join("sfm"),
            seed,
            req.focal_px,
        )?)),
        Init::ColmapCli => InitMode::Colmap(Some(run_colmap(
            &init_images()?,
            &output.join("colmap"),
            &req.colmap_binary,
            req.focal_px,
        )?)),
    })
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
pub fn edi_images(scene: &Path, output: &Path, ev: &EventInit) -> Result<PathBuf, PipelineError> {
    let dir = output.join("edi");
    if dir.join("images").is_dir() {
        tracing::info!(dir = %dir.display(), "reusing EDI images");
        return Ok(dir);
    }
    let opts = gems_data::OpenOptions {
        time_unit: ev.time_unit,
        ..Default::default()
    };
    let s = gems_data::open_scene(scene, &opts).map_err(|source| PipelineError::OpenScene {
        path: scene.to_path_buf(),
        source,
    })?;
    if s.events.stream.is_none() && s.events.bin_counts.is_none() {
        return Err(PipelineError::NoEvents {
            scene: scene.to_path_buf(),
        });
    }
    let cfg = gems_init::edi::EdiConfig {
        thresholds: gems_init::edi::Thresholds::equal(ev.threshold),
        linearisation: ev.linearisation,
        ..Default::default()
    };
    let edi = gems_init::edi::deblur_scene(&s, &cfg)?;
    gems_init::edi::write_edi_scene(&s, &edi, &dir)?;
    tracing::info!(dir = %dir.display(), views = edi.views.len(), "EDI images written");
    Ok(dir)
}

/// Runs the built-in SfM on `images` (a scene folder or an image folder), writes its outputs to
/// `out` and returns the COLMAP model folder. `focal_px` fixes a known focal (calibrated camera).
/// Views it could not register are reported by name.
pub fn run_sfm(
    images: &Path,
    out: &Path,
    seed: u64,
    focal_px: Option<f64>,
) -> Result<PathBuf, PipelineError> {
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
) -> Result<PathBuf, PipelineError> {
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
        .map_err(PipelineError::WriteColmapModel)?;
    // Views COLMAP left out are named by the trainer's preparation, which skips them.
    tracing::info!(
        registered = model.images.len(),
        points = model.points.len(),
        "COLMAP model imported"
    );
    Ok(sparse)
}
