//! Scene preparation on a `gems synth` tiny scene: ground-truth and noisy ground-truth
//! initialisation, PRISM3D normalisation, points from the ground-truth model, a few training
//! steps, and the PLY export landing back in the input frame.

use gems_data::OpenOptions;
use gems_math::{Se3, Vector3};
use gems_train::TrainConfig;
use gems_train::TrainOutput;
use gems_train::Trainer;
use gems_train::{InitMode, prepare_input};

#[test]
fn synth_scene_prepares_normalises_and_trains() {
    let dir = tempfile::tempdir().unwrap();
    gems_synth::generate(&gems_synth::SynthConfig::tiny(), dir.path()).unwrap();
    let scene = gems_data::open_scene(dir.path(), &OpenOptions::default()).unwrap();
    let n_train = scene.train_views().count();
    let cfg = TrainConfig {
        steps: 4,
        num_virtual_views: 3,
        ..TrainConfig::default()
    };

    let gt = prepare_input(&scene, &InitMode::Gt, &cfg).unwrap();
    assert_eq!(gt.views.len(), n_train);
    // Normalised: cameras centred, max |coordinate| = 0.25 (PRISM3D scale factor).
    let c = gt
        .views
        .iter()
        .fold(Vector3::zeros(), |a, v| a + v.c2w_init.trans)
        / n_train as f64;
    assert!(c.norm() < 1e-9, "{c}");
    let max = gt
        .views
        .iter()
        .map(|v| v.c2w_init.trans.abs().max())
        .fold(0.0, f64::max);
    assert!((max - 0.25).abs() < 1e-9);
    // With GT init the initial pose is the ground truth.
    let d = gt.views[0].c2w_init.inverse() * gt.views[0].c2w_gt.unwrap();
    assert!(d.log().norm() < 1e-9);
    // The ground-truth sub-frames come along, normalised like the poses: the generated scene's
    // mid-exposure pose lies between its two middle sub-frames (an even count).
    let subs = &gt.views[0].c2w_gt_subframes;
    assert!(
        subs.len() >= 2 && subs.len().is_multiple_of(2),
        "{}",
        subs.len()
    );
    let (a, b) = (subs[subs.len() / 2 - 1], subs[subs.len() / 2]);
    let half = a * Se3::exp(&((a.inverse() * b).log() * 0.5));
    let d = half.inverse() * gt.views[0].c2w_gt.unwrap();
    let step = (a.inverse() * b).log().norm();
    assert!(
        d.log().norm() < 0.25 * step,
        "{} vs step {step}",
        d.log().norm()
    );
    assert!(gt.gaussians.len() > 10, "points from gt/sparse/0");

    let noisy = prepare_input(
        &scene,
        &InitMode::GtNoisy {
            translation_std: 0.01,
            rotation_std: 0.01,
        },
        &cfg,
    )
    .unwrap();
    assert!(noisy.init_label.contains("gt-noisy"));
    let d = noisy.views[0].c2w_init.inverse() * noisy.views[0].c2w_gt.unwrap();
    assert!(d.log().norm() > 1e-4 && d.log().norm() < 0.2);
    // Seeded: the same call gives the same noise.
    let again = prepare_input(
        &scene,
        &InitMode::GtNoisy {
            translation_std: 0.01,
            rotation_std: 0.01,
        },
        &cfg,
    )
    .unwrap();
    assert_eq!(again.views[0].c2w_init, noisy.views[0].c2w_init);

    assert!(
        prepare_input(
            &scene,
            &InitMode::Colmap(Some(dir.path().join("missing"))),
            &cfg
        )
        .is_err()
    );

    let mut t = Trainer::new(cfg, noisy).unwrap();
    t.run(|_, _| Ok(())).unwrap();
    let out = TrainOutput::from_trainer(&t);
    let g_in = out.normalization.gaussians_to_input_frame(&out.gaussians);
    // Exported means are back in the input frame: normalising them again gives the trained ones.
    let m = g_in.means[0].map(f64::from);
    let back = out
        .normalization
        .apply_point(&Vector3::new(m[0], m[1], m[2]));
    let orig = out.gaussians.means[0];
    assert!((back.x - orig[0] as f64).abs() < 1e-4 && (back.z - orig[2] as f64).abs() < 1e-4);
}

#[test]
fn initial_clouds_never_exceed_the_mcmc_cap() {
    let dir = tempfile::tempdir().unwrap();
    gems_synth::generate(&gems_synth::SynthConfig::tiny(), dir.path()).unwrap();
    let scene = gems_data::open_scene(dir.path(), &OpenOptions::default()).unwrap();
    // The ground-truth model without its points: initialisation falls back to random points.
    let mut model = gems_data::colmap::read_model(&dir.path().join("gt/sparse/0")).unwrap();
    model.points.clear();
    model.images.iter_mut().for_each(|i| i.points2d.clear());
    let bare = dir.path().join("bare");
    gems_data::colmap::write_model(&bare, &model, gems_data::colmap::ModelFormat::Binary).unwrap();
    let mut cfg = TrainConfig::default();
    cfg.mcmc.cap_max = 700;
    let input = prepare_input(&scene, &InitMode::Colmap(Some(bare.clone())), &cfg).unwrap();
    assert_eq!(input.gaussians.len(), 700, "random init clamped to cap_max");
    cfg.mcmc.cap_max = 500_000;
    cfg.init.random_points = 900;
    let input = prepare_input(&scene, &InitMode::Colmap(Some(bare)), &cfg).unwrap();
    assert_eq!(
        input.gaussians.len(),
        900,
        "below the cap the configured count"
    );
}
