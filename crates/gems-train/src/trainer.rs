//! The joint optimisation loop: Gaussians (Adam + 3DGS-MCMC) and per-image trajectories (Adam
//! with gradient accumulation), one blurry image per step through the blur model.
//!
//! Per step (gsplat ≥ 1.5 order): pick the next image of a per-epoch shuffled order, random
//! background, render its n virtual cameras in one call (for the first `coarse_to_fine`
//! fraction of the run at a coarser size, against the area-averaged image), average, fused loss
//! (1−λ)·L1 + λ·(1 − SSIM_valid) + MCMC regularisers, backward, Adam on every Gaussian group,
//! knot gradients summed and applied every `accumulate_steps` (and, for the first
//! `straight_fraction` of the run, the knots projected onto straight lines; with `hold_midpoint`,
//! the gradient and then the knots projected so that each exposure's midpoint stays on its
//! initial camera), then MCMC relocation/growth on refinement steps and SGLD noise with the
//! already decayed means lr.
//!
//! Everything that changes during training lives in [`TrainState`], which checkpoints save and
//! resume restores, so a resumed run continues bit-identically.
//!
//! On the GPU engine the step is resident (`gems_gpu::ResidentStep`): the Gaussians and their
//! Adam moments stay on the GPU between steps, and per step only the view's virtual cameras go
//! up and its per-camera pose gradients, loss and PSNR come back. The trajectories, their Adam
//! state, the view order, the random background and the MCMC draws stay on the CPU, in the same
//! code as the CPU engine's step. The SGLD noise is drawn on the GPU (Philox keyed by the seed
//! and the step) instead of from the trainer's ChaCha8 stream, so a GPU run does not retrace a
//! CPU run draw for draw; it is reproducible on its own (same seed, same adapter → same bits,
//! resume included). `state.gaussians` and `state.adam` are then a host copy, refreshed by
//! [`Trainer::sync`]: the trainer syncs at every `checkpoint_every`-th step and at the last
//! step (so [`Trainer::run`]'s callback sees a current state exactly when a checkpoint is due),
//! and [`Trainer::state`], [`Trainer::render_view`] and engine changes sync first;
//! [`crate::save_checkpoint`] refuses a stale copy.

use std::time::Instant;

use gems_gpu::{GroupMoments, NoiseParams, ResidentStep};
use gems_math::{Intrinsics, Se3, Trajectory};
use gems_metrics::TrainingLoss;
use gems_splat::{Camera, Gaussians, Gradients};
use rand::seq::SliceRandom;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::TrainError;
use crate::adam::GaussianAdam;
use crate::adam::{AdamHyper, AdamState};
use crate::blur::{
    BlurWorkspace, Exposure, Rasterizer, accumulate_knot_gradients, backward_blurred,
    backward_view_weights, render_blurred, virtual_cameras,
};
use crate::config::TrainConfig;
use crate::mcmc::{
    BinomialTable, add_new, growth_draws, inject_noise, relocate_dead, relocation_draws,
};
use crate::normalize::Normalization;
use gems_gpu::Engine;

/// One blurry training image, in the normalised frame.
#[derive(Clone, Debug)]
pub struct TrainView {
    pub name: String,
    /// Blurry RGB `[H,W,3]` in [0, 1].
    pub image: Vec<f32>,
    pub intrinsics: Intrinsics,
    /// Initial camera-to-world pose (from SfM, ground truth, or noisy ground truth).
    pub c2w_init: Se3,
    /// Ground-truth mid-exposure camera-to-world pose when known (for APE).
    pub c2w_gt: Option<Se3>,
    /// Ground-truth camera-to-world poses of the exposure's sharp sub-frames, in time order
    /// (empty when unknown), for the report's trajectory plot.
    pub c2w_gt_subframes: Vec<Se3>,
}

/// Everything training starts from.
#[derive(Clone, Debug)]
pub struct TrainInput {
    pub views: Vec<TrainView>,
    /// Initial Gaussians in the normalised frame.
    pub gaussians: Gaussians,
    pub normalization: Normalization,
    /// Scene extent (means lr and noise scale).
    pub scene_scale: f32,
    /// How the poses/points were initialised ("colmap", "gt", "gt-noisy (σ …)", "sfm", …).
    pub init_label: String,
}

/// Per-step training curves (kept for the report).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct History {
    pub loss: Vec<f32>,
    /// PSNR of the synthesised blurry image against the blurry input.
    pub psnr: Vec<f32>,
    pub gaussians: Vec<u32>,
    /// Training image index of each step.
    pub view: Vec<u32>,
    /// Virtual views each step rendered (`virtual_view_spacing_px`); empty in checkpoints
    /// written before counts adapted.
    #[serde(default)]
    pub virtual_views: Vec<u32>,
}

/// All mutable training state (exactly what a checkpoint holds).
#[derive(Clone, Debug, PartialEq)]
pub struct TrainState {
    /// Steps completed.
    pub step: usize,
    pub gaussians: Gaussians,
    pub adam: GaussianAdam,
    /// Knots of every view, `[V][K][6]` flat, [ρ; φ] each.
    pub knots: Vec<f32>,
    pub knot_adam: AdamState,
    /// Knot gradients summed since the last pose step.
    pub knot_grad_acc: Vec<f32>,
    /// ChaCha8 stream position (the seed comes from the config).
    pub rng_word_pos: u128,
    /// Current epoch's view order and the position in it.
    pub order: Vec<u32>,
    pub order_pos: usize,
    pub history: History,
    /// Per view, the scene depths its blur length is measured at ([`crate::blur_depths`] of the
    /// initial Gaussians): fixed at the start of a run, so that the virtual-view count does not
    /// depend on where the Gaussians are (host or GPU). `None` (or empty, in checkpoints written
    /// before counts adapted): the view always renders `num_virtual_views`.
    pub blur_depths: Vec<Option<[f32; 2]>>,
    /// The learned focal factor (`pose.focal_lr`).
    pub focal: FocalState,
    /// Wall-clock training seconds so far (excluded from bit-identity).
    pub seconds: f64,
}

/// The learned focal factor: `exp(log_scale)` multiplies every view's focal lengths, and Adam
/// steps on `log_scale` (so the factor stays positive and its steps are relative).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FocalState {
    pub log_scale: f32,
    pub adam: AdamState,
}

impl Default for FocalState {
    fn default() -> Self {
        Self {
            log_scale: 0.0,
            adam: AdamState::new(1, 1),
        }
    }
}

impl FocalState {
    /// The factor on the initial focal lengths.
    pub fn factor(&self) -> f64 {
        f64::from(self.log_scale).exp()
    }
}

/// What one step reports.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepReport {
    pub step: usize,
    /// What the step minimised: the photometric loss plus the MCMC regularisers and the
    /// trajectory energies.
    pub loss: f32,
    /// (1−λ)·L1 + λ·(1−SSIM) of the blur model against the step's photo alone (before the
    /// step's update): comparable between trainings whatever their Gaussians' scales.
    pub photometric_loss: f32,
    pub psnr: f32,
    pub gaussians: usize,
    /// Virtual views the step rendered.
    pub virtual_views: usize,
}

/// The trajectory of view `v` from the flat knot array.
pub fn trajectory_of(cfg: &TrainConfig, knots: &[f32], v: usize) -> Trajectory {
    let k = cfg.num_knots();
    let ks = knots[v * k * 6..(v + 1) * k * 6]
        .chunks_exact(6)
        .map(|c| std::array::from_fn(|i| c[i] as f64))
        .collect();
    Trajectory::new(cfg.trajectory, ks).expect("knot count comes from the config")
}

/// The Gaussians and Adam moments resident on the GPU, and whether `state` holds them.
struct Resident {
    step: ResidentStep,
    /// `state.gaussians` and `state.adam` equal the resident values.
    host_current: bool,
}

/// Where a GPU training run's steps spent their time ([`Trainer::gpu_profile`]): the steps'
/// wall clock against the GPU time of every kernel they ran. The gap is the host's work
/// (encoding, uploads, read-backs, the CPU's share of a step) and the GPU waiting for it.
#[derive(Clone, Debug, Default)]
pub struct GpuProfile {
    /// Steps profiled.
    pub steps: usize,
    /// Their summed wall-clock time, seconds.
    pub step_seconds: f64,
    /// Their kernels' GPU time, summed per kernel.
    pub kernels: gems_gpu::KernelTimes,
}

impl GpuProfile {
    /// A plain-text report: per step, the wall clock, the kernels' GPU time and the gap; then
    /// the kernels' table (slowest first) over all the steps.
    pub fn report(&self) -> String {
        let n = self.steps.max(1) as f64;
        let wall = 1e3 * self.step_seconds / n;
        let gpu = 1e3 * self.kernels.total_seconds() / n;
        format!(
            "{} steps: {wall:.3} ms a step on the wall clock, {gpu:.3} ms of it in GPU kernels, \
             {:.3} ms host work and idle GPU\n\n{}",
            self.steps,
            wall - gpu,
            self.kernels.table()
        )
    }
}

/// GPU memory held by a trainer's buffers ([`Trainer::gpu_memory`]), bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GpuMemory {
    /// The renderer's buffers (projection, sort, rasterization, gradients per entry).
    pub renderer_bytes: u64,
    /// The resident training state: Gaussians with their moments and gradients, the training
    /// images, the losses' and the per-step buffers.
    pub state_bytes: u64,
    /// The training images, part of `state_bytes`.
    pub image_bytes: u64,
}

impl std::fmt::Display for GpuMemory {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mib = |b: u64| b as f64 / (1u64 << 20) as f64;
        write!(
            f,
            "{:.1} MiB: renderer {:.1} MiB, training state {:.1} MiB (of which images {:.1} MiB)",
            mib(self.renderer_bytes + self.state_bytes),
            mib(self.renderer_bytes),
            mib(self.state_bytes),
            mib(self.image_bytes)
        )
    }
}

/// The trainer: configuration, data and state, plus reusable buffers.
pub struct Trainer {
    pub(crate) cfg: TrainConfig,
    pub(crate) views: Vec<TrainView>,
    pub(crate) normalization: Normalization,
    pub(crate) scene_scale: f32,
    pub(crate) init_label: String,
    /// Everything a checkpoint holds. On the GPU engine `gaussians` and `adam` are a host copy
    /// of the resident values as of the last [`Trainer::sync`] (module docs); the other fields
    /// are always current.
    pub(crate) state: TrainState,
    renderer: Engine,
    resident: Option<Resident>,
    /// Where the steps' time went, while the engine is [`Engine::profiled`].
    gpu_profile: Option<GpuProfile>,
    rng: ChaCha8Rng,
    losses: Vec<((u32, u32), TrainingLoss)>,
    ws: BlurWorkspace,
    d_blurred: Vec<f32>,
    knot_grads: Vec<[f64; 6]>,
    /// dL/d(log focal factor) of the current step.
    focal_grad: f64,
    binoms: BinomialTable,
    times: Vec<f64>,
    /// `coarse[l − 1][v]`: view `v` area-averaged `l` octaves down with its intrinsics, for
    /// the coarse-to-fine levels that fit the images (derived from `views`, not part of the
    /// checkpoint).
    coarse: Vec<Vec<(Intrinsics, Vec<f32>)>>,
}

/// Each view's image and intrinsics one to `levels` octaves below full resolution.
fn coarse_levels(views: &[TrainView], levels: u32) -> Vec<Vec<(Intrinsics, Vec<f32>)>> {
    let mut coarse = vec![Vec::with_capacity(views.len()); levels as usize];
    if levels == 0 {
        return coarse;
    }
    for v in views {
        let k = v.intrinsics;
        // One copy of the view as an image for all its levels.
        let full = gems_data::ImageRgb {
            width: k.width,
            height: k.height,
            data: v.image.clone(),
        };
        for (l, level) in (1..).zip(coarse.iter_mut()) {
            let (w, h) = gems_data::image::downscaled_size(k.width, k.height, 1 << l);
            let small = gems_data::image::downscale_area(&full, w, h);
            level.push((k.resized(w, h), small.data));
        }
    }
    coarse
}

/// How many of the configured coarse levels every view can take: the coarsest must leave each
/// image at least the SSIM window on either side (so the default also trains tiny images).
fn fitting_levels(levels: u32, views: &[TrainView]) -> u32 {
    (1..=levels)
        .take_while(|&l| {
            views.iter().all(|v| {
                let k = &v.intrinsics;
                let (w, h) = gems_data::image::downscaled_size(k.width, k.height, 1 << l);
                w as usize >= gems_metrics::SSIM_WINDOW && h as usize >= gems_metrics::SSIM_WINDOW
            })
        })
        .count() as u32
}

/// The intrinsics (focal lengths times `focal_factor`) and target image of view `v` at
/// `level` octaves below full resolution.
fn view_at_level<'a>(
    views: &'a [TrainView],
    coarse: &'a [Vec<(Intrinsics, Vec<f32>)>],
    v: usize,
    level: u32,
    focal_factor: f64,
) -> (Intrinsics, &'a [f32]) {
    let (k, image) = match level {
        0 => (views[v].intrinsics, views[v].image.as_slice()),
        l => {
            let (k, image) = &coarse[l as usize - 1][v];
            (*k, image.as_slice())
        }
    };
    (k.with_focal_scaled(focal_factor), image)
}

impl Trainer {
    /// The run's configuration.
    pub fn config(&self) -> &TrainConfig {
        &self.cfg
    }

    /// The training views, in the normalised frame.
    pub fn views(&self) -> &[TrainView] {
        &self.views
    }

    /// View `v`'s camera as trained: its initial intrinsics with the learned focal factor
    /// (`pose.focal_lr`; the initial ones when it is 0).
    pub fn intrinsics(&self, v: usize) -> Intrinsics {
        self.views[v]
            .intrinsics
            .with_focal_scaled(self.state.focal.factor())
    }

    /// Steps taken so far.
    pub fn steps_done(&self) -> usize {
        self.state.step
    }

    /// A fresh run: knots ~ N(0, knot_init_std²) from the seeded generator.
    pub fn new(cfg: TrainConfig, input: TrainInput) -> Result<Self, TrainError> {
        cfg.validate().map_err(TrainError::Config)?;
        if input.views.is_empty() {
            return Err(TrainError::Input("no training views".into()));
        }
        for v in &input.views {
            let k = &v.intrinsics;
            if v.image.len() != (k.width * k.height * 3) as usize {
                return Err(TrainError::Input(format!(
                    "view {}: image has {} values, intrinsics say {}x{}x3",
                    v.name,
                    v.image.len(),
                    k.width,
                    k.height
                )));
            }
        }
        input.gaussians.validate()?;
        let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
        let nk = cfg.num_knots() * 6 * input.views.len();
        let normal = rand_distr::Normal::new(0.0, cfg.pose.knot_init_std)
            .map_err(|e| TrainError::Config(e.to_string()))?;
        let knots: Vec<f32> = (0..nk)
            .map(|_| rand_distr::Distribution::sample(&normal, &mut rng) as f32)
            .collect();
        let n = input.gaussians.len();
        let blur_depths = input
            .views
            .iter()
            .map(|v| crate::blur_depths(&input.gaussians.means, &v.c2w_init, &v.intrinsics))
            .collect();
        let mut gaussians = input.gaussians;
        gaussians.sh_degree = 0;
        let state = TrainState {
            step: 0,
            gaussians,
            adam: GaussianAdam::new(n),
            knot_adam: AdamState::new(nk / 6, 6),
            knot_grad_acc: vec![0.0; nk],
            knots,
            rng_word_pos: 0,
            order: Vec::new(),
            order_pos: 0,
            history: History::default(),
            blur_depths,
            focal: FocalState::default(),
            seconds: 0.0,
        };
        let mut t = Self::assemble(
            cfg,
            input.views,
            input.normalization,
            input.scene_scale,
            input.init_label,
            state,
        );
        t.rng = rng;
        Ok(t)
    }

    /// Rebuilds a trainer around a saved state (resume).
    pub fn from_state(
        cfg: TrainConfig,
        views: Vec<TrainView>,
        normalization: Normalization,
        scene_scale: f32,
        init_label: String,
        state: TrainState,
    ) -> Result<Self, TrainError> {
        let expect = cfg.num_knots() * 6 * views.len();
        if !(state.blur_depths.is_empty() || state.blur_depths.len() == views.len()) {
            return Err(TrainError::Input(format!(
                "checkpoint does not match this run: blur depths of {} views for {} views",
                state.blur_depths.len(),
                views.len()
            )));
        }
        if state.knots.len() != expect || state.adam.means.rows() != state.gaussians.len() {
            return Err(TrainError::Input(format!(
                "checkpoint does not match this run: {} knot values (expected {expect}), {} Adam rows for {} Gaussians",
                state.knots.len(),
                state.adam.means.rows(),
                state.gaussians.len()
            )));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
        rng.set_word_pos(state.rng_word_pos);
        let mut t = Self::assemble(cfg, views, normalization, scene_scale, init_label, state);
        t.rng = rng;
        Ok(t)
    }

    fn assemble(
        cfg: TrainConfig,
        views: Vec<TrainView>,
        normalization: Normalization,
        scene_scale: f32,
        init_label: String,
        state: TrainState,
    ) -> Self {
        let times = cfg.virtual_times();
        let k = cfg.num_knots();
        let levels = fitting_levels(cfg.coarse_to_fine.levels, &views);
        if levels < cfg.coarse_to_fine.levels {
            tracing::info!(
                requested = cfg.coarse_to_fine.levels,
                used = levels,
                "coarse-to-fine: fewer levels fit these images"
            );
        }
        let coarse = coarse_levels(&views, levels);
        Self {
            coarse,
            rng: ChaCha8Rng::seed_from_u64(cfg.seed),
            times,
            knot_grads: vec![[0.0; 6]; k],
            focal_grad: 0.0,
            cfg,
            views,
            normalization,
            scene_scale,
            init_label,
            state,
            renderer: Engine::cpu(),
            resident: None,
            gpu_profile: None,
            losses: Vec::new(),
            ws: BlurWorkspace::default(),
            d_blurred: Vec::new(),
            binoms: BinomialTable::default(),
        }
    }

    /// Renders with `engine` from now on (the CPU engine by default) and returns the previous
    /// one. The engine is not part of the checkpointed state: a run may resume on another.
    /// State resident on a previous GPU stays there until the next step or [`Trainer::sync`],
    /// which move it to where the new engine needs it.
    ///
    /// A [profiled](Engine::profiled) engine makes the trainer sum every step's kernel times
    /// into [`Trainer::gpu_profile`], from this call on (what the engine ran before is dropped).
    pub fn set_engine(&mut self, engine: Engine) -> Engine {
        self.gpu_profile = engine.kernel_times().map(|_| GpuProfile::default());
        std::mem::replace(&mut self.renderer, engine)
    }

    /// Where the steps since [`Trainer::set_engine`] spent their time, when the engine is
    /// [profiled](Engine::profiled).
    pub fn gpu_profile(&self) -> Option<&GpuProfile> {
        self.gpu_profile.as_ref()
    }

    /// Downloads the resident Gaussians and Adam moments into `state` when the host copy is
    /// stale (a no-op on the CPU engine).
    pub fn sync(&mut self) -> Result<(), TrainError> {
        let Some(res) = &mut self.resident else {
            return Ok(());
        };
        if res.host_current {
            return Ok(());
        }
        let (mut g, moments) = res.step.download()?;
        g.sh_degree = self.state.gaussians.sh_degree;
        let a = &mut self.state.adam;
        for (dst, m) in [
            &mut a.means,
            &mut a.quats,
            &mut a.log_scales,
            &mut a.opacity_logits,
            &mut a.sh,
        ]
        .into_iter()
        .zip(moments)
        {
            dst.m = m.m;
            dst.v = m.v;
            dst.step = m.step;
        }
        self.state.gaussians = g;
        res.host_current = true;
        Ok(())
    }

    /// Whether `state` holds the current Gaussians and Adam moments (always on the CPU
    /// engine; on the GPU after [`Trainer::sync`] until the next step).
    pub fn is_synced(&self) -> bool {
        self.resident.as_ref().is_none_or(|r| r.host_current)
    }

    /// The whole state, synced first.
    pub fn state(&mut self) -> Result<&TrainState, TrainError> {
        self.sync()?;
        Ok(&self.state)
    }

    /// Bytes the resident GPU step has copied back to the CPU so far (0 on the CPU engine):
    /// per step the pose gradients and a few scalars, per refine step the opacities, per sync
    /// the whole state.
    pub fn gpu_bytes_read_back(&self) -> u64 {
        self.resident
            .as_ref()
            .map_or(0, |r| r.step.bytes_read_back())
    }

    /// GPU memory held by gems's own buffers now, on the GPU engine (`None` on the CPU): the
    /// renderer's (grown to its largest call and kept, so also their peak), the resident state's
    /// (Gaussians, Adam moments, gradients, losses, per-step buffers) and, of those, the
    /// training images'. The driver's figure for the process adds its context and allocator.
    pub fn gpu_memory(&self) -> Option<GpuMemory> {
        let Engine::Gpu(r) = &self.renderer else {
            return None;
        };
        let state = self.resident.as_ref();
        Some(GpuMemory {
            renderer_bytes: r.allocated_bytes(),
            state_bytes: state.map_or(0, |s| s.step.allocated_bytes()),
            image_bytes: state.map_or(0, |s| s.step.image_bytes()),
        })
    }

    /// Puts the Gaussians where the engine needs them: resident on its GPU, or in `state`.
    fn place_state(&mut self) -> Result<(), TrainError> {
        let device = match &self.renderer {
            Engine::Gpu(r) => Some(r.context().clone()),
            Engine::Cpu(_) => None,
        };
        if let (Some(ctx), Some(res)) = (&device, &self.resident)
            && res.step.context().device == ctx.device
        {
            return Ok(());
        }
        self.sync()?;
        self.resident = None;
        if let Some(ctx) = device {
            let a = &self.state.adam;
            let m = |s: &AdamState| GroupMoments {
                m: s.m.clone(),
                v: s.v.clone(),
                step: s.step,
            };
            let moments = [
                m(&a.means),
                m(&a.quats),
                m(&a.log_scales),
                m(&a.opacity_logits),
                m(&a.sh),
            ];
            self.resident = Some(Resident {
                step: ResidentStep::new(&ctx, &self.state.gaussians, Some(&moments))?,
                host_current: true,
            });
        }
        Ok(())
    }

    /// Live Gaussians.
    pub fn gaussian_count(&self) -> usize {
        match &self.resident {
            Some(r) => r.step.len(),
            None => self.state.gaussians.len(),
        }
    }

    /// The engine the trainer renders with.
    pub fn engine(&self) -> &Engine {
        &self.renderer
    }

    pub fn is_done(&self) -> bool {
        self.state.step >= self.cfg.steps
    }

    /// The trajectory of view `v`.
    pub fn trajectory(&self, v: usize) -> Trajectory {
        trajectory_of(&self.cfg, &self.state.knots, v)
    }

    fn next_view(&mut self) -> usize {
        if self.state.order_pos >= self.state.order.len() {
            let mut order: Vec<u32> = (0..self.views.len() as u32).collect();
            order.shuffle(&mut self.rng);
            self.state.order = order;
            self.state.order_pos = 0;
        }
        let v = self.state.order[self.state.order_pos] as usize;
        self.state.order_pos += 1;
        v
    }

    /// Octaves below full size at which `step` trains: the configured schedule, its coarser
    /// levels clamped to the coarsest that fits the images.
    fn resolution_level(&self, step: usize) -> u32 {
        self.cfg
            .resolution_level(step)
            .min(self.coarse.len() as u32)
    }

    /// The exposure times step `step` renders for view `v`: the configured count, or once
    /// counts adapt ([`TrainConfig::adapts_views_at`]) as many as the view's current blur length
    /// at this step's resolution needs ([`crate::virtual_view_count`]).
    fn render_times(&self, v: usize, traj: &Trajectory, step: usize) -> Vec<f64> {
        let depths = self.state.blur_depths.get(v).copied().flatten();
        let (Some(depths), true) = (depths, self.cfg.adapts_views_at(step)) else {
            return self.times.clone();
        };
        let level = self.resolution_level(step);
        let (k, _) = view_at_level(
            &self.views,
            &self.coarse,
            v,
            level,
            self.state.focal.factor(),
        );
        let length = crate::blur_length_px(&self.views[v].c2w_init, traj, &k, depths);
        let n = crate::virtual_view_count(
            length,
            self.cfg.virtual_view_spacing_px,
            self.cfg.num_virtual_views,
        );
        crate::exposure_times(n)
    }

    fn loss_for(&mut self, w: u32, h: u32) -> Result<usize, TrainError> {
        if let Some(i) = self.losses.iter().position(|(s, _)| *s == (w, h)) {
            return Ok(i);
        }
        let l = TrainingLoss::new(h as usize, w as usize, self.cfg.ssim_lambda)
            .map_err(|e| TrainError::Input(format!("loss for {w}x{h} images: {e}")))?;
        self.losses.push(((w, h), l));
        Ok(self.losses.len() - 1)
    }

    /// One optimisation step.
    pub fn step(&mut self) -> Result<StepReport, TrainError> {
        let start = Instant::now();
        self.place_state()?;
        let step = self.state.step;
        let sh_degree = self.cfg.sh_degree_at(step);
        self.state.gaussians.sh_degree = sh_degree;
        let v = self.next_view();
        let bg: [f32; 3] = if self.cfg.random_background {
            std::array::from_fn(|_| self.rng.random::<f32>())
        } else {
            [0.0; 3]
        };
        let traj = self.trajectory(v);
        for kg in &mut self.knot_grads {
            *kg = [0.0; 6];
        }
        let times = self.render_times(v, &traj, step);
        let (mut loss, photometric_loss, train_psnr) = if self.resident.is_some() {
            self.gaussian_step_resident(v, bg, &traj, &times, step, sh_degree)?
        } else {
            self.gaussian_step_host(v, bg, &traj, &times, step)?
        };
        // The trajectory energies sample the exposure at the configured count whatever this
        // step rendered: they are cheap and their weights were tuned at that count.
        if self.cfg.pose.optimize {
            loss += gems_math::uneven_speed_energy(
                &traj,
                &self.times,
                self.cfg.pose.uneven_speed_weight,
                &mut self.knot_grads,
            ) as f32;
            loss += gems_math::off_centre_energy(
                &traj,
                &self.times,
                self.cfg.pose.off_centre_target,
                self.cfg.pose.off_centre_weight,
                &mut self.knot_grads,
            ) as f32;
            loss += gems_math::anchor_energy(
                &traj,
                &self.times,
                self.cfg.pose.anchor_weight,
                &mut self.knot_grads,
            ) as f32;
        }
        self.pose_update(v, step);

        // MCMC after the optimizer step (gsplat ≥ 1.5), with the decayed lr.
        if self.cfg.is_refine_step(step) {
            let (moved, added) = self.refine()?;
            tracing::debug!(
                step,
                moved,
                added,
                total = self.gaussian_count(),
                "MCMC refine"
            );
        }
        let noise = self.cfg.means_lr(step + 1, self.scene_scale) * self.cfg.mcmc.noise_lr;
        let min_opacity = self.cfg.mcmc.min_opacity;
        match &mut self.resident {
            Some(res) => res.step.noise(&NoiseParams {
                seed: self.cfg.seed,
                step: step as u64,
                scale: noise,
                min_opacity,
            }),
            None => inject_noise(&mut self.state.gaussians, noise, min_opacity, &mut self.rng),
        }

        let count = self.gaussian_count();
        let h = &mut self.state.history;
        h.loss.push(loss);
        h.psnr.push(train_psnr);
        h.gaussians.push(count as u32);
        h.view.push(v as u32);
        h.virtual_views.push(times.len() as u32);
        self.state.step += 1;
        self.state.rng_word_pos = self.rng.get_word_pos();
        if let Some(res) = &mut self.resident {
            res.host_current = false;
            let every = self.cfg.checkpoint_every;
            let s = self.state.step;
            if s >= self.cfg.steps || (every > 0 && s.is_multiple_of(every)) {
                self.sync()?;
            }
        }
        if self.gpu_profile.is_some()
            && let Engine::Gpu(r) = &self.renderer
        {
            // Profiled, a step's wall clock covers its last kernel (the SGLD noise runs after
            // the last read-back), so that its kernels' time is part of it.
            gems_gpu::buffers::wait_idle(r.context())?;
        }
        let seconds = start.elapsed().as_secs_f64();
        self.state.seconds += seconds;
        if let Some(profile) = &mut self.gpu_profile
            && let Some(times) = self.renderer.kernel_times()
        {
            // After the wall clock stopped: reading the timestamps costs a submission and a
            // read-back that are no part of the step.
            profile.steps += 1;
            profile.step_seconds += seconds;
            profile.kernels.accumulate(&times?);
        }
        Ok(StepReport {
            step: self.state.step,
            loss,
            photometric_loss,
            psnr: train_psnr,
            gaussians: count,
            virtual_views: times.len(),
        })
    }

    /// Render, loss, backward, regularisers and Adam on the host-side Gaussians (any
    /// [`Rasterizer`]); returns (loss with the regularisers, photometric loss, PSNR) and leaves the knot gradients in `knot_grads`.
    fn gaussian_step_host(
        &mut self,
        v: usize,
        bg: [f32; 3],
        traj: &Trajectory,
        times: &[f64],
        step: usize,
    ) -> Result<(f32, f32, f32), TrainError> {
        let level = self.resolution_level(step);
        let focal = self.state.focal.factor();
        let (k, _) = view_at_level(&self.views, &self.coarse, v, level, focal);
        let li = self.loss_for(k.width, k.height)?;
        let (_, image) = view_at_level(&self.views, &self.coarse, v, level, focal);
        let view = &self.views[v];
        let exposure = Exposure {
            c2w_init: &view.c2w_init,
            trajectory: traj,
            times,
            intrinsics: &k,
        };
        render_blurred(
            &mut self.renderer,
            &self.state.gaussians,
            &exposure,
            bg,
            &mut self.ws,
        )?;
        self.d_blurred.resize(image.len(), 0.0);
        let lv = self.losses[li]
            .1
            .compute(&self.ws.blurred, image, &mut self.d_blurred)
            .map_err(|e| TrainError::Input(format!("view {}: {e}", view.name)))?;
        let train_psnr = gems_metrics::psnr_capped(&self.ws.blurred, image);
        let exposure = Exposure {
            c2w_init: &view.c2w_init,
            trajectory: traj,
            times,
            intrinsics: &k,
        };
        // On the CPU engine only: there the skipped views' time is saved (a GPU backpropagates
        // every view in about the time of one).
        let weights = match self.renderer {
            Engine::Cpu(_) => backward_view_weights(
                times.len(),
                self.cfg.backward_virtual_views,
                self.cfg.seed,
                step,
            ),
            Engine::Gpu(_) => None,
        };
        let mut grads = backward_blurred(
            &mut self.renderer,
            &self.state.gaussians,
            &exposure,
            &self.d_blurred,
            weights.as_deref(),
            &mut self.ws,
            &mut self.knot_grads,
        )?;
        self.focal_grad = log_focal_gradient(&self.ws.cams, &grads.cam_focal);
        let reg = add_regularizers(&self.cfg, &self.state.gaussians, &mut grads);
        self.adam_gaussians(&grads, step);
        Ok((lv.loss + reg, lv.loss, train_psnr))
    }

    /// The same on the GPU-resident Gaussians (`gems_gpu::ResidentStep`): only the pose
    /// gradients and the scalars come back.
    fn gaussian_step_resident(
        &mut self,
        v: usize,
        bg: [f32; 3],
        traj: &Trajectory,
        times: &[f64],
        step: usize,
        sh_degree: u32,
    ) -> Result<(f32, f32, f32), TrainError> {
        let level = self.resolution_level(step);
        let (Engine::Gpu(r), Some(res)) = (&mut self.renderer, &mut self.resident) else {
            return Err(TrainError::Input(
                "the resident step needs the GPU engine".into(),
            ));
        };
        let view = &self.views[v];
        let (k, image) = view_at_level(
            &self.views,
            &self.coarse,
            v,
            level,
            self.state.focal.factor(),
        );
        virtual_cameras(
            &Exposure {
                c2w_init: &view.c2w_init,
                trajectory: traj,
                times,
                intrinsics: &k,
            },
            &mut self.ws.cams,
        );
        let settings = self.cfg.step_settings(step, self.scene_scale);
        res.step.set_sh_degree(sh_degree);
        let out = res
            .step
            .step(r, v, image, &self.ws.cams, bg, &settings)
            .map_err(|e| match e {
                gems_gpu::GpuError::Shape(why) => {
                    TrainError::Input(format!("view {}: {why}", view.name))
                }
                other => other.into(),
            })?;
        accumulate_knot_gradients(
            traj,
            times,
            &self.ws.cams,
            &out.cam_rotation,
            &out.cam_translation,
            &mut self.knot_grads,
        );
        self.focal_grad = log_focal_gradient(&self.ws.cams, &out.cam_focal);
        Ok((out.loss, out.photometric_loss, out.psnr))
    }

    /// MCMC relocation then growth, on the host Gaussians or the resident ones (same draws
    /// from the trainer's generator); returns (relocated, added).
    fn refine(&mut self) -> Result<(usize, usize), TrainError> {
        let c = &self.cfg.mcmc;
        if let Some(res) = &mut self.resident {
            let opacities = res.step.opacity_logits()?;
            let (dead, sources) = relocation_draws(&opacities, c.min_opacity, &mut self.rng);
            let moved = res.step.relocate(&dead, &sources, c.min_opacity)?;
            let opacities = res.step.opacity_logits()?;
            let sources = growth_draws(&opacities, c.cap_max, c.growth_factor, &mut self.rng);
            let added = res.step.grow(&sources, c.min_opacity)?;
            return Ok((moved, added));
        }
        let moved = relocate_dead(
            &mut self.state.gaussians,
            &mut self.state.adam,
            c.min_opacity,
            &self.binoms,
            &mut self.rng,
        );
        let added = add_new(
            &mut self.state.gaussians,
            &mut self.state.adam,
            c.cap_max,
            c.growth_factor,
            c.min_opacity,
            &self.binoms,
            &mut self.rng,
        );
        Ok((moved, added))
    }

    fn adam_gaussians(&mut self, gr: &Gradients, step: usize) {
        let c = &self.cfg;
        let h = AdamHyper {
            beta1: c.adam_beta1,
            beta2: c.adam_beta2,
            eps: c.adam_eps,
        };
        let lrs = c.gaussian_lrs(step, self.scene_scale);
        self.state.adam.step(&mut self.state.gaussians, gr, &lrs, h);
    }

    fn pose_update(&mut self, v: usize, step: usize) {
        if !self.cfg.pose.optimize {
            return;
        }
        if self.cfg.pose.focal_lr > 0.0 {
            let c = &self.cfg;
            let h = AdamHyper {
                beta1: c.adam_beta1,
                beta2: c.adam_beta2,
                eps: c.adam_eps,
            };
            let f = &mut self.state.focal;
            f.adam.step(
                std::slice::from_mut(&mut f.log_scale),
                &[self.focal_grad as f32],
                c.focal_lr(step),
                0.0,
                h,
            );
        }
        let k = self.cfg.num_knots();
        let acc = &mut self.state.knot_grad_acc[v * k * 6..(v + 1) * k * 6];
        for (a, g) in acc.iter_mut().zip(self.knot_grads.iter().flatten()) {
            *a += *g as f32;
        }
        let every = self.cfg.pose.accumulate_steps;
        if step % every == every - 1 {
            let c = &self.cfg;
            let h = AdamHyper {
                beta1: c.adam_beta1,
                beta2: c.adam_beta2,
                eps: c.adam_eps,
            };
            if c.pose.hold_midpoint {
                for v in 0..self.views.len() {
                    let traj = trajectory_of(c, &self.state.knots, v);
                    let acc = &mut self.state.knot_grad_acc[v * k * 6..(v + 1) * k * 6];
                    let mut g: Vec<[f64; 6]> = acc
                        .chunks_exact(6)
                        .map(|g| std::array::from_fn(|i| g[i] as f64))
                        .collect();
                    gems_math::midpoint_tangent_gradient(&traj, &mut g);
                    for (a, g) in acc.chunks_exact_mut(6).zip(&g) {
                        for (a, g) in a.iter_mut().zip(g) {
                            *a = *g as f32;
                        }
                    }
                }
            }
            self.state.knot_adam.step(
                &mut self.state.knots,
                &self.state.knot_grad_acc,
                c.pose_lr(step),
                c.pose.weight_decay,
                h,
            );
            self.state.knot_grad_acc.fill(0.0);
            let straighten = step < c.steps_of(c.pose.straight_fraction);
            if straighten || c.pose.hold_midpoint {
                for v in 0..self.views.len() {
                    let mut traj = trajectory_of(c, &self.state.knots, v);
                    if straighten {
                        let mut line = traj.knots().to_vec();
                        gems_math::straighten_knots(&mut line);
                        traj = Trajectory::new(c.trajectory, line)
                            .expect("straightening keeps the knot count");
                    }
                    if c.pose.hold_midpoint {
                        // f32 knots: a residual far below their rounding is exact enough.
                        gems_math::hold_midpoint(&mut traj, 1e-10, 8);
                    }
                    let view = &mut self.state.knots[v * k * 6..(v + 1) * k * 6];
                    for (x, l) in view.chunks_exact_mut(6).zip(traj.knots()) {
                        for (x, l) in x.iter_mut().zip(l) {
                            *x = *l as f32;
                        }
                    }
                }
            }
        }
    }

    /// Runs to the configured number of steps, calling `on_step` after each.
    pub fn run(
        &mut self,
        mut on_step: impl FnMut(&Trainer, &StepReport) -> Result<(), TrainError>,
    ) -> Result<(), TrainError> {
        while !self.is_done() {
            let r = self.step()?;
            if r.step % self.cfg.log_every.max(1) == 0 || r.step == self.cfg.steps {
                tracing::debug!(
                    step = r.step,
                    loss = r.loss,
                    psnr = r.psnr,
                    gaussians = r.gaussians,
                    virtual_views = r.virtual_views,
                    "train"
                );
            }
            on_step(self, &r)?;
        }
        Ok(())
    }

    /// Mid-exposure (u = 0.5) camera-to-world pose of view `v`.
    pub fn mid_pose(&self, v: usize) -> Se3 {
        self.views[v].c2w_init * self.trajectory(v).eval(0.5)
    }

    /// The virtual camera-to-world poses of view `v`.
    pub fn virtual_poses(&self, v: usize) -> Vec<Se3> {
        crate::blur::virtual_c2w(&self.views[v].c2w_init, &self.trajectory(v), &self.times)
    }

    /// Renders view `v` from `c2w` with a black background (for evaluation and tests).
    pub fn render_view(&mut self, c2w: &Se3, k: &Intrinsics) -> Result<Vec<f32>, TrainError> {
        self.sync()?;
        let mut g = self.state.gaussians.clone();
        g.sh_degree = self.cfg.sh_degree;
        let cam = Camera::from_c2w(k, c2w);
        self.renderer.render(&g, &[cam], &[[0.0; 3]])
    }
}

/// dL/d(log of the focal factor) from the renderer's per-camera (dL/dfx, dL/dfy): the
/// derivative of f·s with respect to log s at s = 1 is f, so it is Σ fx·dL/dfx + fy·dL/dfy.
fn log_focal_gradient(cams: &[Camera], d_focal: &[[f32; 2]]) -> f64 {
    debug_assert_eq!(cams.len(), d_focal.len(), "one focal gradient per camera");
    cams.iter()
        .zip(d_focal)
        .map(|(c, g)| f64::from(c.fx) * f64::from(g[0]) + f64::from(c.fy) * f64::from(g[1]))
        .sum()
}

/// Adds the MCMC regularisers' gradients; returns their value.
/// opacity_reg·mean(sigmoid(l)) and scale_reg·mean(exp(log_scale)) over all N·3 entries.
fn add_regularizers(cfg: &TrainConfig, g: &Gaussians, grads: &mut Gradients) -> f32 {
    let n = g.len();
    if n == 0 {
        return 0.0;
    }
    let (or, sr) = (cfg.mcmc.opacity_reg, cfg.mcmc.scale_reg);
    let mut value = 0.0f64;
    for (i, &l) in g.opacity_logits.iter().enumerate() {
        let s = gems_splat::activation::sigmoid(l);
        value += (or * s) as f64 / n as f64;
        grads.opacity_logits[i] += or * s * (1.0 - s) / n as f32;
    }
    for (ls, gr) in g.log_scales.iter().zip(grads.log_scales.iter_mut()) {
        for (l, d) in ls.iter().zip(gr.iter_mut()) {
            let e = l.exp();
            value += (sr * e) as f64 / (3 * n) as f64;
            *d += sr * e / (3 * n) as f32;
        }
    }
    value as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regularizer_gradients_match_finite_differences() {
        let cfg = TrainConfig::default();
        let mut g = Gaussians::with_degree(0);
        g.push(
            [0.0; 3],
            [1.0, 0.0, 0.0, 0.0],
            [-1.0, 0.5, -2.0],
            0.3,
            [[0.0; 3]; 16],
        );
        g.push(
            [0.0; 3],
            [1.0, 0.0, 0.0, 0.0],
            [0.1, -0.5, -0.2],
            -1.2,
            [[0.0; 3]; 16],
        );
        let zero = || Gradients {
            opacity_logits: vec![0.0; 2],
            log_scales: vec![[0.0; 3]; 2],
            ..Default::default()
        };
        let mut gr = zero();
        add_regularizers(&cfg, &g, &mut gr);
        let eps = 1e-3f32;
        let f = |g: &Gaussians| add_regularizers(&cfg, g, &mut zero()) as f64;
        let mut gp = g.clone();
        gp.opacity_logits[1] += eps;
        let mut gm = g.clone();
        gm.opacity_logits[1] -= eps;
        let fd = (f(&gp) - f(&gm)) / (2.0 * eps as f64);
        assert!(
            (fd - gr.opacity_logits[1] as f64).abs() < 1e-3 * fd.abs(),
            "{fd} vs {}",
            gr.opacity_logits[1]
        );
        let mut gp = g.clone();
        gp.log_scales[0][1] += eps;
        let mut gm = g.clone();
        gm.log_scales[0][1] -= eps;
        let fd = (f(&gp) - f(&gm)) / (2.0 * eps as f64);
        assert!(
            (fd - gr.log_scales[0][1] as f64).abs() < 1e-3 * fd.abs(),
            "{fd} vs {}",
            gr.log_scales[0][1]
        );
    }
}
