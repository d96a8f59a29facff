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
    /// With `focal_px`: how well it is known (σ as a fraction of it), so that the built-in SfM
    /// refines it under that prior ([`gems_init::sfm::SfmOptions::focal_prior`]); `None` holds
    /// it. [`crate::train_scene`] sets it for a focal read from EXIF.
    pub focal_prior: Option<f64>,
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
            focal_prior: None,
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
            &init_images(scene, output, req)?,
            &output.join("sfm"),
            seed,
            req.focal_px,
            req.focal_prior,
            None,
        )?)),
        Init::ColmapCli => InitMode::Colmap(Some(run_colmap(
            &init_images(scene, output, req)?,
            &output.join("colmap"),
            &req.colmap_binary,
            req.focal_px,
        )?)),
    })
}

/// The images an image initialiser reads: the scene's, or with events the EDI-deblurred ones
/// (written under `output` the first time).
pub(crate) fn init_images(
    scene: &Path,
    output: &Path,
    req: &InitRequest,
) -> Result<PathBuf, PipelineError> {
    match &req.events {
        Some(ev) => edi_images(scene, output, ev),
        None => Ok(scene.to_path_buf()),
    }
}

/// Whether `init` estimates poses from the images, so that running it again on a first pass's
/// sharp renders (`init.sfm_rerun_fraction`) can improve them.
pub fn reruns_on_renders(init: Init) -> bool {
    matches!(init, Init::Sfm | Init::ColmapCli)
}

/// Whether a run from `init` trains a first pass and runs an initialiser on its sharp renders
/// (`init.sfm_rerun_fraction`): the image initialisers ([`reruns_on_renders`]), whose model the
/// renders' one may replace, and an imported COLMAP model, which the built-in SfM on the renders
/// only measures: when it confirms the model (`init.sfm_rerun_confirm_imported_pct`), the
/// model's cameras are measured accurate and the run proper holds them
/// (`init.confirmed_hold_midpoint`);
/// otherwise the run proper trains from the model as it is (and with `pose.optimize` off it is
/// not checked: nothing moves its cameras). Ground-truth poses need no check.
pub fn checked_on_renders(init: Init) -> bool {
    reruns_on_renders(init) || init == Init::Colmap
}

/// The initialiser `req` names, run again on a first training's sharp renders: of the images in
/// `source` (a scene folder or an image folder: what the first initialisation read), every view
/// `first` trained on is replaced by its render at the mid-exposure pose (at the photo's own
/// resolution), every other view (held out, or not registered) keeps its image, so the new model
/// holds the same views under the same names. The images go to `<out>/images/` (PNG; a view
/// whose file is not a PNG gets `.png` appended, and the model is renamed back), the model to
/// `<out>/sparse/0`, which is returned.
///
/// Why: under strong blur the blurry images' tracks leave depth and camera rotation poorly
/// determined (BENCHMARKS.md, "Structure from motion on the first pass's renders"), and the
/// first pass's renders are deblurred.
pub fn rerun_init_on_renders(
    engine: &mut gems_gpu::Engine,
    first: &gems_train::TrainOutput,
    source: &Path,
    out: &Path,
    req: &InitRequest,
    seed: u64,
    learned_focal_prior: f64,
) -> Result<PathBuf, PipelineError> {
    let source = gems_fs::image_folder(source);
    let files = gems_fs::list_images(&source)?;
    let file_name = |p: &Path| {
        p.file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    let originals: std::collections::HashMap<String, PathBuf> =
        files.iter().map(|p| (file_name(p), p.clone())).collect();
    let sizes = |name: &str| {
        originals
            .get(name)
            .and_then(|p| gems_data::image::image_dimensions(p).ok())
    };
    let renders = gems_eval::render_mid_exposure(engine, first, &sizes)?;
    // A render has no motion blur; it is as sharp as one pixel of the size the first pass
    // trained at, which is that many pixels of the photo's size. The estimate from the renders'
    // edges reads their softness as blur and can put the SfM on too coarse a level
    // ([`gems_init::sfm::SfmOptions::blur_px`]).
    // A trained view and the photo's size over the size it trained at.
    let photo_scale = first.views.iter().find_map(|v| {
        let (w, _) = sizes(&v.name)?;
        Some((v, f64::from(w) / f64::from(v.intrinsics.width)))
    });
    let blur_px = photo_scale.map(|(_, ratio)| ratio.max(1.0));
    // The renders are made with the focal the first pass learned (`pose.focal_lr`) or, from an
    // imported model, that model's own: the SfM on them starts from it, at the photos' size,
    // under the prior `learned_focal_prior` (0 holds it), instead of searching for one again.
    let learned = (first.focal_factor != 1.0 || req.init == Init::Colmap)
        .then_some(photo_scale)
        .flatten()
        .map(|(v, ratio)| v.intrinsics.fx * ratio);
    let (focal_px, focal_prior) = match learned {
        Some(f) => {
            tracing::info!(
                focal_px = f,
                factor = first.focal_factor,
                "the SfM on the renders starts from the focal the first pass used"
            );
            (
                Some(f),
                (learned_focal_prior > 0.0).then_some(learned_focal_prior),
            )
        }
        None => (req.focal_px, req.focal_prior),
    };
    let images = out.join("images");
    // A folder left by an earlier, unfinished run may hold other views.
    if images.is_dir() {
        std::fs::remove_dir_all(&images).map_err(|source| gems_fs::FsError {
            path: images.clone(),
            source,
        })?;
    }
    std::fs::create_dir_all(&images).map_err(|source| PipelineError::CreateDir {
        path: images.clone(),
        source,
    })?;
    let mut renamed = std::collections::HashMap::new();
    for (name, image) in &renders {
        let written = if name.to_ascii_lowercase().ends_with(".png") {
            name.clone()
        } else {
            format!("{name}.png")
        };
        gems_data::save_png(&images.join(&written), image)?;
        renamed.insert(written, name.clone());
    }
    for (name, path) in &originals {
        if !renders.iter().any(|(n, _)| n == name) {
            let bytes = std::fs::read(path).map_err(|source| gems_fs::FsError {
                path: path.clone(),
                source,
            })?;
            gems_fs::write_atomic(&images.join(name), &bytes)?;
        }
    }
    tracing::info!(
        renders = renders.len(),
        others = originals.len().saturating_sub(renders.len()),
        dir = %images.display(),
        "initialising again on the first pass's sharp renders"
    );
    let model = match req.init {
        Init::ColmapCli => run_colmap(out, out, &req.colmap_binary, focal_px)?,
        Init::Sfm | Init::Colmap | Init::Gt | Init::GtNoisy => {
            run_sfm(out, out, seed, focal_px, focal_prior, blur_px)?
        }
    };
    if renamed.iter().any(|(written, name)| written != name) {
        let mut m = gems_data::colmap::read_model(&model)?;
        for img in &mut m.images {
            if let Some(name) = renamed.get(&img.name) {
                img.name.clone_from(name);
            }
        }
        gems_data::colmap::write_model(&model, &m, gems_data::colmap::ModelFormat::Binary)
            .map_err(PipelineError::WriteColmapModel)?;
    }
    Ok(model)
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
/// `out` and returns the COLMAP model folder. `focal_px` fixes a known focal (calibrated camera),
/// or with `focal_prior` (σ over the focal) is refined under that prior (a focal from EXIF).
/// `blur_px` is the images' motion blur when it is known ([`gems_init::sfm::SfmOptions::blur_px`];
/// `None` estimates it). Views it could not register are reported by name.
pub fn run_sfm(
    images: &Path,
    out: &Path,
    seed: u64,
    focal_px: Option<f64>,
    focal_prior: Option<f64>,
    blur_px: Option<f64>,
) -> Result<PathBuf, PipelineError> {
    let imgs = gems_init::sfm::load_images(images)?;
    let opts = gems_init::sfm::SfmOptions {
        seed,
        focal_px,
        focal_prior,
        blur_px,
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
    let img_dir = gems_fs::image_folder(images);
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

/// Adds to `second` every view `first` registered and `second` did not, placed in `second`'s
/// frame by the similarity between the two models' shared cameras
/// ([`gems_math::camera_similarity`]). Returns the names placed; none when fewer than two shared
/// views with distinct centres fix the similarity.
///
/// Why: a held-out view keeps its blurry photo when the initialiser runs again on the renders,
/// and blurry photos do not always register among sharp images; it still needs a pose for the
/// novel-view evaluation.
pub(crate) fn place_missing_views(
    first: &gems_data::colmap::SparseModel,
    second: &mut gems_data::colmap::SparseModel,
) -> Vec<String> {
    let c2w = |img: &gems_data::colmap::Image| gems_math::Se3::from(&img.pose()).inverse();
    let shared: Vec<_> = first
        .images
        .iter()
        .filter_map(|a| second.image_by_name(&a.name).map(|b| (c2w(a), c2w(b))))
        .collect();
    let missing: Vec<_> = first
        .images
        .iter()
        .filter(|a| second.image_by_name(&a.name).is_none())
        .cloned()
        .collect();
    if missing.is_empty() {
        return Vec::new();
    }
    let Some(sim) = gems_math::camera_similarity(&shared) else {
        return Vec::new();
    };
    let camera_id = second.images.first().map_or(1, |i| i.camera_id);
    let mut next_id = second.images.iter().map(|i| i.id).max().unwrap_or(0);
    missing
        .into_iter()
        .map(|img| {
            let a = c2w(&img);
            let pose = gems_math::Pose::from(&sim.act_c2w(&a).inverse());
            next_id += 1;
            second.images.push(gems_data::colmap::Image::from_pose(
                next_id, camera_id, &img.name, &pose,
            ));
            img.name
        })
        .collect()
}

/// The frames of a video, as a scene folder: `<work>/frames/` (numbered PNG frames in time
/// order, and `frames.json` with each frame's time), extracted with the user's ffmpeg at `rate`
/// frames per second (default [`gems_data::video::default_rate`]). Frames already extracted
/// from the same clip at the same rate are reused (a resumed run). Nothing is written beside the
/// video.
pub fn video_frames(
    video: &Path,
    work: &Path,
    rate: Option<f64>,
    ffmpeg: &gems_data::video::Ffmpeg,
) -> Result<PathBuf, PipelineError> {
    let dir = work.join("frames");
    let video = std::fs::canonicalize(video).unwrap_or_else(|_| video.to_path_buf());
    if let Some(list) = gems_data::video::read_frame_list(&dir)
        && list.video == video
        && rate.is_none_or(|r| (r - list.rate).abs() < 1e-9)
    {
        tracing::info!(
            frames = list.frames.len(),
            "reusing the frames in {}",
            dir.display()
        );
        return Ok(dir);
    }
    if dir.exists() {
        std::fs::remove_dir_all(&dir).map_err(|source| gems_fs::FsError {
            path: dir.clone(),
            source,
        })?;
    }
    let list = ffmpeg.extract_frames(&video, &dir, rate)?;
    tracing::info!(
        frames = list.frames.len(),
        rate = format!("{:.2}", list.rate),
        "frames of {} ({:.1} s at {:.1} fps) in {}",
        video.display(),
        list.info.duration_s,
        list.info.fps,
        dir.display()
    );
    Ok(dir)
}

#[cfg(test)]
mod tests {
    use super::*;
    use gems_data::colmap::{Image, SparseModel};
    use gems_math::{Matrix3, So3, Vector3};

    /// A view with camera-to-world rotation `c2w` and centre `centre`.
    fn view_c2w(name: &str, c2w: &Matrix3<f64>, centre: &Vector3<f64>) -> Image {
        let w2c = c2w.transpose();
        let t = -(w2c * centre);
        let pose = gems_math::Pose {
            rotation: std::array::from_fn(|r| std::array::from_fn(|c| w2c[(r, c)])),
            translation: [t[0], t[1], t[2]],
        };
        Image::from_pose(1, 1, name, &pose)
    }

    /// A view turned by the rotation vector `phi`, centred at `centre`.
    fn view(name: &str, phi: [f64; 3], centre: [f64; 3]) -> Image {
        let c2w = *So3::exp(&Vector3::from(phi)).matrix();
        view_c2w(name, &c2w, &Vector3::from(centre))
    }

    #[test]
    fn a_missing_view_is_placed_through_the_similarity_between_the_models() {
        let views = [
            view("a", [0.1, 0.0, 0.0], [0.0, 0.0, 0.0]),
            view("b", [0.0, 0.2, 0.0], [1.0, 0.1, 0.0]),
            view("c", [0.0, 0.0, -0.1], [2.0, 0.5, 0.3]),
            view("held", [0.2, -0.1, 0.1], [0.5, 1.0, -0.4]),
        ];
        // The second model is the first under p ↦ s·R·p + t.
        let (s, rot) = (2.5, *So3::exp(&Vector3::new(0.3, -0.7, 1.1)).matrix());
        let t = Vector3::new(4.0, -1.0, 0.5);
        let moved = |img: &Image| {
            let p = img.pose();
            let c2w = Matrix3::from_fn(|r, c| p.rotation[c][r]);
            let centre = s * (rot * Vector3::from(p.center())) + t;
            view_c2w(&img.name, &(rot * c2w), &centre)
        };
        let first = SparseModel {
            images: views.to_vec(),
            ..SparseModel::default()
        };
        let mut second = SparseModel {
            images: views[..3].iter().map(moved).collect(),
            ..SparseModel::default()
        };
        assert_eq!(
            place_missing_views(&first, &mut second),
            vec!["held".to_owned()]
        );
        let placed = second.image_by_name("held").unwrap().pose();
        let want = moved(&views[3]).pose();
        for r in 0..3 {
            assert!((placed.center()[r] - want.center()[r]).abs() < 1e-9);
            for c in 0..3 {
                assert!((placed.rotation[r][c] - want.rotation[r][c]).abs() < 1e-9);
            }
        }

        // One shared view cannot fix a similarity: nothing is placed.
        let mut lone = SparseModel {
            images: vec![moved(&views[0])],
            ..SparseModel::default()
        };
        assert!(place_missing_views(&first, &mut lone).is_empty());
    }
}
