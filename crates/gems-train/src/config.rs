//! Training configuration: every constant of the method is a field, loadable from TOML.
//!
//! Defaults follow the GeMS paper where it states a value and the authors' trainer (PRISM3D)
//! where it is silent (`GopiRajuMatta/PRISM3D:prism3d_trainer.py` `DeblurConfig` and `train.sh`). PRISM3D nominally schedules over
//! 30 000 steps but stops at 7 000; our schedules are defined over the *run length* instead, and
//! the defaults are chosen so that a 7 000-step run reproduces PRISM3D's effective behaviour
//! (means lr ends at 0.01^(7/30) ≈ 0.341× its start, pose lr at 1e-3^(7/30) ≈ 0.200×).
//! Step windows (SH degree ramp, MCMC refinement window) are expressed as fractions of the run
//! length referred to the 7 000-step reference run, so a short run has the same shape. The MCMC
//! refinement *period* stays an absolute step count (gsplat: 100): each refinement grows the set
//! by 5 %, so a period that shrank with the run would multiply the Gaussians of a short run.

use gems_math::{BEZIER_DEFAULT_KNOTS, TrajectoryKind};
use serde::{Deserialize, Serialize};
use std::path::Path;

use crate::TrainError;

/// Length of the reference run whose behaviour the default schedules reproduce.
pub const REFERENCE_STEPS: usize = 7000;

/// Adam learning rates of the Gaussian parameter groups (gsplat / 3DGS values).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LearningRates {
    /// Means lr, multiplied by the scene scale.
    pub means: f32,
    /// Means lr at the last step as a fraction of the initial one (exponential decay).
    pub means_final_factor: f32,
    pub log_scales: f32,
    pub quats: f32,
    pub opacities: f32,
    pub sh_dc: f32,
    pub sh_rest: f32,
}

impl Default for LearningRates {
    fn default() -> Self {
        Self {
            means: 1.6e-4,
            means_final_factor: 0.01f32.powf(7.0 / 30.0),
            log_scales: 5e-3,
            quats: 1e-3,
            opacities: 5e-2,
            sh_dc: 2.5e-3,
            sh_rest: 2.5e-3 / 20.0,
        }
    }
}

/// Optimisation of the per-image trajectory knots.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PoseConfig {
    /// Optimise the trajectories at all (false = poses fixed at their initial value).
    pub optimize: bool,
    /// Adam learning rate of the knots. The paper and PRISM3D use 1e-3 with 25-step accumulation;
    /// with one Adam step per training step (`accumulate_steps = 1`) 3e-3 gave +1.8 / +1.0 dB
    /// refined deblurring and +1.5 / +0.8 dB refined novel views over 1e-3 on the two tuning
    /// seeds of `gems bench-quality`'s scenes at 1000 steps, and 1e-2 fell back (BENCHMARKS.md,
    /// "Quality").
    pub lr: f32,
    /// Pose lr at the last step as a fraction of the initial one. Default 1/15: with the 3e-3
    /// start, the final lr is 2e-4, the paper schedule's (1e-3 decayed to 1e-3^(7/30) ≈ 0.2 of
    /// it). Keeping the paper's factor 0.2 with the 3e-3 start left the poses jittering at the end:
    /// on the tuning seed it gained 0.4 dB refined deblurring from blurry inputs but cost the
    /// sharp-input ceiling 1.6 dB (BENCHMARKS.md, "Quality").
    pub lr_final_factor: f32,
    /// L2 weight decay added to the gradient (torch Adam semantics).
    pub weight_decay: f32,
    /// Knot gradients are summed over this many steps before one Adam step. PRISM3D sums over
    /// 25 (`GopiRajuMatta/PRISM3D:prism3d_trainer.py`); set 25 to reproduce it. Default 1 (an
    /// Adam step for the knots every step): on `gems bench-quality` scenes at 1500 steps it
    /// gave +2.3 dB (tuning seed) and +1.6 dB (held-out seed) refined deblurring and +1.4 /
    /// +1.2 dB refined novel views over 25, and 5 lay between (BENCHMARKS.md, "Quality").
    pub accumulate_steps: usize,
    /// Standard deviation of the N(0, σ²) initial knots (non-zero keeps Log/Exp away from 0/0).
    pub knot_init_std: f64,
    /// Weight of the uneven-speed energy Σ‖Log(Δ(u_k)⁻¹Δ(u_{k+1}))‖² of each step's virtual
    /// poses ([`gems_math::uneven_speed_energy`]), added to the loss. The blur model cannot tell
    /// how a path spends its exposure, so without it the pose at u = ½ may sit anywhere along
    /// the path; the energy makes it the middle. 0 = off (the GeMS paper).
    pub uneven_speed_weight: f64,
    /// Weight of the off-centre energy ‖Log Δ(½) − mean_k Log Δ(u_k)‖² of each step's virtual
    /// poses ([`gems_math::off_centre_energy`]), added to the loss: it keeps the reported sharp
    /// pose at u = ½ on the mean of the exposure's poses, which the blurry image fixes, instead of
    /// at one end of a hooked path. 0 = off (the GeMS paper). Default 10: on the two tuning
    /// seeds it raised the trajectory-midpoint deblurring (the sharp image gems outputs) by
    /// +2.2 / +0.7 dB and cut its gap to the refined figure from 3.5 / 2.7 dB to 0.9 / 0.7 dB, at
    /// a cost of 0.4 / 1.2 dB refined deblurring (lr 3e-3, final factor 0.2; BENCHMARKS.md,
    /// "Quality"). On the held-out seed the new pose defaults together cut that gap from 5.0 to
    /// 3.5 dB when training starts from ground-truth poses.
    pub off_centre_weight: f64,
    /// Which centre of the exposure's poses the off-centre energy holds u = ½ on: `mean` or
    /// `median` ([`gems_math::PathCentre`]). The median is the time-midpoint of a steadily
    /// moving path, where the mean is biased toward the inside of a bend (on `gems synth`
    /// exposures the true poses' mean projects 2.5 px RMS from the mid-exposure pose at 27 px
    /// of blur). Default `mean`: the median at weight 50 raised the midpoint deblurring from
    /// ground-truth poses by +0.4 dB (tuning seed, 1000 steps) and +0.5 dB (held-out seed,
    /// 3000 steps), but lost 1.0 / 1.5 dB at the midpoint from the built-in SfM's poses, and
    /// at weight 10 it lost there too (BENCHMARKS.md, "Quality").
    pub off_centre_target: gems_math::PathCentre,
    /// For this fraction of the schedule, after every knot Adam step, each view's knots are
    /// replaced by their least-squares straight line ([`gems_math::straighten_knots`]): the
    /// path opens to the blur as a constant-speed line and only bends afterwards. Trained
    /// freely from the start, most paths end hooked (they fold back on themselves, which the
    /// blur model cannot tell from a straight path of the same poses) and the pose at u = ½
    /// misses the mid-exposure one. 0 = off (the GeMS paper). Default 0: from ground-truth
    /// poses 0.15 gained +2.4 dB at the trajectory midpoint, +0.85 dB refined deblurring and
    /// +0.9 dB refined novel views (tuning seed, three training seeds, 1000 steps), but from the
    /// built-in SfM's poses it lost 0.7 dB refined deblurring and 1.0 dB novel views there, and
    /// on the held-out seed (3000 steps) it lost 0.8 dB of novel views and left the cameras twice as
    /// far from the truth (APE 0.090 against 0.046), while from ground-truth poses it gained +2.3 dB refined deblurring and
    /// +2.2 dB novel views there (BENCHMARKS.md, "Straight paths first"). Set 0.15 when the
    /// initial poses are accurate (a calibrated rig, COLMAP on sharp frames). Trainings from
    /// ground-truth poses, from a model made on a first pass's renders, and from the first
    /// model when those renders confirmed its cameras use
    /// `init.accurate_poses_straight_fraction` instead.
    pub straight_fraction: f64,
    /// Weight of the anchor energy ‖mean_k Log Δ(u_k)‖² ([`gems_math::anchor_energy`]), added
    /// to the loss: it holds each exposure's mean pose on its initial camera, so that accurate
    /// initial cameras (a dataset's COLMAP model) are not carried off by a shared drift of the
    /// paths. 0 = off (the GeMS paper), the default. On Deblur-NeRF's blurball trained from its
    /// COLMAP model (×8, 3000 steps) 100 raised the held-out views at the dataset's poses from
    /// 22.53 to 28.45 dB and refined from 28.08 to 28.72 dB (BENCHMARKS.md, "Real data"); on a
    /// generated scene from the SfM on its sharp frames +3.5 dB at the initial pose and half the
    /// camera drift, but from the SfM on its blurry photos −3.6 dB at the midpoint
    /// (BENCHMARKS.md, "Keeping accurate cameras"): for accurate starts only, where
    /// `hold_midpoint` has since scored higher (blurball 28.41 / 28.75 dB against 28.27 / 28.55
    /// in one build; `configs/accurate-cameras.toml` sets it instead).
    pub anchor_weight: f64,
    /// Each view's knot gradient is projected onto the directions that leave the pose at u = ½
    /// in place ([`gems_math::midpoint_tangent_gradient`]) before the knot Adam step, and after
    /// it (and the straight-path projection) the knots are shifted together so that the pose at
    /// u = ½ is the initial camera ([`gems_math::hold_midpoint`]): the exposure's midpoint stays
    /// where the initial model put it and only the path's shape is learned. Without the first
    /// half Adam's per-coordinate steps follow the photometric pull on the midpoint, which the
    /// shift undoes, and the paths barely learn their shape. A hard form of `anchor_weight`, for cameras
    /// measured more accurate than the blurry photos place them: the truth is not a stationary
    /// point of the joint training (BENCHMARKS.md, "Why accurate cameras drift"). Default false
    /// (the GeMS paper); runs from a confirmed first model use `init.confirmed_hold_midpoint`,
    /// and `configs/accurate-cameras.toml` sets it for cameras the user vouches for (blurball
    /// from its dataset's model: 28.41 dB at the dataset's pose, 28.75 refined, against 28.27 /
    /// 28.55 with `anchor_weight = 100`; BENCHMARKS.md, "Holding a confirmed model's
    /// midpoints").
    pub hold_midpoint: bool,
    /// Adam learning rate of the log of one factor on every view's focal lengths (a shared
    /// zoom about the principal points), learned from the photometric loss with the
    /// trajectories and decayed as their lr: an SfM's focal estimated from blurred photos can
    /// be 5–30 % off. The trained focal is the one every output (cameras, renders, evaluation)
    /// uses. 0 = the initial focal is kept (the GeMS paper), the default: at 3e-3 it brought one
    /// scene's focal from 15 % short to within 0.1 % of the truth but moved another's and
    /// blurball's further away, and no scene's renders gained beyond a training seed's spread
    /// (BENCHMARKS.md, "Learning the focal length").
    pub focal_lr: f32,
}

impl Default for PoseConfig {
    fn default() -> Self {
        Self {
            optimize: true,
            lr: 3e-3,
            lr_final_factor: 1.0 / 15.0,
            weight_decay: 1e-6,
            accumulate_steps: 1,
            knot_init_std: 1e-5,
            uneven_speed_weight: 0.0,
            off_centre_weight: 10.0,
            off_centre_target: gems_math::PathCentre::Mean,
            straight_fraction: 0.0,
            anchor_weight: 0.0,
            hold_midpoint: false,
            focal_lr: 0.0,
        }
    }
}

/// 3DGS-MCMC densification, gsplat `MCMCStrategy` semantics.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct McmcConfig {
    /// Upper bound on the number of Gaussians.
    pub cap_max: usize,
    /// Gaussians at or below this opacity are dead and get relocated.
    pub min_opacity: f32,
    /// Multiplicative growth per refinement (gsplat hard-codes 1.05).
    pub growth_factor: f64,
    /// SGLD noise multiplier (times the current means lr).
    pub noise_lr: f32,
    /// Refinement window as fractions of the run (×7000 = gsplat's 500/25000).
    pub refine_start_fraction: f64,
    pub refine_stop_fraction: f64,
    /// Refinement period in steps (gsplat: 100), independent of the run length.
    pub refine_every: usize,
    /// Opacity and scale regularisers added to the loss.
    pub opacity_reg: f32,
    pub scale_reg: f32,
}

impl Default for McmcConfig {
    fn default() -> Self {
        Self {
            cap_max: 500_000,
            min_opacity: 0.005,
            growth_factor: 1.05,
            noise_lr: 5e5,
            refine_start_fraction: 500.0 / REFERENCE_STEPS as f64,
            refine_stop_fraction: 25_000.0 / REFERENCE_STEPS as f64,
            refine_every: 100,
            opacity_reg: 0.01,
            scale_reg: 0.01,
        }
    }
}

/// Gaussian initialisation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InitConfig {
    pub opacity: f32,
    /// Initial scale = this × RMS distance to the `knn` nearest neighbours.
    pub scale_factor: f32,
    pub knn: usize,
    /// Number of points for random initialisation (no SfM points); at most `mcmc.cap_max`.
    pub random_points: usize,
    /// An SfM cloud sparser than this is topped up to this many points as `top_up` says
    /// (blurry images give sparse clouds, and MCMC grows a set by only 5 % per refinement);
    /// at most `mcmc.cap_max`.
    pub min_points: usize,
    /// Where the top-up points of a sparse SfM cloud go.
    pub top_up: TopUp,
    /// Depth range (in units of the scene scale) of random points inside the camera frustums.
    pub random_near: f32,
    pub random_far: f32,
    /// Fraction of `steps` spent on a first training whose sharp mid-exposure renders of the
    /// training views the image initialiser (the built-in SfM, or COLMAP run by gems) then
    /// reconstructs again, with the other views' photos as they are; the remaining steps train
    /// from that second model, so the run costs about the same. Under strong blur the blurry
    /// photos' tracks leave depth and camera rotation poorly determined; the renders' do not
    /// (BENCHMARKS.md, "Structure from motion on the first pass's renders"). It needs a first
    /// pass long enough to render sharp images (hundreds of steps). Read by gems-pipeline,
    /// which writes the first pass to `first_pass/` and the second model to `sfm_rerun/`; the
    /// run's own `config.toml` then holds the remaining steps and 0 here. From an imported
    /// COLMAP model the first pass only measures that model: the built-in SfM runs on its
    /// renders, the run proper trains from the imported model with all the steps, and holds its
    /// cameras (`confirmed_anchor_weight`) when the SfM confirmed them (`sfm_rerun_confirm_pct`).
    /// Ignored for ground-truth poses. 0: one pass.
    pub sfm_rerun_fraction: f32,
    /// The shortest first pass `sfm_rerun_fraction` runs: below it (short runs, tests, the demo's
    /// 1000 steps) the run is one pass, because a first pass of a few hundred steps does not yet
    /// render sharp enough images to help (measured from 1000 steps up).
    pub sfm_rerun_min_steps: usize,
    /// Before the run proper, both candidate models — the first one and the one initialised on
    /// the first pass's renders — train as their run propers would (the first model with all the
    /// steps, the renders' model with the rest and straight paths first; same seed and views),
    /// from scratch, for this fraction of the run proper's steps (at least one), and the renders'
    /// model is kept only when its probe fits the blurry photos better: a lower mean photometric
    /// loss over the probe's second half (`sfm_rerun/choice.json` records both). The kept
    /// model's run proper continues from its probe, so the probes cost this fraction of the
    /// run proper once. Default 0 (off: the renders' model is kept whenever it registers every
    /// trained view and does not confirm the first model, `sfm_rerun_confirm_pct`), because the choice depends on where the probe stops: on Deblur-NeRF's
    /// real `blurball`, where the first model is the better one (+1.0 dB on the held-out views,
    /// refined), and on `gems bench-quality`'s seed-5 scene, where the renders' model is (+1.8 dB
    /// refined deblurring, +3.2 dB refined novel views), 200 probe steps chose the first model
    /// on both, 400 chose right on both, 600 the renders' model on both (BENCHMARKS.md, "A
    /// probe to choose the renders' model").
    pub sfm_rerun_probe_fraction: f32,
    /// The renders' model is set aside, and the first model kept and treated as accurate
    /// (`accurate_poses_straight_fraction`), when the renders' model's cameras lie within this
    /// much of the first model's: the RMSE of the centres after the best similarity, in % of the
    /// first model's extent. An SfM on the first pass's renders that lands near the cameras the
    /// first pass started from confirms them: what it moved lies within the drift training gives
    /// accurate cameras (BENCHMARKS.md, "Why accurate cameras drift"); one that lands far from
    /// them found a correction the blurry photos' tracks hid. Measured (BENCHMARKS.md, "Keeping
    /// the first model when the renders' model confirms it"): on Deblur-NeRF's real `blurball`
    /// 1.36 %, where the first model scores higher on the held-out views; on generated scenes
    /// with 7–12 px of estimated blur 0.55–0.67 %, the first model's cameras 1.7–3.6× nearer
    /// the truth and its training +0.6 to +1.5 dB refined; on generated scenes with 15–29 px
    /// 1.82–23.5 %, the renders' cameras nearer the truth and their training better. 1.5 lies
    /// in the gap; one 14 px scene at 1.19 % was mixed (first model +0.35 dB refined, renders'
    /// model +0.9 dB at the midpoint). Checked before any probe (`sfm_rerun_probe_fraction`);
    /// `sfm_rerun/choice.json` records the figure. 0: never confirmed by this test.
    pub sfm_rerun_confirm_pct: f64,
    /// `sfm_rerun_confirm_pct` for an imported COLMAP model (`--init colmap`), which the
    /// renders' model never replaces: left unconfirmed, it trains with free paths from its own
    /// cameras, which the first pass and the run proper drift by 1.2–2.3 % of the extent when
    /// they are accurate (BENCHMARKS.md, "The check of an imported model measures the first pass
    /// now"). Measured (BENCHMARKS.md, "A wider bound for imported models"): four sharp-frame
    /// SfM models 0.03–0.46 % from the truth read 1.19–2.30 % with shares 0.02–0.18, and
    /// Deblur-NeRF's `blurball` from the dataset's own model 1.71 % (share 0.08), where holding
    /// it with the first pass's dense points scores +1.1 dB refined and +6.1 dB at the
    /// dataset's poses over training it free. The shape limit
    /// (`sfm_rerun_confirm_max_systematic`) applies as for any first model.
    pub sfm_rerun_confirm_imported_pct: f64,
    /// The largest share of that change (of its centres' squared differences, after their own
    /// best similarity) that may vary smoothly along the camera path — a quadratic in the
    /// position along the first model's principal axis
    /// ([`gems_math::CameraDiscrepancy::systematic_share`]) — for the renders' model to confirm
    /// the first model. The first pass moves accurate cameras each on its own (a blurry photo
    /// places its camera a little off), and corrects the bend an SfM on blurry photos gives the
    /// whole path. Measured on twelve first passes (BENCHMARKS.md, "The shape of the change"):
    /// 0.02–0.18 where the first model was accurate (four sharp-frame SfM models imported,
    /// 0.03–0.46 % from the truth, and blurball's own model and built-in SfM's) or nearer the
    /// truth than the renders' model; 0.42–0.79 where the first pass had straightened a bent path and the
    /// renders' model was nearer the truth (12–30 px of blur), among them a 15 px scene whose
    /// change, 1.35 %, the bound alone confirmed; trained from its renders' model instead, that
    /// scene gained 0.3 dB of refined deblurring and 0.6 dB of refined novel views, and lost
    /// 0.5 dB at the midpoint (one training seed). A failed SfM (17 % of the extent from the
    /// truth) that the first pass hardly moved read 0.15; its change, 3.2 %, is beyond the
    /// bound. With 14 views, independent per-camera changes give about 0.2 by chance. 1: the
    /// shape is not looked at (the rule before).
    pub sfm_rerun_confirm_max_systematic: f64,
    /// The renders' model is also set aside, as confirming the first model, when its cameras lie
    /// within this much (same measure) of the first pass's trained cameras, the poses the renders
    /// were made at: the rule before `sfm_rerun_confirm_pct`, default 0 (off) since. A small shift
    /// says the renders add no evidence beyond the first pass's cameras, not that the first
    /// model's are better: on a generated scene with 16 px of blur the shift was 0.43 % while the
    /// first pass had moved the cameras 2.1 % toward the truth, and the renders' model won by
    /// 1.1 dB refined; two 4–6 px scenes measured 0.37–0.38 %, where the first model was twice
    /// as accurate (BENCHMARKS.md, "Keeping the renders' model only when its cameras are its
    /// own"). `sfm_rerun/choice.json` records the shift either way.
    pub sfm_rerun_min_shift_pct: f64,
    /// `pose.straight_fraction` of a training whose initial poses are accurate: from ground-truth
    /// poses (`--init gt`), and the run proper after `sfm_rerun_fraction`, from the model made on
    /// the first pass's renders or, when the SfM on those renders confirmed the first model
    /// (`sfm_rerun_confirm_pct`, `sfm_rerun_min_shift_pct`), from the first model (at 8 px of blur
    /// +1.0 dB at the midpoint and +0.4 dB refined, at 4 px −0.2 / ±0.0 dB, on blurball's
    /// held-out views +1.0 dB at the dataset's poses and +0.1 dB refined; on a 4 px scene made
    /// afterwards +1.2 / +0.4 dB but −0.45 dB of refined novel views; BENCHMARKS.md,
    /// "Straight paths first from a first model its renders confirmed"; an imported COLMAP
    /// model so confirmed is such a first model). Every other training (from the blurry photos'
    /// SfM, an unconfirmed imported COLMAP model, perturbed ground truth, and the first pass)
    /// uses `pose.straight_fraction`.
    /// Straight paths first help when the initial poses are accurate and hurt from the blurry
    /// photos' SfM (see `pose.straight_fraction`). From ground-truth poses 0.15 gained +0.85 dB
    /// refined deblurring, +0.9 dB refined novel views and +2.4 dB at the trajectory midpoint
    /// (three training seeds, 1000 steps) and +2.3 / +2.2 / +2.9 dB on a held-out seed at 3000
    /// steps; the renders' SfM is accurate enough too: +1.3 / +0.9 dB refined deblurring, +1.0 /
    /// +0.4 dB refined novel views and +1.8 / +2.2 dB at the midpoint on seeds 4 and 5 of
    /// `gems bench-quality`'s scenes, 2000 steps from the same second models (BENCHMARKS.md,
    /// "Straight paths first" and "Structure from motion on the first pass's renders").
    /// 0 = no straight paths there either. Also read under its first name,
    /// `sfm_rerun_straight_fraction`.
    #[serde(alias = "sfm_rerun_straight_fraction")]
    pub accurate_poses_straight_fraction: f64,
    /// `pose.anchor_weight` of the run proper from a first model that the SfM on the first
    /// pass's renders confirmed (`sfm_rerun_confirm_pct`, `sfm_rerun_min_shift_pct`): those
    /// cameras are measured accurate, and training otherwise carries them off to where the
    /// blurry photos' optimum lies (BENCHMARKS.md, "Why accurate cameras drift"). The larger of
    /// this and the run's own `pose.anchor_weight` applies. Default 100 (the weight measured on
    /// blurball from the dataset's poses): on two generated scenes whose first model was
    /// confirmed (6 and 12 px of blur, 3000 steps) +0.1 / +2.5 dB at the trajectory midpoint,
    /// +0.2 / +0.05 dB refined, +3.7 / +6.2 dB on the novel views at their initial poses and
    /// +0.5 / ±0.0 dB refined, the cameras' drift 0.0055 → 0.0100 instead of 0.0129 on the
    /// first (BENCHMARKS.md, "Holding a confirmed first model's cameras"); from an imported
    /// sharp-frame SfM model so confirmed (a held-out seed) +0.6 dB at the midpoint, +0.35 dB
    /// refined, +4.6 dB on the novel views at their initial poses, the drift 2.7× less
    /// (BENCHMARKS.md, "An imported COLMAP model checked on its renders"). Applies only with
    /// `confirmed_hold_midpoint = false`. 0 = the run's own `pose.anchor_weight`.
    pub confirmed_anchor_weight: f64,
    /// `pose.hold_midpoint` of the run proper from a confirmed first model: its exposures'
    /// midpoints stay exactly on the confirmed cameras, and `confirmed_anchor_weight` is not
    /// applied. Default true: from an imported sharp-frame SfM model confirmed on the held-out
    /// seed 7 (3000 steps) +3.0 dB at the trajectory midpoint, +1.0 dB refined deblurring,
    /// +1.1 dB refined novel views and +2.7 dB at their initial poses against the anchor at
    /// 100, and the cameras end where they started (APE 0.0011 → 0.0011 instead of 0.0107;
    /// BENCHMARKS.md, "Holding a confirmed model's midpoints"); from blurball's built-in SfM
    /// model so confirmed (with dense points) +0.73 dB refined on the held-out views and +2.0 dB
    /// at the dataset's pose against free midpoints, where a 15 px scene whose confirmed
    /// cameras were 1.36 % off lost 1.47 dB refined (BENCHMARKS.md, "Holding a built-in SfM's
    /// confirmed model on blurball"; its focal was estimated under heavy blur, and such a model
    /// is no longer held: `confirmed_hold_blurred_focal`). false = the anchor.
    pub confirmed_hold_midpoint: bool,
    /// Whether a confirmed first model from the built-in SfM is held (`confirmed_hold_midpoint`
    /// or `confirmed_anchor_weight`) also when the SfM estimated its focal from photos blurred
    /// by more than 5 % of their long side (`gems_init::sfm::SfmStats::focal_barely_determined`:
    /// the models whose SfM report asks for `--focal`). The check cannot measure such a model:
    /// the first pass renders it with its own focal, so the SfM on the renders inherits that
    /// focal's error (on eight 15 px scenes with fields of view of 45–75° the estimate was
    /// 11–42 % off) and confirms cameras that training can still correct (1.36 % and 1.42 % of
    /// the path's extent from the truth on the two such scenes measured). Default false: such a
    /// model trains as a confirmed one otherwise does (all the steps, straight paths first,
    /// dense points) with free paths: on those two scenes +1.47 / +1.48 dB refined deblurring
    /// and +1.12 / +1.68 dB refined novel views against holding them, the midpoint +4.5 /
    /// −1.2 dB (BENCHMARKS.md, "A confirmed model whose focal blur left undetermined"). A focal
    /// given with `--focal` or read from EXIF (blurball: the hold gains 0.73 dB there), and an
    /// imported model's, are held as before.
    pub confirmed_hold_blurred_focal: bool,
    /// The run proper from a confirmed first model starts from that model's points and dense
    /// points from the first pass's depth maps (gems-pipeline's `dense` module: each training
    /// view's surface depth rendered at its trained midpoint, aligned to the model's sparse
    /// depths, back-projected from the confirmed camera, kept where two other views agree), up
    /// to `min_points` in all, instead of the sparse points topped up at random. The model with
    /// them is `sfm_rerun/dense/sparse/0`. Default true: from the imported sharp-frame SfM
    /// model of the held-out seed 7 (3000 steps, midpoints held) +0.4 dB refined deblurring and
    /// +0.3 dB refined novel views, where the generator's exact surface points give +1.65 dB;
    /// on seeds 8 and 9 (their choices confirmed by hand) +1.6 and +0.3 dB refined deblurring,
    /// +1.45 and +0.1 dB refined novel views (BENCHMARKS.md, "Surface depth for the dense
    /// points", "A third seed for the dense points"). false: the sparse points topped up.
    pub confirmed_dense_points: bool,
    /// The run proper from the model the SfM made on the first pass's renders starts from that
    /// model's points and dense points fused from the first pass's depth maps as with
    /// `confirmed_dense_points`, attached to the renders' model's own cameras (its images are
    /// those renders; each map is aligned to its sparse depths). The model with them is
    /// `sfm_rerun/dense/sparse/0`. Not after probes (`sfm_rerun_probe_fraction`), whose run
    /// proper continues from the kept probe. Default false: on three 15–16 px scenes (2000
    /// steps from their renders' models) refined deblurring +0.14 / +0.10 / −0.25 dB, the novel
    /// views at their initial poses +1.4 to +2.2 dB, the midpoint +1.5 / −0.4 / −0.5 dB
    /// (BENCHMARKS.md, "Holding a built-in SfM's confirmed model on blurball, and dense points
    /// for the renders' model"). false: the sparse points topped up.
    pub renders_dense_points: bool,
    /// σ, as a fraction of the focal, of the prior under which the built-in SfM refines a focal
    /// read from the photos' EXIF (gems-pipeline; `gems_init::sfm::EXIF_FOCAL_PRIOR`, whose value
    /// this default is). 0 holds the EXIF focal fixed. A focal given on the command line is
    /// always held (a calibration).
    pub exif_focal_prior: f64,
}

/// How a sparse SfM cloud is topped up to `min_points`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TopUp {
    /// Random points with random colours inside the camera frustums, at the cloud's depths.
    Frustums,
    /// Points scattered around the cloud's points (σ = their nearest-neighbour distance), with
    /// their colours.
    NearPoints,
}

impl Default for InitConfig {
    fn default() -> Self {
        Self {
            opacity: 0.5,
            scale_factor: 0.1,
            knn: 3,
            random_points: 100_000,
            min_points: 20_000,
            top_up: TopUp::NearPoints,
            random_near: 0.1,
            random_far: 3.0,
            sfm_rerun_fraction: 1.0 / 3.0,
            sfm_rerun_min_steps: 1000,
            sfm_rerun_probe_fraction: 0.0,
            sfm_rerun_confirm_pct: 1.5,
            sfm_rerun_confirm_imported_pct: 2.5,
            sfm_rerun_confirm_max_systematic: 0.3,
            sfm_rerun_min_shift_pct: 0.0,
            accurate_poses_straight_fraction: 0.15,
            confirmed_anchor_weight: 100.0,
            confirmed_hold_midpoint: true,
            confirmed_hold_blurred_focal: false,
            confirmed_dense_points: true,
            renders_dense_points: false,
            exif_focal_prior: 0.02,
        }
    }
}

/// Scene normalisation (PRISM3D: orient up, centre on the cameras, max |t| = 1, × 0.25).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NormalizeConfig {
    pub enabled: bool,
    pub scale_factor: f64,
    /// scene_scale = this × max camera distance from the centre (means lr, SGLD noise).
    pub scene_scale_margin: f64,
}

impl Default for NormalizeConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            scale_factor: 0.25,
            scene_scale_margin: 1.1,
        }
    }
}

/// Coarse-to-fine training: for the first `fraction` of the schedule the blurry image and the
/// renders are compared at `levels` octaves below full resolution, then one octave finer in equal
/// parts of that fraction, then at full resolution. The renders are made at the coarse size
/// (intrinsics scaled, [`Intrinsics::resized`](gems_math::Intrinsics::resized)) and the target is
/// the area-averaged image, so the loss sees the low frequencies only: a pose that is several
/// pixels off still lands inside the photometric basin there (the coarse-to-fine argument of
/// BARF, Lin et al. 2021, for joint pose and radiance-field optimisation). Off by default
/// (`levels = 0`, the GeMS paper): 2 levels over 0.3 of the run gained +0.6 dB refined
/// deblurring and +0.7 dB refined novel views from the built-in SfM's poses on the tuning seed
/// at 1000 steps, but on the held-out seed at 3000 steps +0.1 dB and −0.4 dB, within one
/// training seed's spread (BENCHMARKS.md, "Coarse to fine").
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CoarseToFineConfig {
    /// Octaves below full resolution at the start (0 = off; 2 = a quarter of the width). At
    /// most: images too small for a level (under the 11-pixel SSIM window) train their coarse
    /// part at the coarsest level that fits.
    pub levels: u32,
    /// Fraction of the schedule trained below full resolution.
    pub fraction: f64,
}

impl Default for CoarseToFineConfig {
    fn default() -> Self {
        Self {
            levels: 0,
            fraction: 0.3,
        }
    }
}

/// Largest `coarse_to_fine.levels`: a sixteenth of the width.
pub const MAX_COARSE_LEVELS: u32 = 4;

/// Everything that defines a training run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainConfig {
    pub steps: usize,
    pub seed: u64,
    /// Virtual sharp cameras per blurry image, at u = linspace(0, 1, n); with
    /// `virtual_view_spacing_px` > 0, the most a step renders.
    pub num_virtual_views: usize,
    /// Image-space distance, in pixels at the step's resolution, that adjacent virtual views
    /// may be apart: once counts adapt (`adaptive_views_from`), each step renders
    /// n = ⌈L / spacing⌉ + 1 virtual views (at most `num_virtual_views`; 1 when L is under half
    /// the spacing), where L is the longest spread of a scene point's images over the view's
    /// current trajectory ([`crate::blur::blur_length_px`]): a nearly sharp photo costs one
    /// render instead of n, as BAD-Gaussians users ask (adjacent views about a pixel apart).
    /// 0 = always `num_virtual_views` (the GeMS paper). Default 1 (BENCHMARKS.md, "Virtual
    /// views from the blur length").
    pub virtual_view_spacing_px: f64,
    /// Fraction of the run during which every step renders `num_virtual_views` before counts
    /// adapt: trajectories start as points (`pose.knot_init_std`) and learn their length with
    /// the full count first. Default 0.3, the coarse-to-fine phase's end.
    pub adaptive_views_from: f64,
    /// Virtual views each step backpropagates through, on the CPU engine: the step's n views
    /// are split into this many runs of consecutive views and one view is drawn from each
    /// (seeded by the run's seed and the step), its share of the blurry image's gradient
    /// weighted by its run's length. Every view's expected weight stays 1/n, so the gradient
    /// is an unbiased estimate of the full one, and one draw per run keeps every part of the
    /// exposure, hence every trajectory knot, in each step's gradient. The forward, the loss
    /// and the blur model are untouched; the backward, 40 % of a CPU step at n = 15, costs
    /// k/n of itself. 0 (or ≥ n) = every view (the GeMS paper), the default. The GPU engine
    /// always backpropagates every view. BENCHMARKS.md, "Backward through a subset of the
    /// virtual views".
    pub backward_virtual_views: usize,
    pub trajectory: TrajectoryKind,
    /// Control knots of the Bézier trajectory (9 = degree 8).
    pub bezier_knots: usize,
    /// SSIM weight λ in (1−λ)·L1 + λ·(1−SSIM).
    pub ssim_lambda: f32,
    pub sh_degree: u32,
    /// One more SH degree every this fraction of the run (×7000 = 1000 steps).
    pub sh_degree_interval_fraction: f64,
    /// Random background colour per step (else black).
    pub random_background: bool,
    pub adam_eps: f32,
    pub adam_beta1: f32,
    pub adam_beta2: f32,
    pub lr: LearningRates,
    pub pose: PoseConfig,
    pub mcmc: McmcConfig,
    pub init: InitConfig,
    pub normalize: NormalizeConfig,
    pub coarse_to_fine: CoarseToFineConfig,
    /// Checkpoint period in steps (0 = only at the end).
    pub checkpoint_every: usize,
    /// Progress log period in steps.
    pub log_every: usize,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            steps: REFERENCE_STEPS,
            seed: 0,
            num_virtual_views: 15,
            virtual_view_spacing_px: 1.0,
            adaptive_views_from: 0.3,
            backward_virtual_views: 0,
            trajectory: TrajectoryKind::Bezier,
            bezier_knots: BEZIER_DEFAULT_KNOTS,
            ssim_lambda: 0.3,
            sh_degree: 3,
            sh_degree_interval_fraction: 1000.0 / REFERENCE_STEPS as f64,
            random_background: true,
            adam_eps: 1e-15,
            adam_beta1: 0.9,
            adam_beta2: 0.999,
            lr: LearningRates::default(),
            pose: PoseConfig::default(),
            mcmc: McmcConfig::default(),
            init: InitConfig::default(),
            normalize: NormalizeConfig::default(),
            coarse_to_fine: CoarseToFineConfig::default(),
            checkpoint_every: 1000,
            log_every: 100,
        }
    }
}

impl TrainConfig {
    /// Reads a TOML file; missing fields take their defaults, unknown fields are an error.
    pub fn from_toml_file(path: &Path) -> Result<Self, TrainError> {
        let text = std::fs::read_to_string(path).map_err(|e| TrainError::io(path, e))?;
        let cfg: Self = toml::from_str(&text)
            .map_err(|e| TrainError::Config(format!("{}: {e}", path.display())))?;
        cfg.validate()
            .map_err(|e| TrainError::Config(format!("{}: {e}", path.display())))?;
        Ok(cfg)
    }

    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).expect("TrainConfig always serialises")
    }

    /// How `init.sfm_rerun_fraction` splits `steps`: the first pass's steps and the steps of the
    /// run from the second model, or `None` for one pass (also when the first pass would be
    /// shorter than `init.sfm_rerun_min_steps` or than one step, or leave no step).
    pub fn sfm_rerun_split(&self) -> Option<(usize, usize)> {
        let first = (f64::from(self.init.sfm_rerun_fraction) * self.steps as f64).round() as usize;
        (first >= self.init.sfm_rerun_min_steps.max(1) && first < self.steps)
            .then_some((first, self.steps - first))
    }

    /// Steps of each probe that chooses between the first model and the renders' model before a
    /// run proper of `rest` steps (`init.sfm_rerun_probe_fraction` of them, at least one);
    /// `None`: no probe.
    pub fn sfm_rerun_probe_steps(&self, rest: usize) -> Option<usize> {
        let fraction = f64::from(self.init.sfm_rerun_probe_fraction);
        (fraction > 0.0 && rest > 0)
            .then(|| ((fraction * rest as f64).round() as usize).clamp(1, rest))
    }

    /// Checks values that would make training meaningless or panic.
    pub fn validate(&self) -> Result<(), String> {
        if self.steps == 0 {
            return Err("steps must be > 0".into());
        }
        if self.num_virtual_views == 0 {
            return Err("num_virtual_views must be >= 1".into());
        }
        if !(self.virtual_view_spacing_px.is_finite() && self.virtual_view_spacing_px >= 0.0) {
            return Err("virtual_view_spacing_px must be finite and >= 0".into());
        }
        if !(0.0..=1.0).contains(&self.adaptive_views_from) {
            return Err("adaptive_views_from must be in [0, 1]".into());
        }
        if self.trajectory == TrajectoryKind::Bezier && self.bezier_knots < 1 {
            return Err("bezier_knots must be >= 1".into());
        }
        if !(0.0..=1.0).contains(&self.ssim_lambda) {
            return Err("ssim_lambda must be in [0, 1]".into());
        }
        if self.sh_degree > 3 {
            return Err("sh_degree must be <= 3".into());
        }
        if self.pose.accumulate_steps == 0 {
            return Err("pose.accumulate_steps must be >= 1".into());
        }
        if !(self.pose.uneven_speed_weight.is_finite() && self.pose.uneven_speed_weight >= 0.0) {
            return Err("pose.uneven_speed_weight must be finite and >= 0".into());
        }
        if !(self.pose.focal_lr.is_finite() && self.pose.focal_lr >= 0.0) {
            return Err("pose.focal_lr must be finite and >= 0".into());
        }
        if !(self.pose.anchor_weight.is_finite() && self.pose.anchor_weight >= 0.0) {
            return Err("pose.anchor_weight must be finite and >= 0".into());
        }
        if !(self.pose.off_centre_weight.is_finite() && self.pose.off_centre_weight >= 0.0) {
            return Err("pose.off_centre_weight must be finite and >= 0".into());
        }
        if !(0.0..=1.0).contains(&self.pose.straight_fraction) {
            return Err("pose.straight_fraction must be in [0, 1]".into());
        }
        if self.coarse_to_fine.levels > MAX_COARSE_LEVELS {
            return Err(format!(
                "coarse_to_fine.levels must be <= {MAX_COARSE_LEVELS}"
            ));
        }
        if !(0.0..=1.0).contains(&self.coarse_to_fine.fraction) {
            return Err("coarse_to_fine.fraction must be in [0, 1]".into());
        }
        if self.mcmc.cap_max == 0 {
            return Err("mcmc.cap_max must be >= 1".into());
        }
        if self.init.knn == 0 {
            return Err("init.knn must be >= 1".into());
        }
        if !(self.init.opacity > 0.0 && self.init.opacity < 1.0) {
            return Err("init.opacity must be in (0, 1)".into());
        }
        if !(0.0..1.0).contains(&self.init.sfm_rerun_fraction) {
            return Err("init.sfm_rerun_fraction must be in [0, 1)".into());
        }
        if !(0.0..=1.0).contains(&self.init.sfm_rerun_probe_fraction) {
            return Err("init.sfm_rerun_probe_fraction must be in [0, 1]".into());
        }
        if !(0.0..=1.0).contains(&self.init.sfm_rerun_confirm_max_systematic) {
            return Err("init.sfm_rerun_confirm_max_systematic must be in [0, 1]".into());
        }
        for (name, value) in [
            (
                "init.sfm_rerun_confirm_pct",
                self.init.sfm_rerun_confirm_pct,
            ),
            (
                "init.sfm_rerun_confirm_imported_pct",
                self.init.sfm_rerun_confirm_imported_pct,
            ),
            (
                "init.sfm_rerun_min_shift_pct",
                self.init.sfm_rerun_min_shift_pct,
            ),
            (
                "init.confirmed_anchor_weight",
                self.init.confirmed_anchor_weight,
            ),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(format!("{name} must be finite and >= 0"));
            }
        }
        if !(self.init.exif_focal_prior.is_finite() && self.init.exif_focal_prior >= 0.0) {
            return Err("init.exif_focal_prior must be finite and >= 0".into());
        }
        if !(0.0..=1.0).contains(&self.init.accurate_poses_straight_fraction) {
            return Err("init.accurate_poses_straight_fraction must be in [0, 1]".into());
        }
        Ok(())
    }

    /// The Gaussian groups' learning rates at `step` (the means lr decayed and scaled by the
    /// scene scale).
    pub fn gaussian_lrs(&self, step: usize, scene_scale: f32) -> gems_gpu::GaussianLrs {
        gems_gpu::GaussianLrs {
            means: self.means_lr(step, scene_scale),
            quats: self.lr.quats,
            log_scales: self.lr.log_scales,
            opacity_logits: self.lr.opacities,
            sh_dc: self.lr.sh_dc,
            sh_rest: self.lr.sh_rest,
        }
    }

    /// What the GPU engine's resident step takes at `step` ([`gems_gpu::ResidentStep::step`]):
    /// the loss weights, the MCMC regularisers, [`Self::gaussian_lrs`] and Adam's constants.
    pub fn step_settings(&self, step: usize, scene_scale: f32) -> gems_gpu::StepSettings {
        gems_gpu::StepSettings {
            ssim_lambda: self.ssim_lambda,
            opacity_reg: self.mcmc.opacity_reg,
            scale_reg: self.mcmc.scale_reg,
            lrs: self.gaussian_lrs(step, scene_scale),
            adam: gems_gpu::AdamConfig {
                beta1: self.adam_beta1,
                beta2: self.adam_beta2,
                eps: self.adam_eps,
                weight_decay: 0.0,
            },
            render: gems_splat::RenderSettings::default(),
        }
    }

    /// Number of trajectory control knots for the configured kind.
    pub fn num_knots(&self) -> usize {
        self.trajectory.knots(self.bezier_knots)
    }

    /// Exposure times of the virtual cameras: linspace(0, 1, n), endpoints included.
    pub fn virtual_times(&self) -> Vec<f64> {
        crate::blur::exposure_times(self.num_virtual_views)
    }

    /// Whether the virtual-view count adapts to the blur length at `step`.
    pub fn adapts_views_at(&self, step: usize) -> bool {
        self.virtual_view_spacing_px > 0.0 && step >= self.steps_of(self.adaptive_views_from)
    }

    /// Converts a fraction of the run into a step count (at least 1 for periods).
    pub(crate) fn steps_of(&self, fraction: f64) -> usize {
        (fraction * self.steps as f64).round().max(0.0) as usize
    }

    /// Octaves below full resolution at which `step` trains (0 = full resolution): the first
    /// `coarse_to_fine.fraction` of the run in `levels` equal parts, coarsest first.
    pub fn resolution_level(&self, step: usize) -> u32 {
        let c = &self.coarse_to_fine;
        let end = self.steps_of(c.fraction);
        if c.levels == 0 || step >= end {
            return 0;
        }
        let part = (step * c.levels as usize / end) as u32;
        c.levels - part
    }

    /// Means lr at `step` (exponential decay to `means_final_factor` at the last step).
    pub fn means_lr(&self, step: usize, scene_scale: f32) -> f32 {
        exp_decay(
            self.lr.means * scene_scale,
            self.lr.means_final_factor,
            step,
            self.steps,
        )
    }

    /// Trajectory lr at `step`.
    pub fn pose_lr(&self, step: usize) -> f32 {
        exp_decay(self.pose.lr, self.pose.lr_final_factor, step, self.steps)
    }

    /// Learning rate of the log focal factor at `step` (`pose.focal_lr`, decayed as the poses').
    pub fn focal_lr(&self, step: usize) -> f32 {
        exp_decay(
            self.pose.focal_lr,
            self.pose.lr_final_factor,
            step,
            self.steps,
        )
    }

    /// SH degree in use at `step` (gsplat: min(step / interval, max)).
    pub fn sh_degree_at(&self, step: usize) -> u32 {
        let interval = self.steps_of(self.sh_degree_interval_fraction).max(1);
        ((step / interval) as u32).min(self.sh_degree)
    }

    /// Whether MCMC relocation/growth runs after `step` (gsplat: start < step < stop, step % every == 0).
    pub fn is_refine_step(&self, step: usize) -> bool {
        let start = self.steps_of(self.mcmc.refine_start_fraction);
        let stop = self.steps_of(self.mcmc.refine_stop_fraction);
        let every = self.mcmc.refine_every.max(1);
        step > start && step < stop && step.is_multiple_of(every)
    }
}

/// lr0 · final^(step / total): gsplat's ExponentialLR with gamma = final^(1/total).
fn exp_decay(lr0: f32, final_factor: f32, step: usize, total: usize) -> f32 {
    let t = step as f64 / total.max(1) as f64;
    (lr0 as f64 * (final_factor as f64).powf(t)) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_follow_prism3d_effective_schedule() {
        let c = TrainConfig::default();
        // Means lr at the end of a 7k run of a 30k-step 0.01 decay: 0.01^(7/30).
        let ratio = c.means_lr(c.steps, 1.0) / c.means_lr(0, 1.0);
        assert!((ratio - 0.3412).abs() < 1e-3, "{ratio}");
        // The knots start 3× higher than PRISM3D's 1e-3 but end at its final lr, 1e-3 decayed by
        // 0.001^(7/30) ≈ 0.1995 over a 7k run.
        let end = c.pose_lr(c.steps);
        assert!((end - 1e-3 * 0.1995).abs() < 1e-6, "{end}");
        // SH degree +1 every 1000 steps, capped at 3.
        assert_eq!(c.sh_degree_at(999), 0);
        assert_eq!(c.sh_degree_at(1000), 1);
        assert_eq!(c.sh_degree_at(2999), 2);
        assert_eq!(c.sh_degree_at(6999), 3);
        // Refinement every 100 steps strictly inside (500, 25000).
        assert!(!c.is_refine_step(500));
        assert!(c.is_refine_step(600));
        assert!(!c.is_refine_step(650));
        assert!(c.is_refine_step(6900));
        assert_eq!(c.virtual_times().len(), 15);
        assert_eq!(c.virtual_times()[14], 1.0);
        assert_eq!(c.num_knots(), 9);
    }

    #[test]
    fn schedules_scale_with_run_length() {
        let c = TrainConfig {
            steps: 700,
            ..TrainConfig::default()
        };
        // Window (50, 2500) scales with the run; the period stays 100 steps.
        assert!(c.is_refine_step(100));
        assert!(!c.is_refine_step(50));
        assert!(!c.is_refine_step(60));
        assert_eq!((0..700).filter(|&s| c.is_refine_step(s)).count(), 6);
        assert_eq!(c.sh_degree_at(100), 1);
        let ratio = c.means_lr(700, 2.0) / c.means_lr(0, 2.0);
        assert!((ratio - 0.3412).abs() < 1e-3);
    }

    #[test]
    fn toml_round_trip_and_partial_files() {
        let c = TrainConfig::default();
        let back: TrainConfig = toml::from_str(&c.to_toml()).unwrap();
        assert_eq!(back, c);
        let partial: TrainConfig =
            toml::from_str("steps = 300\ntrajectory = \"spline\"\n[mcmc]\ncap_max = 10\n").unwrap();
        assert_eq!(partial.steps, 300);
        assert_eq!(partial.num_knots(), 4);
        assert_eq!(partial.mcmc.cap_max, 10);
        assert_eq!(partial.mcmc.min_opacity, 0.005);
        assert!(toml::from_str::<TrainConfig>("stepz = 3").is_err());
    }

    #[test]
    fn bad_file_error_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("bad.toml");
        std::fs::write(&p, "steps = 0").unwrap();
        let e = TrainConfig::from_toml_file(&p).unwrap_err().to_string();
        assert!(e.contains("bad.toml") && e.contains("steps"), "{e}");
        std::fs::write(&p, "[pose]\nstraight_fraction = 1.5").unwrap();
        let e = TrainConfig::from_toml_file(&p).unwrap_err().to_string();
        assert!(e.contains("straight_fraction"), "{e}");
        std::fs::write(&p, "[coarse_to_fine]\nlevels = 5").unwrap();
        let e = TrainConfig::from_toml_file(&p).unwrap_err().to_string();
        assert!(e.contains("coarse_to_fine.levels"), "{e}");
    }

    #[test]
    fn coarse_to_fine_runs_the_levels_coarsest_first_in_equal_parts() {
        let mut c = TrainConfig {
            steps: 1000,
            ..TrainConfig::default()
        };
        assert!((0..1000).all(|s| c.resolution_level(s) == 0));
        c.coarse_to_fine = CoarseToFineConfig {
            levels: 2,
            fraction: 0.3,
        };
        let levels: Vec<u32> = (0..1000).map(|s| c.resolution_level(s)).collect();
        assert_eq!(levels.iter().filter(|&&l| l == 2).count(), 150);
        assert_eq!(levels.iter().filter(|&&l| l == 1).count(), 150);
        assert_eq!(
            (levels[0], levels[149], levels[150], levels[299]),
            (2, 2, 1, 1)
        );
        assert!(levels[300..].iter().all(|&l| l == 0));
        c.coarse_to_fine.fraction = 0.0;
        assert_eq!(c.resolution_level(0), 0);
    }

    #[test]
    fn sfm_rerun_fraction_splits_the_steps_and_rejects_bad_values() {
        let mut c = TrainConfig {
            steps: 3000,
            ..TrainConfig::default()
        };
        assert_eq!(c.sfm_rerun_split(), Some((1000, 2000)), "the default");
        c.steps = 2990;
        assert_eq!(c.sfm_rerun_split(), None, "a first pass under 1000 steps");
        c.steps = 7000;
        assert_eq!(c.sfm_rerun_split(), Some((2333, 4667)));
        c.init.sfm_rerun_fraction = 0.0;
        assert_eq!(c.sfm_rerun_split(), None, "0: one pass");
        c.init.sfm_rerun_min_steps = 0;
        c.init.sfm_rerun_fraction = 0.5;
        c.steps = 1;
        assert_eq!(c.sfm_rerun_split(), None, "a first pass of no step");
        c.steps = 2;
        c.init.sfm_rerun_fraction = 0.9;
        assert_eq!(
            c.sfm_rerun_split(),
            None,
            "no step left for the second pass"
        );
        c.steps = 20;
        assert_eq!(c.sfm_rerun_split(), Some((18, 2)));
        c.init.sfm_rerun_fraction = 1.0;
        assert!(c.validate().unwrap_err().contains("sfm_rerun_fraction"));
        c.init.sfm_rerun_fraction = -0.1;
        assert!(c.validate().is_err());
        c.init.sfm_rerun_fraction = 0.5;
        assert!(c.validate().is_ok());
        c.init.accurate_poses_straight_fraction = 1.5;
        assert!(c.validate().unwrap_err().contains("straight_fraction"));
        c.init.accurate_poses_straight_fraction = 0.15;
        c.init.confirmed_anchor_weight = -1.0;
        assert!(
            c.validate()
                .unwrap_err()
                .contains("confirmed_anchor_weight")
        );
        // Configurations saved under the field's first name still load.
        let old: TrainConfig =
            toml::from_str("[init]\nsfm_rerun_straight_fraction = 0.25").unwrap();
        assert_eq!(old.init.accurate_poses_straight_fraction, 0.25);
    }

    #[test]
    fn the_rerun_probes_take_their_fraction_of_the_run_proper() {
        let mut c = TrainConfig::default();
        assert_eq!(c.sfm_rerun_probe_steps(2000), None, "off by default");
        c.init.sfm_rerun_probe_fraction = 0.1;
        assert_eq!(c.sfm_rerun_probe_steps(2000), Some(200));
        assert_eq!(c.sfm_rerun_probe_steps(3), Some(1), "at least one step");
        assert_eq!(c.sfm_rerun_probe_steps(0), None, "no run proper");
        c.init.sfm_rerun_probe_fraction = 1.0;
        assert_eq!(
            c.sfm_rerun_probe_steps(7),
            Some(7),
            "at most the run proper"
        );
        c.init.sfm_rerun_probe_fraction = 0.0;
        assert_eq!(c.sfm_rerun_probe_steps(2000), None, "0: no probe");
        c.init.sfm_rerun_probe_fraction = 1.5;
        assert!(
            c.validate()
                .unwrap_err()
                .contains("sfm_rerun_probe_fraction")
        );
        c.init.sfm_rerun_probe_fraction = -0.1;
        assert!(c.validate().is_err());
        c.init.sfm_rerun_probe_fraction = 0.0;
        for bad in [-0.5, f64::NAN, f64::INFINITY] {
            c.init.sfm_rerun_min_shift_pct = bad;
            assert!(
                c.validate()
                    .unwrap_err()
                    .contains("sfm_rerun_min_shift_pct")
            );
            c.init.sfm_rerun_min_shift_pct = 0.0;
            c.init.sfm_rerun_confirm_pct = bad;
            assert!(c.validate().unwrap_err().contains("sfm_rerun_confirm_pct"));
            c.init.sfm_rerun_confirm_pct = 1.5;
            c.init.sfm_rerun_confirm_imported_pct = bad;
            assert!(
                c.validate()
                    .unwrap_err()
                    .contains("sfm_rerun_confirm_imported_pct")
            );
            c.init.sfm_rerun_confirm_imported_pct = 2.5;
        }
        c.init.sfm_rerun_confirm_pct = 0.0;
        assert!(c.validate().is_ok());
        for bad in [-0.1, 1.5, f64::NAN] {
            c.init.sfm_rerun_confirm_max_systematic = bad;
            assert!(
                c.validate()
                    .unwrap_err()
                    .contains("sfm_rerun_confirm_max_systematic")
            );
        }
    }
}
