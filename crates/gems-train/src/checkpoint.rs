//! Checkpoints: the trainer's whole state as `checkpoint.safetensors` (tensors) +
//! `checkpoint.json` (the rest). Both carry the step and loading refuses a mismatched pair;
//! resuming from one continues bit-identically.

use std::collections::HashMap;
use std::path::Path;

use safetensors::SafeTensors;
use serde::{Deserialize, Serialize};

use crate::TrainError;
use crate::adam::{AdamState, GaussianAdam};
use crate::config::TrainConfig;
use crate::tensors::{TensorReader, TensorSet, add_gaussians, format_err, read, read_gaussians};
use crate::trainer::{FocalState, History, TrainState, Trainer};

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
    /// Absent in checkpoints written before virtual-view counts adapted: those views keep the
    /// configured count.
    #[serde(default)]
    blur_depths: Vec<Option<[f32; 2]>>,
    /// Absent in checkpoints written before the focal was learned: factor 1.
    #[serde(default)]
    focal: FocalState,
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
    gems_fs::write_atomic(&tpath, &bytes)?;
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
        blur_depths: s.blur_depths.clone(),
        focal: s.focal.clone(),
        seconds: s.seconds,
        config: t.cfg.clone(),
    };
    let json = serde_json::to_vec(&meta).expect("checkpoint metadata serialises");
    Ok(gems_fs::write_atomic(&dir.join(CHECKPOINT_JSON), &json)?)
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
    let nk = r.element_count("knots")?;
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
        blur_depths: meta.blur_depths,
        focal: meta.focal,
        seconds: meta.seconds,
    };
    Ok((meta.config, state))
}
