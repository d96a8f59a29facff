//! The evaluation protocol on a trained result ([`TrainOutput`]), its ground truth from a scene
//! folder, trajectory export and the report's inputs.

use std::path::Path;

use gems_data::{OpenOptions, PoseSource, Scene, Split, load_image, open_scene};
use gems_gpu::Engine;
use gems_math::{Intrinsics, Pose, Se3};
use gems_metrics::Lpips;
use gems_splat::Camera;
use gems_train::TrainOutput;

use crate::EvalError;
use crate::metrics::{
    ApeSummary, CameraShift, EvalView, FocalSummary, HeldOutFrame, HeldOutPosing, MetricsReport,
    PoseMode, RotationErrorSummary, SplitResult, SplitScores, ape_of_centres,
    evaluate_views_with_progress, relative_rotation_error, score_image,
};
use crate::refine::PoseRefineConfig;
use crate::report::{GridRow, ReportInput};
use crate::tum::write_tum;
use crate::viewer::{CameraKind, ViewerCamera, ViewerScene};

/// A held-out (novel) view: never trained on; its pose is the initial one.
#[derive(Clone, Debug)]
pub struct HeldOutView {
    pub name: String,
    pub intrinsics: Intrinsics,
    /// Initial camera-to-world pose in the trained result's normalised frame.
    pub c2w_init: Se3,
    /// Sharp ground truth `[H,W,3]`.
    pub gt: Vec<f32>,
}

/// Images for evaluation and the report.
#[derive(Clone, Debug, Default)]
pub struct EvalData {
    /// Sharp ground truth per training view (same order as `output.views`), `None` where
    /// unknown. Empty means none known.
    pub train_gt: Vec<Option<Vec<f32>>>,
    /// The blurry training inputs (same order; empty if not loaded), for the report grid.
    pub train_blurry: Vec<Option<Vec<f32>>>,
    /// EDI-deblurred images of the training views (same order; empty unless
    /// [`attach_edi_images`] found them), the report's GeMS-E column.
    pub train_edi: Vec<Option<Vec<f32>>>,
    pub held_out: Vec<HeldOutView>,
    /// How `held_out` was posed.
    pub held_out_posing: Option<HeldOutPosing>,
    /// How far the trained cameras moved from the held-out views' pose source's cameras.
    pub camera_shift: Option<CameraShift>,
    /// The scene's own camera for each training view (same order; empty or `None` where the
    /// scene has none), at the trained view's size.
    pub train_scene_intrinsics: Vec<Option<Intrinsics>>,
}

/// Everything one evaluation produced.
#[derive(Clone, Debug)]
pub struct Evaluation {
    pub metrics: MetricsReport,
    /// Indices (into `output.views`) of the views in `deblur`.
    pub deblur_views: Vec<usize>,
    pub deblur: SplitResult,
    pub nvs: SplitResult,
    pub nvs_no_pose_opt: SplitResult,
}

fn se3(p: &Pose) -> Se3 {
    Se3::from(p)
}

/// Runs the protocol (see the crate docs). APE needs ground-truth poses on at least three
/// training views with non-collinear centres; otherwise `ape` is `None`.
pub fn evaluate_output(
    output: &TrainOutput,
    data: &EvalData,
    refine: &PoseRefineConfig,
    lpips: Option<&Lpips>,
) -> Result<Evaluation, EvalError> {
    evaluate_output_on(&mut Engine::cpu(), output, data, refine, lpips, &mut |_| {})
}

/// Renders [`evaluate_output`] does: two per deblur view (midpoint and refined) plus two per
/// held-out view; pass it to a progress bar driven by [`evaluate_output_on`].
pub fn evaluation_units(data: &EvalData) -> usize {
    2 * data.train_gt.iter().flatten().count() + 2 * data.held_out.len()
}

/// [`evaluate_output`] rendering with `engine` (`--device`), calling `on_view` with the view
/// name after each of the [`evaluation_units`] evaluations (the refined ones are the slow ones).
pub fn evaluate_output_on(
    engine: &mut Engine,
    output: &TrainOutput,
    data: &EvalData,
    refine: &PoseRefineConfig,
    lpips: Option<&Lpips>,
    on_view: &mut dyn FnMut(&str),
) -> Result<Evaluation, EvalError> {
    if !data.train_gt.is_empty() && data.train_gt.len() != output.views.len() {
        return Err(EvalError::Input(format!(
            "{} training ground-truth entries for {} training views",
            data.train_gt.len(),
            output.views.len()
        )));
    }
    let gaussians = &output.gaussians;
    let mut deblur_views = Vec::new();
    let mut train_views = Vec::new();
    for (i, (view, gt)) in output.views.iter().zip(&data.train_gt).enumerate() {
        if let Some(gt) = gt {
            deblur_views.push(i);
            train_views.push(EvalView {
                name: view.name.clone(),
                intrinsics: view.intrinsics,
                c2w_init: se3(&view.c2w_init),
                c2w_eval: se3(&view.mid_c2w),
                gt: gt.clone(),
            });
        }
    }
    let held: Vec<EvalView> = data
        .held_out
        .iter()
        .map(|h| EvalView {
            name: h.name.clone(),
            intrinsics: h.intrinsics,
            c2w_init: h.c2w_init,
            c2w_eval: h.c2w_init,
            gt: h.gt.clone(),
        })
        .collect();
    let mut run = |views: &[EvalView], mode| {
        evaluate_views_with_progress(engine, gaussians, views, mode, lpips, on_view)
    };
    let deblur = run(&train_views, PoseMode::AsGiven)?;
    let nvs_no_pose_opt = run(&held, PoseMode::AsGiven)?;
    let nvs = run(&held, PoseMode::Refine(*refine))?;
    let deblur_refined = run(&train_views, PoseMode::Refine(*refine))?;
    let mid_pairs = poses_with_gt(output, |v| &v.mid_c2w);
    let init_pairs = poses_with_gt(output, |v| &v.c2w_init);
    let ape = ape_if_known(&mid_pairs);
    let ape_init = ape_if_known(&init_pairs);
    let input = input_scores(output, data, &deblur_views, lpips)?;
    let metrics = MetricsReport {
        deblur: deblur.scores.clone(),
        deblur_refined: deblur_refined.scores,
        input,
        nvs: nvs.scores.clone(),
        nvs_no_pose_opt: nvs_no_pose_opt.scores.clone(),
        ape,
        ape_init,
        rotation_error: rotation_error_if_known(&mid_pairs),
        rotation_error_init: rotation_error_if_known(&init_pairs),
        focal: output.views.first().map(|v| FocalSummary {
            initial_px: v.intrinsics.fx / output.focal_factor,
            trained_px: v.intrinsics.fx,
            scene_px: data
                .train_scene_intrinsics
                .first()
                .copied()
                .flatten()
                .map(|k| k.fx),
        }),
        steps: output.steps,
        seconds: output.seconds,
        gaussians: gaussians.len(),
        init: output.init_label.clone(),
        labels: crate::metrics::split_labels()
            .into_iter()
            .map(|(k, v)| (k.to_owned(), v.to_owned()))
            .collect(),
        held_out_pose: data.held_out_posing.clone(),
        camera_shift: data.camera_shift,
        run: output.run.clone(),
        eval_seconds: None,
    };
    Ok(Evaluation {
        metrics,
        deblur_views,
        deblur,
        nvs,
        nvs_no_pose_opt,
    })
}

/// The blurry inputs of the `views` (indices into `output.views`) scored against their sharp
/// ground truth: what the user started from, beside every figure of ours. `None` when the blurry
/// images were not loaded.
fn input_scores(
    output: &TrainOutput,
    data: &EvalData,
    views: &[usize],
    lpips: Option<&Lpips>,
) -> Result<Option<SplitScores>, EvalError> {
    let mut per_image = Vec::with_capacity(views.len());
    for &i in views {
        let (Some(Some(blurry)), Some(Some(gt))) = (data.train_blurry.get(i), data.train_gt.get(i))
        else {
            return Ok(None);
        };
        let view = &output.views[i];
        let (h, w) = (
            view.intrinsics.height as usize,
            view.intrinsics.width as usize,
        );
        per_image.push(score_image(&view.name, blurry, gt, h, w, lpips)?);
    }
    Ok(SplitScores::from_images(per_image))
}

/// The camera-to-world poses `pose(view)` (the trajectory midpoint, or the initial pose) and the
/// ground truth's, in the input frame, for the training views whose ground-truth pose is known.
fn poses_with_gt(
    output: &TrainOutput,
    pose: impl Fn(&gems_train::ViewResult) -> &Pose,
) -> Vec<(Se3, Se3)> {
    output
        .views
        .iter()
        .filter_map(|v| {
            let gt = v.c2w_gt.as_ref()?;
            Some((
                to_input_frame(output, &se3(pose(v))),
                to_input_frame(output, &se3(gt)),
            ))
        })
        .collect()
}

/// APE of the camera centres of `(estimated, ground-truth)` poses; `None` (with a warning when
/// the alignment fails) for fewer than 3 views with ground truth.
fn ape_if_known(pairs: &[(Se3, Se3)]) -> Option<ApeSummary> {
    if pairs.len() < 3 {
        return None;
    }
    let (est, gt): (Vec<[f64; 3]>, Vec<[f64; 3]>) = pairs
        .iter()
        .map(|(e, g)| -> ([f64; 3], [f64; 3]) { (e.trans.into(), g.trans.into()) })
        .unzip();
    ape_of_centres(&est, &gt)
        .inspect_err(|e| tracing::warn!("APE not computed: {e}"))
        .ok()
}

/// Relative rotation error of `(estimated, ground-truth)` poses; `None` for fewer than 2 views
/// with ground truth.
fn rotation_error_if_known(pairs: &[(Se3, Se3)]) -> Option<RotationErrorSummary> {
    if pairs.len() < 2 {
        return None;
    }
    let (est, gt): (Vec<_>, Vec<_>) = pairs.iter().map(|(e, g)| (e.rot, g.rot)).unzip();
    relative_rotation_error(&est, &gt)
        .inspect_err(|e| tracing::warn!("rotation error not computed: {e}"))
        .ok()
}

/// A file-name-safe stem of a view name ("images/0001.png" → "0001").
pub fn file_stem(name: &str) -> String {
    let base = Path::new(name)
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or(name);
    base.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "._-".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
}

pub(crate) fn to_input_frame(output: &TrainOutput, c2w: &Se3) -> Se3 {
    let (r, t) = output.normalization.invert_c2w(&c2w.rot, &c2w.trans);
    Se3::new(r, t)
}

/// Writes, in the input frame: `trajectories/<view>.txt` (the n virtual camera-to-world poses,
/// timestamps u_k = linspace(0, 1, n)), `trajectories/mid.txt` (midpoints, timestamp = view
/// index) and, when known, `trajectories/gt.txt` (same timestamps, so evo associates them 1:1).
pub fn write_trajectories(dir: &Path, output: &TrainOutput) -> Result<(), EvalError> {
    let tdir = dir.join("trajectories");
    let mut mids = Vec::new();
    let mut gts = Vec::new();
    for (i, v) in output.views.iter().enumerate() {
        let n = v.virtual_c2w.len();
        let poses: Vec<(f64, Se3)> = v
            .virtual_c2w
            .iter()
            .enumerate()
            .map(|(k, p)| {
                let u = if n <= 1 {
                    0.5
                } else {
                    k as f64 / (n - 1) as f64
                };
                (u, to_input_frame(output, &se3(p)))
            })
            .collect();
        write_tum(&tdir.join(format!("{}.txt", file_stem(&v.name))), &poses)?;
        mids.push((i as f64, to_input_frame(output, &se3(&v.mid_c2w))));
        if let Some(gt) = &v.c2w_gt {
            gts.push((i as f64, to_input_frame(output, &se3(gt))));
        }
    }
    write_tum(&tdir.join("mid.txt"), &mids)?;
    if !gts.is_empty() {
        write_tum(&tdir.join("gt.txt"), &gts)?;
    }
    Ok(())
}

fn load_rgb(path: &Path, k: &Intrinsics) -> Result<Vec<f32>, EvalError> {
    let img = load_image(path)?;
    if (img.width, img.height) != (k.width, k.height) {
        return Err(EvalError::Format {
            path: path.to_path_buf(),
            reason: format!(
                "image is {}x{}, the trained view is {}x{}",
                img.width, img.height, k.width, k.height
            ),
        });
    }
    Ok(img.data)
}

/// Ground truth from the scene the result was trained on (opened at the training resolution):
/// sharp images of the training views matched by name, blurry inputs for the report, and the
/// held-out views with a sharp ground truth, posed as [`held_out_reference`] says and carried
/// into the result's initial frame ([`HeldOutFrame::Initial`], see
/// [`eval_data_from_scene_in`]).
pub fn eval_data_from_scene(output: &TrainOutput, scene: &Scene) -> Result<EvalData, EvalError> {
    eval_data_from_scene_in(output, scene, HeldOutFrame::Initial)
}

/// [`eval_data_from_scene`] with the held-out views carried into `frame`: by the similarity
/// between the reference's training cameras and the result's initial ones, or its trained
/// mid-exposure ones ([`EvalData::held_out_posing`] records which).
pub fn eval_data_from_scene_in(
    output: &TrainOutput,
    scene: &Scene,
    frame: HeldOutFrame,
) -> Result<EvalData, EvalError> {
    let mut data = EvalData::default();
    for v in &output.views {
        let sv = scene.views.iter().find(|s| s.name == v.name);
        let gt = match sv.and_then(|s| s.sharp_gt.as_ref()) {
            Some(p) => Some(load_rgb(p, &v.intrinsics)?),
            None => None,
        };
        let blurry = match sv {
            Some(s) => Some(load_rgb(&s.image, &v.intrinsics)?),
            None => None,
        };
        data.train_gt.push(gt);
        data.train_blurry.push(blurry);
        data.train_scene_intrinsics.push(
            sv.and_then(|s| s.intrinsics)
                .map(|k| k.resized(v.intrinsics.width, v.intrinsics.height)),
        );
    }
    let pose_model = match &output.pose_model {
        Some(dir) => {
            let mut model = gems_data::colmap::read_model(dir)?;
            let names: Vec<String> = scene.views.iter().map(|v| v.name.clone()).collect();
            model.key_by_view_names(&names);
            Some(model)
        }
        None => None,
    };
    let reference = held_out_reference(scene, pose_model.as_ref());
    // Training cameras in both frames, the reference's and the result's (input frame): the
    // initial cameras or the trained mid-exposure ones.
    let pairs_with = |pose: &dyn Fn(&gems_train::ViewResult) -> &Pose| -> Vec<(Se3, Se3)> {
        output
            .views
            .iter()
            .filter_map(|v| {
                let p = (reference.pose)(v.name.as_str())?;
                Some((
                    Se3::from(&p.0).inverse(),
                    to_input_frame(output, &se3(pose(v))),
                ))
            })
            .collect()
    };
    let initial = pairs_with(&|v| &v.c2w_init);
    let trained = pairs_with(&|v| &v.mid_c2w);
    data.camera_shift = camera_shift(&initial, &trained);
    let pairs = match frame {
        HeldOutFrame::Initial => &initial,
        HeldOutFrame::Trained => &trained,
    };
    let similarity = gems_math::camera_similarity(pairs);
    data.held_out_posing = Some(HeldOutPosing {
        source: reference.source.clone(),
        frame,
        similarity_cameras: if similarity.is_some() { pairs.len() } else { 0 },
    });
    for s in scene.views.iter().filter(|s| s.split == Split::NovelView) {
        let Some(gt_path) = &s.sharp_gt else { continue };
        let Some((pose, model_k)) = (reference.pose)(s.name.as_str()) else {
            tracing::warn!(view = %s.name, "held-out view has no pose; not evaluated");
            continue;
        };
        // The trained frame's camera: the model the run started from (with the focal factor
        // training learned), else the trained views' (the datasets use one camera), at this
        // image's size. The dataset's own intrinsics belong to its frame, not necessarily to
        // the one the result was trained in.
        let model_k = model_k.map(|k| k.with_focal_scaled(output.focal_factor));
        let k = match model_k.or_else(|| output.views.first().map(|v| v.intrinsics)) {
            Some(k) => k.resized(s.width, s.height),
            None => continue,
        };
        let c2w_ref = Se3::from(&pose).inverse();
        let c2w = match &similarity {
            Some(sim) => sim.act_c2w(&c2w_ref),
            None => c2w_ref,
        };
        let (r, t) = output.normalization.apply_c2w(&c2w.rot, &c2w.trans);
        data.held_out.push(HeldOutView {
            name: s.name.clone(),
            intrinsics: k,
            c2w_init: Se3::new(r, t),
            gt: load_rgb(gt_path, &k)?,
        });
    }
    Ok(data)
}

/// Where the poses of held-out views come from, and a lookup of the pose (world-to-camera) and,
/// when the source knows it, the camera of a view by name.
struct Reference<'a> {
    source: String,
    #[allow(clippy::type_complexity)]
    pose: Box<dyn Fn(&str) -> Option<(Pose, Option<Intrinsics>)> + 'a>,
}

/// The poses held-out views are evaluated at, in order of preference: the dataset's own (the
/// scene's COLMAP model, poses file or transforms — what the published tables render at); else
/// the model the run was initialised from (the built-in SfM registers held-out photos too);
/// else the ground truth. The camera comes from the initialisation's model when it has the
/// view.
fn held_out_reference<'a>(
    scene: &'a Scene,
    pose_model: Option<&'a gems_data::colmap::SparseModel>,
) -> Reference<'a> {
    let model_camera = move |name: &str| -> Option<Intrinsics> {
        let m = pose_model?;
        let img = m.image_by_name(name)?;
        m.camera(img.camera_id)?.intrinsics().ok()
    };
    let held_out = || scene.views.iter().filter(|v| v.split == Split::NovelView);
    let view = move |name: &str| scene.views.iter().find(|v| v.name == name);
    if scene.pose_source != PoseSource::None && held_out().any(|v| v.pose.is_some()) {
        let what = match scene.pose_source {
            PoseSource::Sfm => "its COLMAP model",
            PoseSource::Llff => "its poses file",
            PoseSource::Nerfstudio => "its transforms file",
            PoseSource::None => unreachable!("checked above"),
        };
        return Reference {
            source: format!("the dataset's poses ({what})"),
            pose: Box::new(move |name| Some((view(name)?.pose?, model_camera(name)))),
        };
    }
    if let Some(m) = pose_model {
        return Reference {
            source: "the initialisation's model (the SfM registers held-out photos too)".into(),
            pose: Box::new(move |name| Some((m.image_by_name(name)?.pose(), model_camera(name)))),
        };
    }
    Reference {
        source: "the ground-truth poses".into(),
        pose: Box::new(move |name| Some((view(name)?.gt_pose?, None))),
    }
}

/// How far the trained mid-exposure cameras, and the initial ones, lie from the reference
/// cameras of the same views, each set after its own best similarity to them (so a change of
/// frame, scale or gauge counts for nothing, a change of shape for everything).
fn camera_shift(initial: &[(Se3, Se3)], trained: &[(Se3, Se3)]) -> Option<CameraShift> {
    let residual = |pairs: &[(Se3, Se3)]| {
        gems_math::camera_discrepancy(pairs).map(|d| (d.centre_pct, d.rotation_deg))
    };
    let (centre_pct, rotation_deg) = residual(trained)?;
    let (initial_centre_pct, initial_rotation_deg) = residual(initial)?;
    Some(CameraShift {
        views: trained.len(),
        centre_pct,
        rotation_deg,
        initial_centre_pct,
        initial_rotation_deg,
    })
}

/// Loads the EDI-deblurred image of each training view from `edi_images` (a folder of images
/// named like the views, as `gems edi` / `gems train --events` write them) into
/// `data.train_edi`, area-downscaled to the trained resolution when training ran downscaled.
/// Views without an EDI image get `None`. Returns how many were found.
pub fn attach_edi_images(
    data: &mut EvalData,
    output: &TrainOutput,
    edi_images: &Path,
) -> Result<usize, EvalError> {
    data.train_edi.clear();
    for v in &output.views {
        let path = edi_images.join(&v.name);
        if !path.is_file() {
            data.train_edi.push(None);
            continue;
        }
        let img = load_image(&path)?;
        let k = &v.intrinsics;
        let img = if (img.width, img.height) == (k.width, k.height) {
            img
        } else if img.width >= k.width && img.height >= k.height {
            gems_data::image::downscale_area(&img, k.width, k.height)
        } else {
            return Err(EvalError::Format {
                path,
                reason: format!(
                    "EDI image is {}x{}, smaller than the trained view's {}x{}",
                    img.width, img.height, k.width, k.height
                ),
            });
        };
        data.train_edi.push(Some(img.data));
    }
    Ok(data.train_edi.iter().flatten().count())
}

/// The report's inputs: curves from the training history, every view's virtual camera centres
/// (input frame), and a grid of up to `max_rows` deblurred training views.
pub fn report_input(
    output: &TrainOutput,
    data: &EvalData,
    eval: &Evaluation,
    max_rows: usize,
) -> ReportInput {
    let norm = &output.normalization;
    let centre = |p: &Pose| -> [f64; 3] { norm.invert_point(&se3(p).trans).into() };
    let grid = eval
        .deblur_views
        .iter()
        .zip(&eval.deblur.renders)
        .filter_map(|(&v, render)| {
            let view = &output.views[v];
            let blurry = data.train_blurry.get(v)?.clone()?;
            Some(GridRow {
                name: view.name.clone(),
                width: view.intrinsics.width,
                height: view.intrinsics.height,
                blurry,
                edi: data.train_edi.get(v).cloned().flatten(),
                ours: render.clone(),
                gt: data.train_gt.get(v).cloned().flatten(),
            })
        })
        .take(max_rows)
        .collect();
    ReportInput {
        title: "gems: sharp Gaussian splatting from motion-blurred photos".into(),
        metrics: eval.metrics.clone(),
        loss: output.history.loss.clone(),
        psnr: output.history.psnr.clone(),
        trajectories: output
            .views
            .iter()
            .map(|v| v.virtual_c2w.iter().map(centre).collect())
            .collect(),
        gt_centres: output
            .views
            .iter()
            .map(|v| v.c2w_gt.as_ref().map(centre))
            .collect(),
        gt_paths: output
            .views
            .iter()
            .map(|v| v.c2w_gt_subframes.iter().map(centre).collect())
            .collect(),
        grid,
        viewer: Some(viewer_scene(output, data)),
        registration: None,
    }
}

/// The interactive view's scene, in the trained result's normalised frame (where its cameras
/// live): the Gaussians, every training view at its mid-exposure pose with its exposure
/// trajectory and its blurry input and ground truth (when loaded) as toggles, and every
/// held-out view at its initial pose with its ground truth.
pub fn viewer_scene(output: &TrainOutput, data: &EvalData) -> ViewerScene {
    let mut scene = ViewerScene {
        gaussians: output.gaussians.clone(),
        ..Default::default()
    };
    let mut image = |stem: &str, label: &str, k: &Intrinsics, img: Option<&Vec<f32>>| {
        let img = img?;
        let rel = format!("report/viewer/{stem}_{}.png", label.replace(' ', "_"));
        scene.image_files.push((
            rel.clone(),
            gems_data::ImageRgb {
                width: k.width,
                height: k.height,
                data: img.iter().map(|v| v.clamp(0.0, 1.0)).collect(),
            },
        ));
        Some((label.to_owned(), rel))
    };
    let mut cameras = Vec::new();
    for (i, v) in output.views.iter().enumerate() {
        let k = &v.intrinsics;
        let stem = format!("train_{}", file_stem(&v.name));
        let images = [
            image(
                &stem,
                "blurry input",
                k,
                data.train_blurry.get(i).and_then(Option::as_ref),
            ),
            image(
                &stem,
                "ground truth",
                k,
                data.train_gt.get(i).and_then(Option::as_ref),
            ),
        ];
        cameras.push(ViewerCamera {
            name: v.name.clone(),
            kind: CameraKind::Train,
            camera: Camera::from_c2w(k, &se3(&v.mid_c2w)),
            trajectory: v
                .virtual_c2w
                .iter()
                .map(|p| se3(p).trans.map(|x| x as f32).into())
                .collect(),
            images: images.into_iter().flatten().collect(),
        });
    }
    for h in &data.held_out {
        let stem = format!("held_out_{}", file_stem(&h.name));
        let images = image(&stem, "ground truth", &h.intrinsics, Some(&h.gt));
        cameras.push(ViewerCamera {
            name: h.name.clone(),
            kind: CameraKind::HeldOut,
            camera: Camera::from_c2w(&h.intrinsics, &h.c2w_init),
            trajectory: Vec::new(),
            images: images.into_iter().collect(),
        });
    }
    scene.cameras = cameras;
    scene
}

/// Opens the scene a result was trained on at the training resolution: the downscale factor is
/// inferred from the first training view found in the scene (full-resolution width / trained
/// width). `opts` carries what training was given: the hold-out interval, the cache folder for
/// downscaled copies the scene lacks (never the scene), the time unit; its `downscale` is ignored.
pub fn open_scene_for(
    output: &TrainOutput,
    root: &Path,
    opts: &OpenOptions,
) -> Result<Scene, EvalError> {
    let full = open_scene(
        root,
        &OpenOptions {
            downscale: 1,
            ..opts.clone()
        },
    )?;
    let factor = output
        .views
        .iter()
        .find_map(|v| {
            let s = full.views.iter().find(|s| s.name == v.name)?;
            Some(
                (f64::from(s.width) / f64::from(v.intrinsics.width))
                    .round()
                    .max(1.0) as u32,
            )
        })
        .ok_or_else(|| {
            EvalError::Input(format!(
                "no training view of the result is in the scene {}",
                root.display()
            ))
        })?;
    if factor == 1 {
        return Ok(full);
    }
    Ok(open_scene(
        root,
        &OpenOptions {
            downscale: factor,
            ..opts.clone()
        },
    )?)
}

/// Writes the render images of a trained result under `dir/renders/`:
/// - `train/<view>_mid.png`, `_start.png`, `_end.png`: sharp renders at the trajectory's middle
///   and ends (the deblurred view and the exposure's extent);
/// - `train/<view>_reblurred.png`: the mean of the n virtual renders, i.e. what the blur model
///   fits to the blurry input;
/// - `nvs/<view>.png`: held-out views as evaluated (after test-time pose refinement).
///
/// Renders use a black background, like the evaluation, and are clamped to [0, 1] when saved.
pub fn write_renders(
    dir: &Path,
    output: &TrainOutput,
    data: &EvalData,
    eval: &Evaluation,
) -> Result<(), EvalError> {
    write_renders_on(&mut Engine::cpu(), dir, output, data, eval)
}

/// [`write_renders`] rendering with `engine` (`--device`).
pub fn write_renders_on(
    engine: &mut Engine,
    dir: &Path,
    output: &TrainOutput,
    data: &EvalData,
    eval: &Evaluation,
) -> Result<(), EvalError> {
    let train_dir = dir.join("renders").join("train");
    let nvs_dir = dir.join("renders").join("nvs");
    for d in [&train_dir, &nvs_dir] {
        std::fs::create_dir_all(d).map_err(|source| EvalError::Io {
            path: d.clone(),
            source,
        })?;
    }
    let save = |path: std::path::PathBuf, k: &Intrinsics, data: Vec<f32>| {
        let img = gems_data::ImageRgb {
            width: k.width,
            height: k.height,
            data,
        };
        gems_data::save_png(&path, &img).map_err(EvalError::from)
    };
    for (i, v) in output.views.iter().enumerate() {
        let burst = crate::export::render_exposure_burst(engine, output, i)?;
        let k = &burst.intrinsics;
        let stem = file_stem(&v.name);
        save(train_dir.join(format!("{stem}_mid.png")), k, burst.mid)?;
        if let (Some(first), Some(last)) = (burst.frames.first(), burst.frames.last()) {
            save(
                train_dir.join(format!("{stem}_start.png")),
                k,
                first.clone(),
            )?;
            save(train_dir.join(format!("{stem}_end.png")), k, last.clone())?;
            save(
                train_dir.join(format!("{stem}_reblurred.png")),
                k,
                burst.reblurred,
            )?;
        }
    }
    for (view, render) in data.held_out.iter().zip(&eval.nvs.renders) {
        let stem = file_stem(&view.name);
        save(
            nvs_dir.join(format!("{stem}.png")),
            &view.intrinsics,
            render.clone(),
        )?;
    }
    Ok(())
}

/// The sharp render of every training view at its mid-exposure pose (what
/// `renders/train/<view>_mid.png` shows), with the view's name, at the resolution `size_of`
/// gives for that name (e.g. the original photos' when training ran on downscaled copies;
/// `None`: the trained resolution). Black background, like [`write_renders`]; not clamped.
pub fn render_mid_exposure(
    engine: &mut Engine,
    output: &TrainOutput,
    size_of: &dyn Fn(&str) -> Option<(u32, u32)>,
) -> Result<Vec<(String, gems_data::ImageRgb)>, EvalError> {
    let settings = gems_splat::RenderSettings::default();
    output
        .views
        .iter()
        .map(|v| {
            let k = match size_of(&v.name) {
                Some((w, h)) => v.intrinsics.resized(w, h),
                None => v.intrinsics,
            };
            let cam = Camera::from_c2w(&k, &Se3::from(&v.mid_c2w));
            let out = engine.forward(&output.gaussians, &[cam], &[[0.0; 3]], &settings)?;
            let image = gems_data::ImageRgb {
                width: k.width,
                height: k.height,
                data: out.rgb,
            };
            Ok((v.name.clone(), image))
        })
        .collect()
}
