//! Whether the model initialised on the first pass's renders replaces the first one: decided
//! by how far its cameras lie from the first model's ([`renders_change`],
//! `init.sfm_rerun_confirm_pct`) and, when asked, from the first pass's trained ones
//! ([`renders_shift`], `init.sfm_rerun_min_shift_pct`, off by default), and, when asked, by how
//! well each fits the blurry photos after a short training (`init.sfm_rerun_probe_fraction`, off
//! by default); [`confirms_first_model`] is the rule.
//!
//! The renders' model helps when the blurry photos' tracks leave the first model distorted
//! (extreme blur) and can hurt when the first model was already good (Deblur-NeRF's real
//! `blurball`: photos at 2400×1600 with moderate blur, renders of a model trained at 300×200).
//! Neither can be compared with the truth; what both are for is fitting the photos, so each
//! trains as its run proper would (steps, schedule, straight paths, seed) for a short probe, and
//! the one whose blur model then reproduces the photos better is kept; its run proper continues
//! from its probe, so only the other probe's steps are extra. Measured, the choice depends on
//! where the probe stops — right on `blurball` and wrong on a generated extreme-blur scene at
//! 200 steps, right on both at 400, wrong on `blurball` at 600 (BENCHMARKS.md, "A probe to
//! choose the renders' model") — hence off by default. The two camera tests need no training.
//! Where the first model was accurate, the first pass drifts its cameras a little (as training
//! does from accurate cameras) and the SfM on its renders recovers them: the renders' model
//! lands within 0.6–0.7 % of the extent of the first model on generated scenes (1.4 % on
//! `blurball`), and the first model trains better. Where the blur distorted the first model,
//! the first pass moves its cameras toward the truth and the renders' model lands 1.8–23 % from
//! the first model, nearer the truth (BENCHMARKS.md, "Keeping the first model when the renders'
//! model confirms it"). The shift from the trained cameras separates the two only in a narrow
//! gap (0.38 to 0.43 %): it is small on both kinds of scene whenever the renders are
//! consistent with the cameras they were made at.

use std::path::{Path, PathBuf};

use gems_data::colmap::SparseModel;
use gems_gpu::Engine;
use gems_math::{CameraDiscrepancy, Pose, Se3};
use gems_train::{
    CHECKPOINT_JSON, CHECKPOINT_TENSORS, InitMode, TrainConfig, TrainOutput, Trainer, ViewResult,
    prepare_input, save_checkpoint,
};
use serde::{Deserialize, Serialize};

use crate::PipelineError;

/// The file in `sfm_rerun/` that records the choice.
const CHOICE_FILE: &str = "choice.json";

/// Which model the run proper trains from, and what it was chosen by. Written to
/// `sfm_rerun/choice.json`, so that a resumed run keeps the choice without training its first
/// pass and probes again.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RerunChoice {
    /// The run proper trains from the model initialised on the renders.
    pub kept: bool,
    /// Why, in words (the run's description quotes it).
    pub reason: String,
    /// Steps each probe trained (0: no probe ran).
    pub probe_steps: usize,
    /// Each probe's mean training loss over its second half ([`probe_score`]); `None` when no
    /// probe ran.
    pub loss_first_model: Option<f64>,
    pub loss_renders_model: Option<f64>,
    /// How far the renders' model's cameras lie from the first pass's trained ones
    /// ([`renders_shift`]): centres in % of their extent and rotations in degrees; `None` when
    /// not measured (no renders' model, or a choice written by an older version).
    #[serde(default)]
    pub shift_centre_pct: Option<f64>,
    #[serde(default)]
    pub shift_rotation_deg: Option<f64>,
    /// How far the renders' model's cameras lie from the first model's ([`renders_change`]),
    /// in the same units; `None` when not measured (as for the shift, or in a choice written by
    /// a version before `init.sfm_rerun_confirm_pct`).
    #[serde(default)]
    pub change_centre_pct: Option<f64>,
    #[serde(default)]
    pub change_rotation_deg: Option<f64>,
    /// The share of that change of the centres that varies smoothly along the camera path
    /// ([`CameraDiscrepancy::systematic_share`]); `None` as for the change (and in a choice
    /// written before `init.sfm_rerun_confirm_max_systematic`).
    #[serde(default)]
    pub change_systematic_share: Option<f64>,
    /// The renders' model was set aside because it confirms the first model
    /// ([`confirms_first_model`]): the SfM on renders of a scene trained from the first model
    /// recovered its cameras, so its run proper starts from accurate poses and has straight paths
    /// first, as every training from accurate poses does. `false` in a choice written by an
    /// older version (which trained those paths freely).
    #[serde(default)]
    pub first_model_confirmed: bool,
}

impl RerunChoice {
    /// The choice an earlier run wrote into `dir`, if any.
    pub fn read(dir: &Path) -> Result<Option<Self>, PipelineError> {
        let path = dir.join(CHOICE_FILE);
        if !path.is_file() {
            return Ok(None);
        }
        let bytes = std::fs::read(&path).map_err(|source| gems_fs::FsError {
            path: path.clone(),
            source,
        })?;
        serde_json::from_slice(&bytes)
            .map(Some)
            .map_err(|source| PipelineError::ReadChoice { path, source })
    }

    /// Writes the choice into `dir` (atomically).
    pub fn write(&self, dir: &Path) -> Result<PathBuf, PipelineError> {
        let path = dir.join(CHOICE_FILE);
        let json = serde_json::to_vec_pretty(self).expect("a choice serialises");
        gems_fs::write_atomic(&path, &json)?;
        Ok(path)
    }

    /// The choice from both probes' scores: the renders' model is kept only when its score is
    /// finite and lower than the first model's (a non-finite score never wins; a non-finite
    /// first score loses to any finite one).
    pub fn from_probes(probe_steps: usize, first: f64, renders: f64) -> Self {
        let kept = renders.is_finite() && (!first.is_finite() || renders < first);
        let relation = if kept { "below" } else { "not below" };
        Self {
            kept,
            reason: format!(
                "after {probe_steps} probe steps each, its loss against the blurry photos \
                 {renders:.4} is {relation} the first model's {first:.4}"
            ),
            probe_steps,
            loss_first_model: Some(first),
            loss_renders_model: Some(renders),
            shift_centre_pct: None,
            shift_rotation_deg: None,
            change_centre_pct: None,
            change_rotation_deg: None,
            change_systematic_share: None,
            first_model_confirmed: false,
        }
    }

    /// A choice made without probes (`reason` says why).
    pub fn without_probes(kept: bool, reason: String) -> Self {
        Self {
            kept,
            reason,
            probe_steps: 0,
            loss_first_model: None,
            loss_renders_model: None,
            shift_centre_pct: None,
            shift_rotation_deg: None,
            change_centre_pct: None,
            change_rotation_deg: None,
            change_systematic_share: None,
            first_model_confirmed: false,
        }
    }

    /// The choice with the measured [`renders_change`] and [`renders_shift`] recorded.
    pub fn with_measures(
        self,
        change: Option<CameraDiscrepancy>,
        shift: Option<CameraDiscrepancy>,
    ) -> Self {
        Self {
            shift_centre_pct: shift.map(|d| d.centre_pct),
            shift_rotation_deg: shift.map(|d| d.rotation_deg),
            change_centre_pct: change.map(|d| d.centre_pct),
            change_rotation_deg: change.map(|d| d.rotation_deg),
            change_systematic_share: change.map(|d| d.systematic_share),
            ..self
        }
    }
}

/// What confirms a first model ([`confirms_first_model`]); `init.sfm_rerun_confirm_pct`,
/// `init.sfm_rerun_confirm_max_systematic` and `init.sfm_rerun_min_shift_pct`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConfirmRule {
    /// The renders' model's cameras within this much of the first model's (centres, % of the
    /// extent) ...
    pub confirm_pct: f64,
    /// ... with at most this share of that change varying smoothly along the camera path
    /// ([`CameraDiscrepancy::systematic_share`]);
    pub max_systematic: f64,
    /// or within this much of the first pass's trained cameras.
    pub min_shift_pct: f64,
}

/// Whether the renders' model confirms the first model, which is then kept: its cameras lie
/// within `rule.confirm_pct` of the first model's ([`renders_change`]) and what they changed is
/// mostly each camera on its own, at most `rule.max_systematic` of it a smooth bend, stretch or
/// drift of the path; or they lie within `rule.min_shift_pct` of the first pass's trained
/// cameras ([`renders_shift`]). An unmeasured figure confirms nothing.
///
/// Why the shape of the change: the first pass moves accurate cameras each by its own small
/// amount (the blurry photos place each camera a little off, differently for each), and the
/// renders' SfM recovers where it took them; it corrects an SfM's errors on blurry photos,
/// which bend the whole path (crates/gems-init/BENCHMARKS.md, "Where the error under heavy blur
/// comes from: the path turns too little"), along the path (BENCHMARKS.md, "The shape of the
/// change: a first model confirmed only when its renders jitter it").
pub fn confirms_first_model(
    change: Option<CameraDiscrepancy>,
    shift: Option<CameraDiscrepancy>,
    rule: ConfirmRule,
) -> bool {
    change.is_some_and(|d| {
        d.centre_pct < rule.confirm_pct && d.systematic_share <= rule.max_systematic
    }) || shift.is_some_and(|d| d.centre_pct < rule.min_shift_pct)
}

/// How far the cameras of `renders_model` (the model initialised on the first pass's renders)
/// lie from the first pass's trained mid-exposure cameras, the poses the renders were made at,
/// over the views both hold ([`gems_math::camera_discrepancy`]); `None` when fewer than two
/// views fix the similarity.
///
/// Why: an SfM on renders of a scene consistent with its cameras recovers those cameras, and
/// then adds nothing the first pass had not; on renders of a scene distorted together with its
/// cameras (extreme blur) it recovers cameras of its own.
pub fn renders_shift(
    first: &TrainOutput,
    renders_model: &SparseModel,
) -> Option<CameraDiscrepancy> {
    discrepancy(first, renders_model, |v| &v.mid_c2w)
}

/// How far the cameras of `renders_model` lie from the first model's, the cameras the first
/// pass started from (its views' initial poses), over the views both hold; `None` as for
/// [`renders_shift`].
///
/// Why: training drifts accurate cameras a little and moves distorted ones toward the truth, and
/// the SfM on the renders recovers where the first pass took them; so a renders' model near the
/// first model confirms it, and one far from it holds a correction.
pub fn renders_change(
    first: &TrainOutput,
    renders_model: &SparseModel,
) -> Option<CameraDiscrepancy> {
    discrepancy(first, renders_model, |v| &v.c2w_init)
}

/// [`gems_math::camera_discrepancy`] of `renders_model`'s cameras carried onto the camera
/// `camera` picks from each of the first pass's views (camera-to-world poses).
fn discrepancy(
    first: &TrainOutput,
    renders_model: &SparseModel,
    camera: impl Fn(&ViewResult) -> &Pose,
) -> Option<CameraDiscrepancy> {
    let pairs: Vec<(Se3, Se3)> = first
        .views
        .iter()
        .filter_map(|v| {
            let img = renders_model.image_by_name(&v.name)?;
            Some((Se3::from(&img.pose()).inverse(), Se3::from(camera(v))))
        })
        .collect();
    gems_math::camera_discrepancy(&pairs)
}

/// A probe's score: the mean of its step losses over the second half of its steps (the first
/// half is dominated by how far the initial points are from a fit; every step's loss is that of
/// one training photo's blur model before the step's update). `NaN` for no steps.
pub fn probe_score(losses: &[f32]) -> f64 {
    let tail = &losses[losses.len() / 2..];
    tail.iter().map(|&l| f64::from(l)).sum::<f64>() / tail.len() as f64
}

/// Trains from `mode` with `cfg` — the configuration of the run proper this candidate would
/// have — for `steps` steps on `engine`, saves the trainer's checkpoint into `checkpoint` (a
/// folder, created if missing), and returns the probe's [`probe_score`] and the engine. The
/// checkpoint is exactly the run proper's state after `steps` steps, so the kept candidate's run
/// proper continues from it ([`continue_from`]) and only the other probe's steps are extra.
pub fn probe(
    scene: &gems_data::Scene,
    mode: &InitMode,
    cfg: &TrainConfig,
    steps: usize,
    engine: Engine,
    checkpoint: &Path,
) -> Result<(f64, Engine), PipelineError> {
    let input = prepare_input(scene, mode, cfg)?;
    let mut trainer = Trainer::new(cfg.clone(), input)?;
    trainer.set_engine(engine);
    let mut losses = Vec::with_capacity(steps);
    for _ in 0..steps.min(cfg.steps) {
        losses.push(trainer.step()?.photometric_loss);
    }
    trainer.sync()?;
    std::fs::create_dir_all(checkpoint).map_err(|source| PipelineError::CreateDir {
        path: checkpoint.to_path_buf(),
        source,
    })?;
    save_checkpoint(checkpoint, &trainer)?;
    let engine = trainer.set_engine(Engine::cpu());
    Ok((probe_score(&losses), engine))
}

/// Moves the checkpoint a [`probe`] saved in `probe_dir` into `output` (replacing any there) and
/// removes `probe_dir`: a run proper resumed from `output` then continues the probe.
pub fn continue_from(probe_dir: &Path, output: &Path) -> Result<(), PipelineError> {
    // Tensors first: a pair cut in between is refused by the step check when loading.
    for name in [CHECKPOINT_TENSORS, CHECKPOINT_JSON] {
        let from = probe_dir.join(name);
        std::fs::rename(&from, output.join(name))
            .map_err(|source| gems_fs::FsError { path: from, source })?;
    }
    remove_probe(probe_dir)
}

/// Removes a [`probe`]'s folder (nothing to do when it is absent).
pub fn remove_probe(probe_dir: &Path) -> Result<(), PipelineError> {
    match std::fs::remove_dir_all(probe_dir) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(gems_fs::FsError {
            path: probe_dir.to_path_buf(),
            source: e,
        }
        .into()),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_score_is_the_mean_of_the_second_half() {
        assert_eq!(probe_score(&[9.0, 9.0, 1.0, 3.0]), 2.0);
        assert_eq!(probe_score(&[9.0, 1.0, 2.0]), 1.5, "the middle step counts");
        assert_eq!(probe_score(&[4.0]), 4.0);
        assert!(probe_score(&[]).is_nan());
    }

    #[test]
    fn the_renders_model_is_kept_only_when_it_fits_better() {
        assert!(RerunChoice::from_probes(200, 0.12, 0.11).kept);
        assert!(!RerunChoice::from_probes(200, 0.11, 0.12).kept);
        assert!(
            !RerunChoice::from_probes(200, 0.11, 0.11).kept,
            "a tie keeps the first"
        );
        assert!(!RerunChoice::from_probes(200, 0.11, f64::NAN).kept);
        assert!(RerunChoice::from_probes(200, f64::NAN, 0.11).kept);
        let c = RerunChoice::from_probes(200, 0.2, 0.1);
        assert!(
            c.reason
                .contains("0.1000 is below the first model's 0.2000"),
            "{}",
            c.reason
        );
    }

    #[test]
    fn the_first_model_is_confirmed_by_a_renders_model_near_it() {
        let d = |centre_pct, systematic_share| {
            Some(CameraDiscrepancy {
                centre_pct,
                rotation_deg: 0.1,
                systematic_share,
            })
        };
        let rule = |confirm_pct, min_shift_pct| ConfirmRule {
            confirm_pct,
            max_systematic: 0.3,
            min_shift_pct,
        };
        // (change %, its systematic share), shift %, and the rule's (confirm %, min shift %).
        let confirmed = |(change, share), shift, (confirm, min_shift)| {
            confirms_first_model(d(change, share), d(shift, 0.0), rule(confirm, min_shift))
        };
        // Measured pairs (BENCHMARKS.md): blurball, and a 4 px scene (seed 25) whose shift from
        // the trained cameras exceeded the rule before; a 16 px scene (seed 10) with a small
        // shift, where the first pass had corrected the first model.
        assert!(confirmed((1.36, 0.17), 0.15, (1.5, 0.0)));
        assert!(confirmed((0.64, 0.1), 0.38, (1.5, 0.0)));
        assert!(!confirmed((2.22, 0.4), 0.43, (1.5, 0.0)));
        assert!(
            !confirms_first_model(d(1.5, 0.0), None, rule(1.5, 0.0)),
            "strictly within"
        );
        // A change within the bound that bends the path (seed 12) does not confirm, unless the
        // shape is not looked at.
        assert!(!confirms_first_model(d(1.35, 0.49), None, rule(1.5, 0.0)));
        let shape_ignored = ConfirmRule {
            max_systematic: 1.0,
            ..rule(1.5, 0.0)
        };
        assert!(confirms_first_model(d(1.35, 0.49), None, shape_ignored));
        // The shift confirms on its own when asked to.
        assert!(confirmed((2.22, 0.4), 0.43, (1.5, 0.5)));
        assert!(!confirmed((2.22, 0.4), 0.43, (0.0, 0.3)));
        // Nothing measured, nothing confirmed.
        assert!(!confirms_first_model(None, None, rule(1e9, 1e9)));
    }

    #[test]
    fn a_probe_checkpoint_moves_into_the_output_and_its_folder_goes() {
        let dir = tempfile::tempdir().unwrap();
        let (probe_dir, output) = (dir.path().join("probe"), dir.path().join("run"));
        std::fs::create_dir_all(&probe_dir).unwrap();
        std::fs::create_dir_all(&output).unwrap();
        std::fs::write(probe_dir.join(CHECKPOINT_TENSORS), b"tensors").unwrap();
        std::fs::write(probe_dir.join(CHECKPOINT_JSON), b"json").unwrap();
        std::fs::write(output.join(CHECKPOINT_JSON), b"an older run's").unwrap();
        continue_from(&probe_dir, &output).unwrap();
        assert_eq!(
            std::fs::read(output.join(CHECKPOINT_TENSORS)).unwrap(),
            b"tensors"
        );
        assert_eq!(
            std::fs::read(output.join(CHECKPOINT_JSON)).unwrap(),
            b"json"
        );
        assert!(!probe_dir.exists());
        remove_probe(&probe_dir).unwrap();
        let err = continue_from(&probe_dir, &output).unwrap_err();
        assert!(err.to_string().contains("probe"), "{err}");
    }

    #[test]
    fn a_choice_is_written_and_read_back() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(RerunChoice::read(dir.path()).unwrap(), None);
        let c = RerunChoice::from_probes(7, 0.25, 0.5);
        c.write(dir.path()).unwrap();
        assert_eq!(RerunChoice::read(dir.path()).unwrap(), Some(c));
        std::fs::write(dir.path().join(CHOICE_FILE), b"{").unwrap();
        let err = RerunChoice::read(dir.path()).unwrap_err();
        assert!(err.to_string().contains("choice.json"), "{err}");
    }
}
