//! Files: atomic writes, checkpoints (safetensors for tensors + JSON for the rest) and the
//! trained result [`TrainOutput`] that evaluation, rendering and export build on.
//!
//! Every file is written to a temporary file in the destination directory and renamed into
//! place, so a crash never leaves a half-written file. A checkpoint is a pair
//! `checkpoint.safetensors` + `checkpoint.json`; both carry the step and loading refuses a
//! mismatched pair.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use gems_math::{Intrinsics, Pose, Trajectory};
use gems_splat::{Gaussians, SH_COEFFS};
use safetensors::{Dtype, SafeTensors, tensor::TensorView};
use serde::{Deserialize, Serialize};

use crate::TrainError;
use crate::adam::AdamState;
use crate::adam::GaussianAdam;
use crate::config::TrainConfig;
use crate::normalize::Normalization;
use crate::trainer::{History, TrainState, TrainView, Trainer};

/// Writes `bytes` to `path` atomically (gems-data's temporary file + rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), TrainError> {
    gems_data::write_atomic(path, bytes).map_err(|e| match e {
        gems_data::DataError::Io { path, source } => TrainError::Io { path, source },
        other => TrainError::Format {
            path: path.to_path_buf(),
            reason: other.to_string(),
        },
    })
}

fn read(path: &Path) -> Result<Vec<u8>, TrainError> {
    std::fs::read(path).map_err(|e| TrainError::io(path, e))
}

fn format_err(path: &Path, reason: impl std::fmt::Display) -> TrainError {
    TrainError::Format {
        path: path.to_path_buf(),
        reason: reason.to_string(),
    }
}

/// Named f32 tensors to be written as one safetensors file.
#[derive(Default)]
struct TensorSet {
    tensors: Vec<(String, Vec<usize>, Vec<u8>)>,
}

impl TensorSet {
    fn add(&mut self, name: &str, shape: Vec<usize>, data: &[f32]) {
        self.tensors
            .push((name.to_owned(), shape, bytemuck::cast_slice(data).to_vec()));
    }

    fn serialize(&self, metadata: HashMap<String, String>) -> Result<Vec<u8>, String> {
        let views: Result<Vec<(String, TensorView<'_>)>, _> = self
            .tensors
            .iter()
            .map(|(n, s, d)| TensorView::new(Dtype::F32, s.clone(), d).map(|v| (n.clone(), v)))
            .collect();
        safetensors::serialize(views.map_err(|e| e.to_string())?, Some(metadata))
            .map_err(|e| e.to_string())
    }
}

/// Reads named f32 tensors of an expected element count.
struct TensorReader<'a> {
    st: SafeTensors<'a>,
    path: &'a Path,
}

impl<'a> TensorReader<'a> {
    fn new(bytes: &'a [u8], path: &'a Path) -> Result<Self, TrainError> {
        Ok(Self {
            st: SafeTensors::deserialize(bytes).map_err(|e| format_err(path, e))?,
            path,
        })
    }

    fn get(&self, name: &str, len: usize) -> Result<Vec<f32>, TrainError> {
        let t = self
            .st
            .tensor(name)
            .map_err(|e| format_err(self.path, format!("tensor {name}: {e}")))?;
        if t.dtype() != Dtype::F32 || t.data().len() != len * 4 {
            return Err(format_err(
                self.path,
                format!(
                    "tensor {name} is {:?} {:?}, expected {len} f32 values",
                    t.dtype(),
                    t.shape()
                ),
            ));
        }
        Ok(bytemuck::pod_collect_to_vec(t.data()))
    }
}

fn chunks<const W: usize>(v: &[f32]) -> Vec<[f32; W]> {
    v.chunks_exact(W)
        .map(|c| std::array::from_fn(|i| c[i]))
        .collect()
}

fn add_gaussians(ts: &mut TensorSet, g: &Gaussians) {
    let n = g.len();
    ts.add("means", vec![n, 3], bytemuck::cast_slice(&g.means));
    ts.add("quats", vec![n, 4], bytemuck::cast_slice(&g.quats));
    ts.add(
        "log_scales",
        vec![n, 3],
        bytemuck::cast_slice(&g.log_scales),
    );
    ts.add("opacity_logits", vec![n], &g.opacity_logits);
    ts.add("sh", vec![n, SH_COEFFS, 3], bytemuck::cast_slice(&g.sh));
}

fn read_gaussians(r: &TensorReader<'_>, n: usize, sh_degree: u32) -> Result<Gaussians, TrainError> {
    let sh = r.get("sh", n * SH_COEFFS * 3)?;
    Ok(Gaussians {
        means: chunks::<3>(&r.get("means", n * 3)?),
        quats: chunks::<4>(&r.get("quats", n * 4)?),
        log_scales: chunks::<3>(&r.get("log_scales", n * 3)?),
        opacity_logits: r.get("opacity_logits", n)?,
        sh: sh
            .chunks_exact(48)
            .map(|c| std::array::from_fn(|k| [c[3 * k], c[3 * k + 1], c[3 * k + 2]]))
            .collect(),
        sh_degree,
    })
}

/// Non-tensor part of a checkpoint.
#[derive(Serialize, Deserialize)]
struct CheckpointMeta {
    format: u32,
    step: usize,
    gaussians: usize,
    sh_degree: u32,
    adam_steps: [u64; 5],
    knot_adam_step: u64,
    /// u128 as a decimal string (JSON numbers are not that wide).
    rng_word_pos: String,
    order: Vec<u32>,
    order_pos: usize,
    history: History,
    seconds: f64,
    config: TrainConfig,
}

pub const CHECKPOINT_TENSORS: &str = "checkpoint.safetensors";
pub const CHECKPOINT_JSON: &str = "checkpoint.json";

/// Saves the trainer's full state into `dir` (two files, each written atomically). A trainer
/// stepped by hand on the GPU engine must be synced first ([`Trainer::sync`]; `Trainer::run`
/// syncs at checkpoint steps): a stale host copy is refused, never saved.
pub fn save_checkpoint(dir: &Path, t: &Trainer) -> Result<(), TrainError> {
    if !t.is_synced() {
        return Err(TrainError::Input(
            "the GPU-resident Gaussians were not downloaded: call Trainer::sync before saving a \
             checkpoint"
                .into(),
        ));
    }
    let s = &t.state;
    let n = s.gaussians.len();
    let mut ts = TensorSet::default();
    add_gaussians(&mut ts, &s.gaussians);
    let groups: [(&str, &AdamState); 5] = [
        ("means", &s.adam.means),
        ("quats", &s.adam.quats),
        ("log_scales", &s.adam.log_scales),
        ("opacity_logits", &s.adam.opacity_logits),
        ("sh", &s.adam.sh),
    ];
    for (name, a) in groups {
        ts.add(&format!("adam.{name}.m"), vec![n, a.width], &a.m);
        ts.add(&format!("adam.{name}.v"), vec![n, a.width], &a.v);
    }
    let nk = s.knots.len();
    ts.add("knots", vec![nk], &s.knots);
    ts.add("knot_adam.m", vec![nk], &s.knot_adam.m);
    ts.add("knot_adam.v", vec![nk], &s.knot_adam.v);
    ts.add("knot_grad_acc", vec![nk], &s.knot_grad_acc);
    let meta = HashMap::from([("step".to_owned(), s.step.to_string())]);
    let tpath = dir.join(CHECKPOINT_TENSORS);
    let bytes = ts.serialize(meta).map_err(|e| format_err(&tpath, e))?;
    write_atomic(&tpath, &bytes)?;
    let meta = CheckpointMeta {
        format: 1,
        step: s.step,
        gaussians: n,
        sh_degree: s.gaussians.sh_degree,
        adam_steps: [
            s.adam.means.step,
            s.adam.quats.step,
            s.adam.log_scales.step,
            s.adam.opacity_logits.step,
            s.adam.sh.step,
        ],
        knot_adam_step: s.knot_adam.step,
        rng_word_pos: s.rng_word_pos.to_string(),
        order: s.order.clone(),
        order_pos: s.order_pos,
        history: s.history.clone(),
        seconds: s.seconds,
        config: t.cfg.clone(),
    };
    let json = serde_json::to_vec(&meta).expect("checkpoint metadata serialises");
    write_atomic(&dir.join(CHECKPOINT_JSON), &json)
}

/// Whether `dir` holds a checkpoint.
pub fn has_checkpoint(dir: &Path) -> bool {
    dir.join(CHECKPOINT_JSON).is_file() && dir.join(CHECKPOINT_TENSORS).is_file()
}

/// Loads a checkpoint: the configuration it was written with and the state.
pub fn load_checkpoint(dir: &Path) -> Result<(TrainConfig, TrainState), TrainError> {
    let jpath = dir.join(CHECKPOINT_JSON);
    let meta: CheckpointMeta =
        serde_json::from_slice(&read(&jpath)?).map_err(|e| format_err(&jpath, e))?;
    let tpath = dir.join(CHECKPOINT_TENSORS);
    let bytes = read(&tpath)?;
    let r = TensorReader::new(&bytes, &tpath)?;
    let (_, header) = SafeTensors::read_metadata(&bytes).map_err(|e| format_err(&tpath, e))?;
    let tstep = header
        .metadata()
        .as_ref()
        .and_then(|m| m.get("step"))
        .cloned()
        .unwrap_or_default();
    if tstep != meta.step.to_string() {
        return Err(format_err(
            &tpath,
            format!(
                "tensors are from step {tstep} but {} says step {}",
                jpath.display(),
                meta.step
            ),
        ));
    }
    let n = meta.gaussians;
    let gaussians = read_gaussians(&r, n, meta.sh_degree)?;
    let adam_group = |name: &str, width: usize, step: u64| -> Result<AdamState, TrainError> {
        Ok(AdamState {
            width,
            step,
            m: r.get(&format!("adam.{name}.m"), n * width)?,
            v: r.get(&format!("adam.{name}.v"), n * width)?,
        })
    };
    let st = meta.adam_steps;
    let adam = GaussianAdam {
        means: adam_group("means", 3, st[0])?,
        quats: adam_group("quats", 4, st[1])?,
        log_scales: adam_group("log_scales", 3, st[2])?,
        opacity_logits: adam_group("opacity_logits", 1, st[3])?,
        sh: adam_group("sh", 48, st[4])?,
    };
    let nk =
        r.st.tensor("knots")
            .map_err(|e| format_err(&tpath, e))?
            .shape()
            .iter()
            .product();
    let state = TrainState {
        step: meta.step,
        gaussians,
        adam,
        knots: r.get("knots", nk)?,
        knot_adam: AdamState {
            width: 6,
            step: meta.knot_adam_step,
            m: r.get("knot_adam.m", nk)?,
            v: r.get("knot_adam.v", nk)?,
        },
        knot_grad_acc: r.get("knot_grad_acc", nk)?,
        rng_word_pos: meta
            .rng_word_pos
            .parse()
            .map_err(|e| format_err(&jpath, format!("rng_word_pos: {e}")))?,
        order: meta.order,
        order_pos: meta.order_pos,
        history: meta.history,
        seconds: meta.seconds,
    };
    Ok((meta.config, state))
}

/// The trained trajectory of one training image (normalised frame, camera-to-world).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewResult {
    pub name: String,
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
    /// The COLMAP model the initial poses came from, if any. Held-out views are evaluated from
    /// its poses (through the same normalisation), never from poses of another frame.
    pub pose_model: Option<PathBuf>,
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
    #[serde(default)]
    pose_model: Option<PathBuf>,
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
                    intrinsics: view.intrinsics,
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
            pose_model: None,
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
        write_atomic(&tpath, &bytes)?;
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
            pose_model: self.pose_model.clone(),
        };
        write_atomic(
            &dir.join(MODEL_JSON),
            &serde_json::to_vec_pretty(&meta).expect("output metadata serialises"),
        )
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
            pose_model: meta.pose_model,
        })
    }
}
