//! The trained result [`TrainOutput`] (`model.safetensors` + `model.json`) that evaluation,
//! rendering and export build on.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use gems_math::{Intrinsics, Pose, Trajectory};
use gems_splat::Gaussians;
use serde::{Deserialize, Serialize};

use crate::TrainError;
use crate::config::TrainConfig;
use crate::normalize::Normalization;
use crate::tensors::{TensorReader, TensorSet, add_gaussians, format_err, read, read_gaussians};
use crate::trainer::{History, TrainView, Trainer};

/// The trained trajectory of one training image (normalised frame, camera-to-world).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewResult {
    pub name: String,
    /// The camera as trained (the initial one times the learned focal factor).
    pub intrinsics: Intrinsics,
    pub c2w_init: Pose,
    /// Ground truth for APE: the scene's explicit pose, else the mid sub-frame of its sub-frame
    /// poses (the mid-exposure pose).
    pub c2w_gt: Option<Pose>,
    /// Ground-truth poses of the exposure's sharp sub-frames in time order (empty when unknown).
    #[serde(default)]
    pub c2w_gt_subframes: Vec<Pose>,
    /// Trajectory knots [ρ; φ].
    pub knots: Vec<[f64; 6]>,
    /// The n virtual camera poses c2w_init·Δ(u_k), u_k = linspace(0, 1, n).
    pub virtual_c2w: Vec<Pose>,
    /// The mid-exposure pose c2w_init·Δ(0.5).
    pub mid_c2w: Pose,
}

/// What the user ran, as the report and `metrics.json` open with: the protocol, the data, the
/// initialisation, the schedule, the device and what it cost. Filled by the pipeline that ran
/// the whole job (training alone knows none of it).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunDescription {
    /// The published protocol the run follows by name (`--protocol`), if any.
    pub protocol: Option<String>,
    /// The scene folder.
    pub scene: PathBuf,
    /// The dataset the folder looks like, and its layout.
    pub dataset: String,
    /// Image downscale factor.
    pub downscale: u32,
    /// Hold-out interval (`None`: none).
    pub hold: Option<i64>,
    /// Training views and held-out views with a sharp image.
    pub train_views: usize,
    pub held_out_views: usize,
    /// The initialisation as the user asked for it, and what it gave (e.g. "built-in SfM on the
    /// blurry photos, then again on the first pass's renders").
    pub init: String,
    /// Steps in all (a first pass and the run proper together).
    pub steps: usize,
    /// Virtual views per exposure (the most a step renders when counts adapt).
    pub virtual_views: usize,
    /// Virtual views a step rendered on average (`None` in outputs written before counts
    /// adapted).
    #[serde(default)]
    pub mean_virtual_views: Option<f64>,
    /// The splatting engine's device.
    pub device: String,
    /// Wall time from opening the scene to the end of training (initialisation included), s.
    pub wall_seconds: f64,
    /// The process's peak resident memory at the end of training, bytes (Linux `VmHWM`).
    pub peak_memory_bytes: Option<u64>,
}

/// What training produces; gems-eval renders, measures and exports from it.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainOutput {
    pub config: TrainConfig,
    /// Input → normalised frame; [`Normalization::gaussians_to_input_frame`] undoes it.
    pub normalization: Normalization,
    pub scene_scale: f32,
    pub init_label: String,
    /// Gaussians in the normalised frame, SH degree = the configured maximum.
    pub gaussians: Gaussians,
    pub views: Vec<ViewResult>,
    pub history: History,
    pub seconds: f64,
    pub steps: usize,
    /// The learned factor on the initial focal lengths (`pose.focal_lr`; 1 when not learned):
    /// the views' intrinsics already include it, a camera taken from the initial model does
    /// not.
    pub focal_factor: f64,
    /// The COLMAP model the initial poses came from, if any. Held-out views are evaluated from
    /// its poses (through the same normalisation), never from poses of another frame.
    pub pose_model: Option<PathBuf>,
    /// What the user ran (`None` for results of older versions or of a bare trainer).
    pub run: Option<RunDescription>,
}

#[derive(Serialize, Deserialize)]
struct OutputMeta {
    format: u32,
    config: TrainConfig,
    normalization: Normalization,
    scene_scale: f32,
    init_label: String,
    gaussians: usize,
    sh_degree: u32,
    views: Vec<ViewResult>,
    history: History,
    seconds: f64,
    steps: usize,
    #[serde(default = "unit_factor")]
    focal_factor: f64,
    #[serde(default)]
    pose_model: Option<PathBuf>,
    #[serde(default)]
    run: Option<RunDescription>,
}

/// The focal factor of outputs written before the focal was learned.
fn unit_factor() -> f64 {
    1.0
}

pub const MODEL_TENSORS: &str = "model.safetensors";
pub const MODEL_JSON: &str = "model.json";

impl TrainOutput {
    /// Collects the result of a (finished or interrupted) trainer from its host state: sync a
    /// trainer stepped by hand on the GPU engine first ([`Trainer::sync`]; `Trainer::run`
    /// ends synced).
    pub fn from_trainer(t: &Trainer) -> Self {
        let mut gaussians = t.state.gaussians.clone();
        gaussians.sh_degree = t.cfg.sh_degree;
        let views = t
            .views
            .iter()
            .enumerate()
            .map(|(v, view): (usize, &TrainView)| {
                let traj = t.trajectory(v);
                ViewResult {
                    name: view.name.clone(),
                    intrinsics: t.intrinsics(v),
                    c2w_init: Pose::from(&view.c2w_init),
                    c2w_gt: view.c2w_gt.as_ref().map(Pose::from),
                    c2w_gt_subframes: view.c2w_gt_subframes.iter().map(Pose::from).collect(),
                    knots: traj.knots().to_vec(),
                    virtual_c2w: t.virtual_poses(v).iter().map(Pose::from).collect(),
                    mid_c2w: Pose::from(&t.mid_pose(v)),
                }
            })
            .collect();
        Self {
            config: t.cfg.clone(),
            normalization: t.normalization.clone(),
            scene_scale: t.scene_scale,
            init_label: t.init_label.clone(),
            gaussians,
            views,
            history: t.state.history.clone(),
            seconds: t.state.seconds,
            steps: t.state.step,
            focal_factor: t.state.focal.factor(),
            pose_model: None,
            run: None,
        }
    }

    /// The trajectory Δ(u) of view `v`.
    pub fn trajectory(&self, v: usize) -> Trajectory {
        Trajectory::new(self.config.trajectory, self.views[v].knots.clone())
            .expect("knot count matches the kind: built by the trainer or checked by `load`")
    }

    /// Writes `model.safetensors` + `model.json` into `dir` (atomically).
    pub fn save(&self, dir: &Path) -> Result<(), TrainError> {
        let mut ts = TensorSet::default();
        add_gaussians(&mut ts, &self.gaussians);
        let tpath = dir.join(MODEL_TENSORS);
        let bytes = ts
            .serialize(HashMap::new())
            .map_err(|e| format_err(&tpath, e))?;
        gems_fs::write_atomic(&tpath, &bytes)?;
        let meta = OutputMeta {
            format: 1,
            config: self.config.clone(),
            normalization: self.normalization.clone(),
            scene_scale: self.scene_scale,
            init_label: self.init_label.clone(),
            gaussians: self.gaussians.len(),
            sh_degree: self.gaussians.sh_degree,
            views: self.views.clone(),
            history: self.history.clone(),
            seconds: self.seconds,
            steps: self.steps,
            focal_factor: self.focal_factor,
            pose_model: self.pose_model.clone(),
            run: self.run.clone(),
        };
        Ok(gems_fs::write_atomic(
            &dir.join(MODEL_JSON),
            &serde_json::to_vec_pretty(&meta).expect("output metadata serialises"),
        )?)
    }

    /// Reads what [`TrainOutput::save`] wrote.
    pub fn load(dir: &Path) -> Result<Self, TrainError> {
        let jpath = dir.join(MODEL_JSON);
        let meta: OutputMeta =
            serde_json::from_slice(&read(&jpath)?).map_err(|e| format_err(&jpath, e))?;
        // `trajectory()` builds each view's trajectory from these knots; a hand-edited or
        // mismatched `model.json` must fail here, with the file named, not panic there.
        let needed = meta.config.num_knots();
        if let Some(v) = meta.views.iter().find(|v| v.knots.len() != needed) {
            return Err(format_err(
                &jpath,
                format!(
                    "view {:?} has {} trajectory knots, but the {:?} trajectory of its config needs {needed}",
                    v.name,
                    v.knots.len(),
                    meta.config.trajectory,
                ),
            ));
        }
        let tpath = dir.join(MODEL_TENSORS);
        let bytes = read(&tpath)?;
        let r = TensorReader::new(&bytes, &tpath)?;
        let gaussians = read_gaussians(&r, meta.gaussians, meta.sh_degree)?;
        Ok(Self {
            config: meta.config,
            normalization: meta.normalization,
            scene_scale: meta.scene_scale,
            init_label: meta.init_label,
            gaussians,
            views: meta.views,
            history: meta.history,
            seconds: meta.seconds,
            steps: meta.steps,
            focal_factor: meta.focal_factor,
            pose_model: meta.pose_model,
            run: meta.run,
        })
    }
}
