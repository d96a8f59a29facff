//! Training-loop properties: same seed → same result, checkpoint + resume continues
//! bit-identically, the trained output round-trips through its files.

mod common;

use gems_train::Normalization;
use gems_train::TrainConfig;
use gems_train::{TrainInput, TrainState, Trainer};
use gems_train::{TrainOutput, has_checkpoint, load_checkpoint, save_checkpoint};

fn small_config() -> TrainConfig {
    let mut c = TrainConfig {
        steps: 24,
        num_virtual_views: 4,
        seed: 7,
        ..TrainConfig::default()
    };
    c.pose.accumulate_steps = 5;
    c.mcmc.cap_max = 700;
    c.mcmc.refine_every = 6; // refine at steps 6, 12, 18
    c.mcmc.refine_start_fraction = 0.1;
    c
}

fn trainer(cfg: &TrainConfig) -> Trainer {
    let scene = common::blur_scene(3, 32, 24, 0.2, 0.02, 1);
    let input = TrainInput {
        views: scene.views.clone(),
        gaussians: common::init_gaussians(&scene, 0.02, 3),
        normalization: Normalization::identity(),
        scene_scale: 1.0,
        init_label: "gt-noisy".into(),
    };
    Trainer::new(cfg.clone(), input).unwrap()
}

fn same(a: &TrainState, b: &TrainState) {
    assert_eq!(a.step, b.step);
    assert_eq!(a.gaussians, b.gaussians);
    assert_eq!(a.adam, b.adam);
    assert_eq!(a.knots, b.knots);
    assert_eq!(a.knot_adam, b.knot_adam);
    assert_eq!(a.knot_grad_acc, b.knot_grad_acc);
    assert_eq!(a.rng_word_pos, b.rng_word_pos);
    assert_eq!(a.history, b.history);
    assert_eq!(a.blur_depths, b.blur_depths);
    assert_eq!(a.focal, b.focal);
}

#[test]
fn virtual_views_follow_each_photos_blur_length() {
    let counts = |cfg: &TrainConfig| -> Vec<u32> {
        let mut t = trainer(cfg);
        t.run(|_, _| Ok(())).unwrap();
        let s = t.state().unwrap();
        assert!(s.blur_depths.iter().all(Option::is_some));
        s.history.virtual_views.clone()
    };
    // Counts adapt from step round(0.3 · 24) = 7.
    let start = 7;
    // Poses held at (nearly) a point: one render per step once counts adapt.
    let mut still = small_config();
    still.pose.optimize = false;
    still.pose.knot_init_std = 1e-7;
    let n = counts(&still);
    assert_eq!(n.len(), 24);
    assert!(n[..start].iter().all(|&c| c == 4), "{n:?}");
    assert!(n[start..].iter().all(|&c| c == 1), "{n:?}");
    // Wide random paths: the configured count throughout.
    let mut wide = still.clone();
    wide.pose.knot_init_std = 0.05;
    assert!(counts(&wide).iter().all(|&c| c == 4));
    // Spacing 0 (the paper): the configured count for the nearly still poses too.
    still.virtual_view_spacing_px = 0.0;
    assert!(counts(&still).iter().all(|&c| c == 4));
    // Counts from the start when the fraction is 0.
    still.virtual_view_spacing_px = 1.0;
    still.adaptive_views_from = 0.0;
    assert!(counts(&still).iter().all(|&c| c == 1));
}

#[test]
fn same_seed_same_result_and_resume_is_bit_identical() {
    let a = check_same_seed_and_resume(&small_config());
    // With the uneven-speed energy on: the same guarantees, and it changes the trajectories.
    let mut speed = small_config();
    speed.pose.uneven_speed_weight = 1.0;
    let b = check_same_seed_and_resume(&speed);
    assert_ne!(a.knots, b.knots);
    // With the off-centre energy off (on by default): the same guarantees, and other
    // trajectories.
    let mut free = small_config();
    free.pose.off_centre_weight = 0.0;
    let c = check_same_seed_and_resume(&free);
    assert_ne!(a.knots, c.knots);
    // Centred on the median instead of the mean of the poses: the same guarantees (the median's
    // choice of poses is deterministic), and other trajectories.
    let mut median = small_config();
    median.pose.off_centre_target = gems_math::PathCentre::Median;
    let d = check_same_seed_and_resume(&median);
    assert_ne!(a.knots, d.knots);
    // Straightened for the whole run: the same guarantees, other trajectories, and every
    // view's knots end on their least-squares line.
    let mut straight = small_config();
    straight.pose.straight_fraction = 1.0;
    let e = check_same_seed_and_resume(&straight);
    assert_ne!(a.knots, e.knots);
    for v in 0..e.knots.len() / (straight.num_knots() * 6) {
        let knots = gems_train::trajectory_of(&straight, &e.knots, v)
            .knots()
            .to_vec();
        let mut line = knots.clone();
        gems_math::straighten_knots(&mut line);
        for (k, l) in knots.iter().zip(&line) {
            for i in 0..6 {
                assert!(
                    (k[i] - l[i]).abs() < 1e-6,
                    "knot off its line: {k:?} vs {l:?}"
                );
            }
        }
    }
    // Midpoints held on the initial cameras: the same guarantees, other trajectories, and
    // every view's pose at u = ½ ends on its initial camera while its path still moved.
    let mut held = small_config();
    held.pose.hold_midpoint = true;
    let h = check_same_seed_and_resume(&held);
    assert_ne!(a.knots, h.knots);
    let start = trainer(&held).state().unwrap().knots.clone();
    let ends = |knots: &[f32], v: usize| {
        let traj = gems_train::trajectory_of(&held, knots, v);
        (traj.eval(0.0).inverse() * traj.eval(1.0)).log()
    };
    let views = h.knots.len() / (held.num_knots() * 6);
    for v in 0..views {
        let mid = gems_train::trajectory_of(&held, &h.knots, v)
            .eval(0.5)
            .log()
            .norm();
        assert!(mid < 1e-6, "view {v}: midpoint {mid} off its camera");
    }
    // Four knot steps on a tiny scene: a view whose gradient is a shared shift of its knots
    // only is held back in place, but the paths as a whole were learned.
    let changed = (0..views)
        .map(|v| (ends(&h.knots, v) - ends(&start, v)).norm())
        .fold(0.0, f64::max);
    assert!(changed > 1e-6, "no path changed its shape ({changed})");
    // Coarse-to-fine, interrupted inside the coarse part (steps 0–11 at half size): the same
    // guarantees, and another result.
    let mut coarse = small_config();
    coarse.coarse_to_fine = gems_train::CoarseToFineConfig {
        levels: 1,
        fraction: 0.5,
    };
    let f = check_same_seed_and_resume(&coarse);
    assert_ne!(a.knots, f.knots);
    assert_ne!(a.gaussians, f.gaussians);
    // Two octaves down the 32×24 views would be 8×6, below the SSIM window: the coarse part
    // runs at the one level that fits, the same run as `levels = 1`.
    coarse.coarse_to_fine.levels = 2;
    let mut clamped = trainer(&coarse);
    clamped.run(|_, _| Ok(())).unwrap();
    same(clamped.state().unwrap(), &f);
    // Backward through one view in each half of the exposure: the same guarantees (the draws
    // follow the seed and the step), and another result; through as many views as are
    // rendered, the exact backward's result bit for bit.
    let mut subset = small_config();
    subset.backward_virtual_views = 2;
    let g = check_same_seed_and_resume(&subset);
    assert_ne!(a.gaussians, g.gaussians);
    assert_ne!(a.knots, g.knots);
    subset.backward_virtual_views = 4;
    let mut every = trainer(&subset);
    every.run(|_, _| Ok(())).unwrap();
    same(every.state().unwrap(), &a);
    // With the focal learned: the same guarantees (its Adam state is in the checkpoint), and
    // another result.
    let mut focal = small_config();
    focal.pose.focal_lr = 1e-2;
    let h = check_same_seed_and_resume(&focal);
    assert_ne!(h.focal.log_scale, 0.0);
    assert_ne!(a.knots, h.knots);
    assert_eq!(a.focal, gems_train::FocalState::default());
    // From wide random paths, the energy's weight brings u = ½ nearer the mean pose.
    let mut wide = small_config();
    wide.pose.knot_init_std = 0.05;
    wide.pose.accumulate_steps = 1;
    wide.pose.lr = 1e-2;
    let off_centre = |weight: f64| -> f64 {
        let cfg = TrainConfig {
            pose: gems_train::PoseConfig {
                off_centre_weight: weight,
                ..wide.pose.clone()
            },
            ..wide.clone()
        };
        let mut t = trainer(&cfg);
        t.run(|_, _| Ok(())).unwrap();
        let times = cfg.virtual_times();
        (0..t.views().len())
            .map(|v| {
                let traj = t.trajectory(v);
                let mut g = vec![[0.0; 6]; traj.num_knots()];
                gems_math::off_centre_energy(&traj, &times, cfg.pose.off_centre_target, 1.0, &mut g)
            })
            .sum()
    };
    let (free, pinned) = (off_centre(0.0), off_centre(10.0));
    assert!(
        pinned < 0.5 * free,
        "off-centre energy {pinned} vs {free} without the term"
    );
}

/// Runs `cfg` twice and once interrupted at step 10 and resumed from disk: all three end
/// bit-identical; another seed ends elsewhere. Returns the final state.
fn check_same_seed_and_resume(cfg: &TrainConfig) -> TrainState {
    let cfg = cfg.clone();
    let mut a = trainer(&cfg);
    a.run(|_, _| Ok(())).unwrap();
    assert!(
        a.state().unwrap().gaussians.len() > 500,
        "MCMC grew the population"
    );
    let mut b = trainer(&cfg);
    b.run(|_, _| Ok(())).unwrap();
    same(a.state().unwrap(), b.state().unwrap());

    // Interrupted at step 10 (mid pose accumulation, between refinements), resumed from disk.
    let dir = tempfile::tempdir().unwrap();
    let mut c = trainer(&cfg);
    for _ in 0..10 {
        let r = c.step().unwrap();
        // The photometric part alone: the MCMC regularisers (both weights > 0) come on top.
        assert!(
            r.photometric_loss > 0.0 && r.photometric_loss < r.loss,
            "photometric {} of {}",
            r.photometric_loss,
            r.loss
        );
    }
    save_checkpoint(dir.path(), &c).unwrap();
    assert!(has_checkpoint(dir.path()));
    drop(c);
    let (cfg2, state) = load_checkpoint(dir.path()).unwrap();
    assert_eq!(cfg2, cfg);
    let fresh = trainer(&cfg);
    let mut d = Trainer::from_state(
        cfg2,
        fresh.views().to_vec(),
        Normalization::identity(),
        1.0,
        "gt-noisy".into(),
        state,
    )
    .unwrap();
    d.run(|_, _| Ok(())).unwrap();
    same(a.state().unwrap(), d.state().unwrap());

    // A different seed gives a different run.
    let mut e = trainer(&TrainConfig { seed: 8, ..cfg });
    e.run(|_, _| Ok(())).unwrap();
    assert_ne!(a.state().unwrap().knots, e.state().unwrap().knots);
    a.state().unwrap().clone()
}

#[test]
fn output_round_trips_and_bad_files_are_named() {
    let mut cfg = small_config();
    cfg.steps = 3;
    let mut t = trainer(&cfg);
    t.run(|_, _| Ok(())).unwrap();
    let out = TrainOutput::from_trainer(&t);
    assert_eq!(out.views.len(), 3);
    assert_eq!(out.views[0].virtual_c2w.len(), 4);
    assert_eq!(out.steps, 3);
    let dir = tempfile::tempdir().unwrap();
    out.save(dir.path()).unwrap();
    let back = TrainOutput::load(dir.path()).unwrap();
    assert!(back == out, "TrainOutput differs after save/load");
    // The mid pose is the trajectory at u = 0.5 on the initial pose.
    let mid = gems_math::Se3::from(&out.views[1].c2w_init) * out.trajectory(1).eval(0.5);
    let saved = gems_math::Se3::from(&out.views[1].mid_c2w);
    assert!((mid.trans - saved.trans).norm() < 1e-12);

    std::fs::write(
        dir.path().join("model.safetensors"),
        b"not a safetensors file",
    )
    .unwrap();
    let e = TrainOutput::load(dir.path()).unwrap_err().to_string();
    assert!(e.contains("model.safetensors"), "{e}");
    let e = load_checkpoint(dir.path()).unwrap_err().to_string();
    assert!(e.contains("checkpoint.json"), "{e}");
}

/// A `model.json` whose knot count does not fit its trajectory kind is refused by `load`, with
/// the file and the view named, so `trajectory()` cannot panic on it later.
#[test]
fn output_with_wrong_knot_count_is_refused() {
    let mut cfg = small_config();
    cfg.steps = 1;
    let mut t = trainer(&cfg);
    t.run(|_, _| Ok(())).unwrap();
    let out = TrainOutput::from_trainer(&t);
    let dir = tempfile::tempdir().unwrap();
    out.save(dir.path()).unwrap();
    let jpath = dir.path().join("model.json");
    let meta: serde_json::Value = serde_json::from_slice(&std::fs::read(&jpath).unwrap()).unwrap();

    // Fewer knots than the Bézier config asks for.
    let mut short = meta.clone();
    short["views"][1]["knots"]
        .as_array_mut()
        .unwrap()
        .truncate(3);
    std::fs::write(&jpath, serde_json::to_vec(&short).unwrap()).unwrap();
    let e = TrainOutput::load(dir.path()).unwrap_err().to_string();
    assert!(
        e.contains("model.json") && e.contains("3 trajectory knots"),
        "{e}"
    );

    // The trainer's knots under a kind that needs another count (a spline has 4).
    let mut spline = meta;
    spline["config"]["trajectory"] = "spline".into();
    std::fs::write(&jpath, serde_json::to_vec(&spline).unwrap()).unwrap();
    let e = TrainOutput::load(dir.path()).unwrap_err().to_string();
    assert!(e.contains("needs 4"), "{e}");
}

/// Sharp photos rendered at the true focal and given to the trainer 6 % short, with the true
/// Gaussians and poses held fixed: only the focal factor can explain the difference, and
/// `pose.focal_lr` learns it; at 0 it stays 1.
#[test]
fn a_learned_focal_recovers_one_given_six_percent_short() {
    let factor = |focal_lr: f32| -> f64 {
        let input = common::short_focal_input();
        let given = input.views[0].intrinsics;
        let mut t = Trainer::new(common::focal_only_config(focal_lr), input).unwrap();
        t.run(|_, _| Ok(())).unwrap();
        let f = t.state().unwrap().focal.factor();
        assert_eq!(t.intrinsics(0), given.with_focal_scaled(f));
        f
    };
    assert_eq!(factor(0.0), 1.0);
    let learned = factor(1e-2);
    let truth = 1.0 / common::SHORT_FOCAL;
    assert!(
        (learned - truth).abs() < 0.2 * (truth - 1.0),
        "learned factor {learned}, truth {truth}"
    );
}
