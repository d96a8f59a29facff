//! Ground truth from a real scene folder (made by gems-synth): training views matched by name,
//! held-out views with their poses, and the training resolution inferred from the result.

mod common;

use gems_data::Split;
use gems_eval::*;
use gems_math::Pose;
use gems_math::Se3;
use gems_train::Normalization;
use gems_train::{TrainOutput, ViewResult};

fn trained_on(scene: &gems_data::Scene, factor: u32, cfg_fov: f64) -> TrainOutput {
    let views = scene
        .views
        .iter()
        .filter(|v| v.split == Split::Train)
        .map(|v| {
            // Synthetic scenes have no SfM model yet: the camera is the generator's.
            let (w, h) = (v.width / factor, v.height / factor);
            let f = 0.5 * w as f64 / (0.5 * cfg_fov.to_radians()).tan();
            let k = v.intrinsics.map_or(
                gems_math::Intrinsics {
                    fx: f,
                    fy: f,
                    cx: w as f64 / 2.0,
                    cy: h as f64 / 2.0,
                    width: w,
                    height: h,
                },
                |k| k.resized(w, h),
            );
            let c2w = Se3::from(v.pose.or(v.gt_pose).unwrap()).inverse();
            ViewResult {
                name: v.name.clone(),
                intrinsics: k,
                c2w_init: Pose::from(&c2w),
                c2w_gt: v.gt_pose.map(|p| Pose::from(&Se3::from(p).inverse())),
                c2w_gt_subframes: Vec::new(),
                knots: vec![[0.0; 6]; 9],
                virtual_c2w: vec![Pose::from(&c2w); 3],
                mid_c2w: Pose::from(&c2w),
            }
        })
        .collect();
    TrainOutput {
        config: gems_train::TrainConfig::default(),
        normalization: Normalization::identity(),
        scene_scale: 1.0,
        init_label: "gt".into(),
        gaussians: common::scene(50, -1.5, 1.0),
        views,
        history: Default::default(),
        seconds: 0.0,
        steps: 0,
        focal_factor: 1.0,
        pose_model: None,
        run: None,
    }
}

#[test]
fn ground_truth_and_held_out_views_from_a_scene() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = gems_synth::SynthConfig {
        hold: 4,
        ..gems_synth::SynthConfig::tiny()
    };
    gems_synth::generate(&cfg, dir.path()).unwrap();
    let full = gems_data::open_scene(dir.path(), &Default::default()).unwrap();
    let n_train = full.train_views().count();
    let n_novel = full.nvs_eval_views().count();
    assert!(
        n_train >= 4 && n_novel >= 1,
        "{n_train} train, {n_novel} novel"
    );

    let cache = tempfile::tempdir().unwrap();
    for factor in [1, 2] {
        let out = trained_on(&full, factor, cfg.fov_x_deg);
        let scene = open_scene_for(
            &out,
            dir.path(),
            &gems_data::OpenOptions {
                cache_dir: Some(cache.path().to_path_buf()),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(scene.downscale, factor);
        let data = eval_data_from_scene(&out, &scene).unwrap();
        assert_eq!(data.train_gt.iter().flatten().count(), n_train);
        assert_eq!(data.train_blurry.iter().flatten().count(), n_train);
        assert_eq!(data.held_out.len(), n_novel);
        let k = &out.views[0].intrinsics;
        assert_eq!(
            data.train_gt[0].as_ref().unwrap().len(),
            (k.width * k.height * 3) as usize
        );
        for h in &data.held_out {
            assert_eq!(h.intrinsics, *k, "same camera, same size");
        }
        let eval = evaluate_output(
            &out,
            &data,
            &PoseRefineConfig {
                steps: 3,
                ..Default::default()
            },
            None,
        )
        .unwrap();
        assert_eq!(
            eval.metrics.deblur.as_ref().unwrap().per_image.len(),
            n_train
        );
        assert_eq!(eval.metrics.nvs.as_ref().unwrap().per_image.len(), n_novel);
        // Midpoints at the ground-truth poses: APE vanishes.
        assert!(eval.metrics.ape.unwrap().rmse < 1e-9);
    }
    // A result whose views are not in the scene: one clear error.
    let mut stranger = trained_on(&full, 1, cfg.fov_x_deg);
    for v in &mut stranger.views {
        v.name = format!("other_{}", v.name);
    }
    assert!(
        open_scene_for(&stranger, dir.path(), &Default::default())
            .unwrap_err()
            .to_string()
            .contains("no training view")
    );
}

/// Held-out views are carried into the result's initial frame (the identity here: the result
/// started from the reference's poses), or into the trained cameras' frame: here those are the
/// reference cameras under a known similarity, and every held-out view follows it.
#[test]
fn held_out_views_are_carried_into_the_initial_or_the_trained_frame() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = gems_synth::SynthConfig {
        hold: 4,
        ..gems_synth::SynthConfig::tiny()
    };
    gems_synth::generate(&cfg, dir.path()).unwrap();
    let scene = gems_data::open_scene(dir.path(), &Default::default()).unwrap();
    let mut out = trained_on(&scene, 1, cfg.fov_x_deg);
    let sim = gems_math::Sim3 {
        scale: 1.7,
        rot: Se3::from(&Pose::from_quaternion([0.8, 0.2, -0.4, 0.1], [0.0; 3])).rot,
        trans: gems_math::Vector3::new(0.3, -0.2, 0.5),
    };
    for v in &mut out.views {
        v.mid_c2w = Pose::from(&sim.act_c2w(&Se3::from(&v.mid_c2w)));
    }
    // In the initial frame (the default) the held-out views are where the reference puts
    // them: the result started from the reference's own poses.
    let data = eval_data_from_scene(&out, &scene).unwrap();
    assert_eq!(
        data.held_out_posing.as_ref().unwrap().frame,
        HeldOutFrame::Initial
    );
    for h in &data.held_out {
        let s = scene.views.iter().find(|s| s.name == h.name).unwrap();
        let want = Se3::from(&s.gt_pose.unwrap()).inverse();
        assert!((h.c2w_init.trans - want.trans).norm() < 1e-9, "{}", h.name);
    }
    let data = eval_data_from_scene_in(&out, &scene, HeldOutFrame::Trained).unwrap();
    let posing = data.held_out_posing.as_ref().unwrap();
    assert_eq!(posing.source, "the ground-truth poses");
    assert_eq!(posing.similarity_cameras, out.views.len());
    assert!(!data.held_out.is_empty());
    for h in &data.held_out {
        let s = scene.views.iter().find(|s| s.name == h.name).unwrap();
        let want = sim.act_c2w(&Se3::from(&s.gt_pose.unwrap()).inverse());
        assert!(
            (h.c2w_init.trans - want.trans).norm() < 1e-9
                && (h.c2w_init.rot - want.rot).norm() < 1e-9,
            "{}",
            h.name
        );
    }
    // A similarity changes no camera's place relative to the others: nothing moved.
    let shift = data.camera_shift.unwrap();
    assert_eq!(shift.views, out.views.len());
    assert!(
        shift.centre_pct < 1e-6 && shift.rotation_deg < 1e-6,
        "{shift:?}"
    );
    assert!(shift.initial_centre_pct < 1e-6, "{shift:?}");
    // One camera moved on its own: that is a change of shape.
    let nudge = gems_math::Vector6::new(0.2, 0.0, 0.0, 0.0, 0.05, 0.0);
    out.views[0].mid_c2w = Pose::from(&(Se3::from(&out.views[0].mid_c2w) * Se3::exp(&nudge)));
    let moved = eval_data_from_scene(&out, &scene)
        .unwrap()
        .camera_shift
        .unwrap();
    assert!(
        moved.centre_pct > 0.1 && moved.rotation_deg > 0.5,
        "{moved:?}"
    );
}

/// The trained cameras leave as a COLMAP model and a nerfstudio transforms file in the scene's
/// input frame: read back, each photo's camera is its trained mid-exposure one (here the scene's
/// own poses, trained in a normalised frame), and the Gaussians' centres are the points.
#[test]
fn cameras_export_as_colmap_and_nerfstudio_and_read_back_in_the_input_frame() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = gems_synth::SynthConfig::tiny();
    gems_synth::generate(&cfg, dir.path()).unwrap();
    let scene = gems_data::open_scene(dir.path(), &Default::default()).unwrap();
    let mut out = trained_on(&scene, 1, cfg.fov_x_deg);
    // Train "in" a normalised frame: the result's poses and Gaussians are normalised, the
    // export must undo it.
    let c2w: Vec<_> = out
        .views
        .iter()
        .map(|v| {
            let s = Se3::from(&v.mid_c2w);
            (s.rot, s.trans)
        })
        .collect();
    out.normalization = Normalization::from_cameras(&c2w, 0.25);
    for v in &mut out.views {
        let s = Se3::from(&v.mid_c2w);
        let (r, t) = out.normalization.apply_c2w(&s.rot, &s.trans);
        v.mid_c2w = Pose::from(&Se3::new(r, t));
    }
    let input_means = out.gaussians.means.clone();
    for m in &mut out.gaussians.means {
        let p = out
            .normalization
            .apply_point(&gems_math::Vector3::from(m.map(f64::from)));
        *m = [p.x as f32, p.y as f32, p.z as f32];
    }
    let close = |a: &Pose, b: &Pose| {
        let (a, b) = (Se3::from(a), Se3::from(b));
        (a.rot - b.rot).norm() < 1e-6 && (a.trans - b.trans).norm() < 1e-5
    };
    let scene_pose = |name: &str| {
        let v = scene.views.iter().find(|v| v.name == name).unwrap();
        v.pose.or(v.gt_pose).unwrap()
    };

    let colmap_dir = dir.path().join("export_colmap");
    export::write_colmap_export(&colmap_dir, &out).unwrap();
    let model = gems_data::colmap::read_model(&colmap_dir.join("sparse/0")).unwrap();
    assert_eq!(model.images.len(), out.views.len());
    assert_eq!(
        model.cameras.len(),
        1,
        "one camera for views that share intrinsics"
    );
    for img in &model.images {
        assert!(close(&img.pose(), &scene_pose(&img.name)), "{}", img.name);
        let k = model.camera(img.camera_id).unwrap().intrinsics().unwrap();
        assert_eq!(k, out.views[0].intrinsics);
    }
    assert_eq!(model.points.len(), input_means.len());
    for (p, m) in model.points.iter().zip(&input_means) {
        for c in 0..3 {
            assert!((p.xyz[c] - f64::from(m[c])).abs() < 1e-4, "{p:?} vs {m:?}");
        }
    }
    assert!(colmap_dir.join("trajectories/mid.txt").is_file());

    let ns_dir = dir.path().join("export_nerfstudio");
    export::write_nerfstudio_export(&ns_dir, &mut gems_gpu::Engine::cpu(), &out).unwrap();
    let t = gems_data::nerfstudio::read_transforms(&ns_dir.join("transforms.json")).unwrap();
    assert_eq!(t.frames.len(), out.views.len());
    for (f, v) in t.frames.iter().zip(&out.views) {
        assert!(close(&f.pose, &scene_pose(&v.name)), "{}", v.name);
        let img = gems_data::load_image(&ns_dir.join(&f.file_path)).unwrap();
        assert_eq!(
            (img.width, img.height),
            (v.intrinsics.width, v.intrinsics.height)
        );
        assert_eq!(f.camera.resolve(img.width, img.height), v.intrinsics);
    }
}

/// The burst of a photo is its exposure: the mean of its sharp frames is the re-blurred image
/// the trainer's blur model renders from the same trajectory, and the files are written.
#[test]
fn an_exposure_burst_averages_to_the_reblurred_render() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = gems_synth::SynthConfig::tiny();
    gems_synth::generate(&cfg, dir.path()).unwrap();
    let scene = gems_data::open_scene(dir.path(), &Default::default()).unwrap();
    let mut out = trained_on(&scene, 1, cfg.fov_x_deg);
    out.config.num_virtual_views = 5;
    let times = out.config.virtual_times();
    for (i, v) in out.views.iter_mut().enumerate() {
        // A moving exposure: knots along x and a turn about y, different per view.
        v.knots = (0..out.config.num_knots())
            .map(|j| {
                let s = (j as f64 - 4.0) * 0.01 * (1.0 + i as f64);
                [s, 0.0, 0.2 * s, 0.0, 0.5 * s, 0.0]
            })
            .collect();
    }
    for i in 0..out.views.len() {
        let traj = out.trajectory(i);
        let v = &mut out.views[i];
        let c2w = Se3::from(&v.c2w_init);
        v.virtual_c2w = gems_train::virtual_c2w(&c2w, &traj, &times)
            .iter()
            .map(Pose::from)
            .collect();
        v.mid_c2w = Pose::from(&(c2w * traj.eval(0.5)));
    }
    let mut engine = gems_gpu::Engine::cpu();
    for i in 0..out.views.len() {
        let burst = export::render_exposure_burst(&mut engine, &out, i).unwrap();
        assert_eq!(burst.frames.len(), 5);
        let traj = out.trajectory(i);
        let c2w = Se3::from(&out.views[i].c2w_init);
        let mut ws = gems_train::BlurWorkspace::default();
        gems_train::render_blurred(
            &mut engine,
            &out.gaussians,
            &gems_train::Exposure {
                c2w_init: &c2w,
                trajectory: &traj,
                times: &times,
                intrinsics: &out.views[i].intrinsics,
            },
            [0.0; 3],
            &mut ws,
        )
        .unwrap();
        let mean: Vec<f32> = (0..ws.blurred.len())
            .map(|p| burst.frames.iter().map(|f| f[p]).sum::<f32>() / 5.0)
            .collect();
        let worst = mean
            .iter()
            .zip(&ws.blurred)
            .chain(burst.reblurred.iter().zip(&ws.blurred))
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-5, "view {i}: {worst}");
        // The frames differ: the exposure moves.
        let d: f32 = burst.frames[0]
            .iter()
            .zip(&burst.frames[4])
            .map(|(a, b)| (a - b).abs())
            .sum();
        assert!(d > 1.0, "view {i}: the burst does not move ({d})");
    }
    let bursts = dir.path().join("bursts");
    let n = export::write_bursts(&bursts, &mut engine, &out, &mut |_| {}).unwrap();
    assert_eq!(n, out.views.len());
    let stem = std::path::Path::new(&out.views[0].name)
        .file_stem()
        .unwrap()
        .to_string_lossy()
        .into_owned();
    for f in ["00.png", "04.png"] {
        assert!(bursts.join(&stem).join(f).is_file(), "{f}");
    }
    assert!(bursts.join(format!("{stem}_mid.png")).is_file());
    let gif = std::fs::read(bursts.join(format!("{stem}.gif"))).unwrap();
    assert!(gif.starts_with(b"GIF89a"), "an animated GIF");
}
