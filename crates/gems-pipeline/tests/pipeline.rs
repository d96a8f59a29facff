//! The whole pipeline through the library API on a tiny generated scene: what a library user
//! (a benchmark, another program) calls instead of the `gems` command line.

use gems_gpu::Engine;
use gems_pipeline::{Init, InitRequest, PipelineError, TrainRequest, train_scene};
use gems_train::TrainConfig;

fn request(scene: &std::path::Path, output: &std::path::Path, init: InitRequest) -> TrainRequest {
    TrainRequest {
        scene: scene.to_path_buf(),
        output: output.to_path_buf(),
        init,
        cfg: TrainConfig {
            steps: 20,
            seed: 5,
            ..TrainConfig::default()
        },
        open: gems_data::OpenOptions::default(),
        resume: false,
        evaluate: true,
        lpips: Vec::new(),
        engine: Engine::cpu(),
        progress: false,
        protocol: None,
    }
}

/// A request whose first half is a first pass, with the SfM run again on its renders: every
/// view trains (so every image the SfM saw is a render the second time), no evaluation.
fn first_pass_request(
    scene: &std::path::Path,
    output: &std::path::Path,
    init: InitRequest,
) -> TrainRequest {
    let mut req = request(scene, output, init);
    req.cfg.init.sfm_rerun_fraction = 0.5;
    req.cfg.init.sfm_rerun_min_steps = 1;
    req.evaluate = false;
    req.open.hold = Some(0);
    req
}

/// A temporary folder holding the generator's tiny scene in `scene/`.
fn tiny_scene() -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene");
    gems_synth::generate(&gems_synth::SynthConfig::tiny(), &scene).unwrap();
    (dir, scene)
}

#[test]
fn tiny_scene_end_to_end_from_rust() {
    let (dir, scene) = tiny_scene();
    let out = dir.path().join("run");
    let run = train_scene(request(&scene, &out, InitRequest::new(Init::Gt))).unwrap();

    assert_eq!(run.point_cloud, out.join("point_cloud.ply"));
    let g = gems_splat::ply::read_ply(&run.point_cloud).unwrap();
    assert!(!g.is_empty(), "the trained Gaussians are exported");
    assert!(out.join("model.json").is_file() && out.join("config.toml").is_file());
    let report = run.report.expect("an evaluated run writes a report");
    assert_eq!(report, out.join("report.html"));
    assert!(report.is_file());
    let metrics = run.metrics.expect("an evaluated run returns its metrics");
    assert_eq!(
        metrics,
        gems_eval::read_metrics_json(&out.join("metrics.json")).unwrap(),
        "the returned metrics are the ones written"
    );
    let deblur = metrics
        .deblur
        .expect("a generated scene has sharp ground truth");
    assert!(
        deblur.psnr.is_finite() && deblur.psnr > 5.0,
        "{}",
        deblur.psnr
    );
    assert!(metrics.ape.is_some(), "ground-truth poses give an APE");
    // Exact poses train straight paths first.
    let cfg = TrainConfig::from_toml_file(&out.join("config.toml")).unwrap();
    assert_eq!(
        cfg.pose.straight_fraction,
        TrainConfig::default().init.accurate_poses_straight_fraction
    );
    // Trained from the ground-truth poses: the initial poses are the truth.
    assert!(
        metrics.ape_init.unwrap().rmse < 1e-9,
        "{:?}",
        metrics.ape_init
    );
    // The result says what ran, and how the held-out views were posed.
    let what = metrics.run.as_ref().expect("a run description");
    assert_eq!(what.init, "ground-truth poses");
    assert_eq!(
        (what.steps, what.downscale, what.protocol.as_deref()),
        (20, 1, None)
    );
    assert_eq!(what.train_views, deblur.per_image.len());
    assert!(
        what.wall_seconds > 0.0 && what.device.starts_with("CPU"),
        "{what:?}"
    );
    let posing = metrics.held_out_pose.as_ref().expect("held-out posing");
    assert_eq!(posing.source, "the ground-truth poses");
    assert_eq!(posing.similarity_cameras, what.train_views);
    assert!(metrics.eval_seconds.is_some_and(|s| s > 0.0));
    assert!(
        std::fs::read_to_string(&report)
            .unwrap()
            .contains("What ran")
    );
}

#[test]
fn events_with_an_initialiser_that_reads_no_images_is_an_error() {
    let (dir, scene) = tiny_scene();
    let init = InitRequest {
        events: Some(gems_pipeline::EventInit {
            threshold: 0.2,
            linearisation: gems_init::edi::Linearisation::SrgbEncodedAverage,
            time_unit: None,
        }),
        ..InitRequest::new(Init::Gt)
    };
    let err = train_scene(request(&scene, &dir.path().join("run"), init)).unwrap_err();
    assert!(matches!(err, PipelineError::EventsNeedImageInit), "{err}");
    assert!(!dir.path().join("run").join("point_cloud.ply").exists());
}

#[test]
fn a_missing_scene_is_one_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-such-scene");
    let err = train_scene(request(
        &missing,
        &dir.path().join("run"),
        InitRequest::new(Init::Sfm),
    ))
    .unwrap_err();
    assert!(matches!(err, PipelineError::OpenScene { .. }), "{err}");
    assert!(err.to_string().contains("no-such-scene"), "{err}");
}

#[test]
fn sfm_rerun_trains_a_first_pass_and_initialises_again_on_its_renders() {
    let (dir, scene) = tiny_scene();
    let run_with = |out: &std::path::Path, resume: bool| {
        let mut req = first_pass_request(&scene, out, InitRequest::new(Init::Sfm));
        req.resume = resume;
        // Kept however close its cameras lie to the first model's (see
        // `sfm_rerun_keeps_the_renders_model_only_when_its_cameras_are_its_own`).
        req.cfg.init.sfm_rerun_confirm_pct = 0.0;
        train_scene(req).unwrap()
    };
    let run = |out: &std::path::Path| run_with(out, false);
    let out = dir.path().join("run");
    let first = run(&out);

    let steps = |dir: &std::path::Path| {
        let cfg = TrainConfig::from_toml_file(&dir.join("config.toml")).unwrap();
        (
            cfg.steps,
            cfg.init.sfm_rerun_fraction,
            cfg.pose.straight_fraction,
            cfg.pose.anchor_weight,
        )
    };
    assert_eq!(
        steps(&out.join("first_pass")),
        (10, 0.0, 0.0, 0.0),
        "first pass: half, with the run's own pose.straight_fraction"
    );
    assert_eq!(
        steps(&out),
        (10, 0.0, 0.15, 0.0),
        "the run proper: the other half, with init.accurate_poses_straight_fraction and, from \
         the renders' model, no anchor"
    );
    // The second initialisation read renders named like the scene's images, at their size.
    let mut scene_names: Vec<String> = gems_fs::list_images(&scene.join("images"))
        .unwrap()
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    scene_names.sort();
    let renders = gems_fs::list_images(&out.join("sfm_rerun").join("images")).unwrap();
    let mut render_names: Vec<String> = renders
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    render_names.sort();
    assert_eq!(render_names, scene_names);
    let photo = gems_data::load_image(&scene.join("images").join(&scene_names[0])).unwrap();
    let render = gems_data::load_image(&renders[0]).unwrap();
    assert_eq!((render.width, render.height), (photo.width, photo.height));
    assert_ne!(
        render.data, photo.data,
        "a render, not a copy of the blurry photo"
    );
    // The run proper trained from the second model, which names the scene's images.
    let second = out.join("sfm_rerun").join("sparse").join("0");
    let model = gems_data::colmap::read_model(&second).unwrap();
    assert!(model.images.iter().all(|i| scene_names.contains(&i.name)));
    let trained = gems_train::TrainOutput::load(&out).unwrap();
    assert!(
        trained.init_label.contains("sfm_rerun"),
        "{}",
        trained.init_label
    );
    let choice = gems_pipeline::probe::RerunChoice::read(&out.join("sfm_rerun"))
        .unwrap()
        .expect("the choice is written");
    assert!(choice.kept, "{}", choice.reason);
    assert!(
        choice.shift_centre_pct.is_some_and(f64::is_finite)
            && choice.shift_rotation_deg.is_some_and(f64::is_finite)
            && choice.change_centre_pct.is_some_and(f64::is_finite)
            && choice.change_rotation_deg.is_some_and(f64::is_finite),
        "the shift and the change are recorded: {choice:?}"
    );

    // Same seed, same result.
    let cloud = std::fs::read(&first.point_cloud).unwrap();
    let again = run(&dir.path().join("again"));
    assert_eq!(cloud, std::fs::read(&again.point_cloud).unwrap());

    // Resumed after the second model was written, or after the first pass only: the same run.
    forget_run_proper(&out);
    let resumed = run_with(&out, true);
    assert_eq!(cloud, std::fs::read(&resumed.point_cloud).unwrap());
    forget_run_proper(&out);
    std::fs::remove_dir_all(out.join("sfm_rerun")).unwrap();
    let resumed = run_with(&out, true);
    assert_eq!(cloud, std::fs::read(&resumed.point_cloud).unwrap());
}

#[test]
fn sfm_rerun_keeps_the_renders_model_only_when_its_cameras_are_its_own() {
    let (dir, scene) = tiny_scene();
    let out = dir.path().join("run");
    let mut req = first_pass_request(&scene, &out, InitRequest::new(Init::Sfm));
    // No SfM on renders lands this far from the first model's cameras, and any shape of
    // change passes.
    req.cfg.init.sfm_rerun_confirm_pct = 1e9;
    req.cfg.init.sfm_rerun_confirm_max_systematic = 1.0;
    train_scene(req).unwrap();

    let choice = gems_pipeline::probe::RerunChoice::read(&out.join("sfm_rerun"))
        .unwrap()
        .expect("the choice is written");
    assert!(!choice.kept && choice.first_model_confirmed);
    assert!(
        choice.reason.contains("init.sfm_rerun_confirm_pct")
            && choice
                .reason
                .contains("init.sfm_rerun_confirm_max_systematic")
            && choice.reason.contains("confirms the first model"),
        "{}",
        choice.reason
    );
    let share = choice
        .change_systematic_share
        .expect("the shape is recorded");
    assert!((0.0..=1.0).contains(&share), "{share}");
    // The run proper trained from the first model with all the steps and, its cameras
    // confirmed by the renders, straight paths first (the first pass had its own paths). The
    // tiny scene's 12 px of blur on 96 px left the SfM's estimated focal barely determined, so
    // the confirmed cameras are not held (`init.confirmed_hold_blurred_focal`).
    let report: serde_json::Value = serde_json::from_slice(
        &std::fs::read(out.join("sfm").join(gems_init::sfm::REPORT_FILE)).unwrap(),
    )
    .unwrap();
    assert_eq!(report["focal_barely_determined"], true, "{report}");
    let cfg = TrainConfig::from_toml_file(&out.join("config.toml")).unwrap();
    let first_cfg =
        TrainConfig::from_toml_file(&out.join("first_pass").join("config.toml")).unwrap();
    assert!(cfg.init.accurate_poses_straight_fraction > 0.0);
    assert!(cfg.init.confirmed_hold_midpoint && !cfg.init.confirmed_hold_blurred_focal);
    assert_eq!(
        (
            cfg.steps,
            cfg.pose.straight_fraction,
            first_cfg.pose.straight_fraction
        ),
        (20, cfg.init.accurate_poses_straight_fraction, 0.0)
    );
    assert_eq!(
        (cfg.pose.hold_midpoint, first_cfg.pose.hold_midpoint),
        (false, false)
    );
    let trained = gems_train::TrainOutput::load(&out).unwrap();
    assert_trained_from_the_dense_model(&trained);
    let run_init = trained.run.unwrap().init;
    assert!(
        run_init.contains("tried and not kept")
            && run_init.contains("init.confirmed_hold_blurred_focal = false"),
        "{run_init}"
    );

    // The recorded change is the renders' model against the first model's cameras (the first
    // pass's initial ones), the shift against the first pass's trained cameras.
    let first = gems_train::TrainOutput::load(&out.join("first_pass")).unwrap();
    let renders =
        gems_data::colmap::read_model(&out.join("sfm_rerun").join("sparse").join("0")).unwrap();
    let change = gems_pipeline::probe::renders_change(&first, &renders).unwrap();
    let shift = gems_pipeline::probe::renders_shift(&first, &renders).unwrap();
    assert_eq!(choice.change_centre_pct, Some(change.centre_pct));
    assert_eq!(choice.change_rotation_deg, Some(change.rotation_deg));
    assert_eq!(choice.shift_centre_pct, Some(shift.centre_pct));
    assert_eq!(choice.shift_rotation_deg, Some(shift.rotation_deg));
    assert_ne!(
        change, shift,
        "the first pass moved its cameras, so the two differ"
    );
    // A model holding exactly the cameras measured against, in a frame of its own (turned,
    // scaled, moved), lies at nothing from them; one with a camera moved along the path's
    // extent lies at the expected distance.
    let frame = gems_math::Sim3 {
        scale: 3.0,
        rot: *gems_math::So3::exp(&gems_math::Vector3::new(0.2, -0.7, 0.4)).matrix(),
        trans: gems_math::Vector3::new(4.0, -1.0, 2.0),
    };
    type Camera = fn(&gems_train::ViewResult) -> &gems_math::Pose;
    let holding = |camera: Camera| {
        let mut model = renders.clone();
        model.images = first
            .views
            .iter()
            .enumerate()
            .map(|(i, v)| {
                let c2w = frame.act_c2w(&gems_math::Se3::from(camera(v)));
                gems_data::colmap::Image::from_pose(
                    i as u32 + 1,
                    renders.images[0].camera_id,
                    &v.name,
                    &gems_math::Pose::from(&c2w.inverse()),
                )
            })
            .collect();
        model
    };
    let c2w = |img: &gems_data::colmap::Image| gems_math::Se3::from(&img.pose()).inverse();
    let moved = |model: &gems_data::colmap::SparseModel| {
        let extent = model
            .images
            .iter()
            .flat_map(|a| {
                model
                    .images
                    .iter()
                    .map(move |b| (c2w(a).trans - c2w(b).trans).norm())
            })
            .fold(0.0, f64::max);
        let mut moved = model.clone();
        let c = c2w(&moved.images[1]);
        let shifted = gems_math::Se3::new(
            c.rot,
            c.trans + gems_math::Vector3::new(0.05 * extent, 0.0, 0.0),
        );
        moved.images[1] = gems_data::colmap::Image::from_pose(
            moved.images[1].id,
            moved.images[1].camera_id,
            &moved.images[1].name.clone(),
            &gems_math::Pose::from(&shifted.inverse()),
        );
        moved
    };
    let n = first.views.len() as f64;
    type Measure = fn(
        &gems_train::TrainOutput,
        &gems_data::colmap::SparseModel,
    ) -> Option<gems_math::CameraDiscrepancy>;
    let measures: [(Measure, Camera); 2] = [
        (gems_pipeline::probe::renders_change, |v| &v.c2w_init),
        (gems_pipeline::probe::renders_shift, |v| &v.mid_c2w),
    ];
    for (measure, camera) in measures {
        let same = holding(camera);
        let none = measure(&first, &same).unwrap();
        assert!(
            none.centre_pct < 1e-6 && none.rotation_deg < 1e-6,
            "{none:?}"
        );
        let some = measure(&first, &moved(&same)).unwrap();
        assert!(
            some.centre_pct > 5.0 / n.sqrt() * 0.8 && some.centre_pct < 5.0,
            "one of {n} cameras moved by 5 % of the extent: {some:?}"
        );
    }
}

/// A confirmed first model's run proper trained from that model with the first pass's dense
/// points (`init.confirmed_dense_points`, `sfm_rerun/dense/sparse/0`), not from the renders'
/// model (`sfm_rerun/sparse/0`).
fn assert_trained_from_the_dense_model(trained: &gems_train::TrainOutput) {
    let renders_model = std::path::Path::new("sfm_rerun").join("sparse");
    let label = &trained.init_label;
    assert!(
        !label.contains(&renders_model.display().to_string()),
        "{label}"
    );
    assert!(label.contains("dense"), "{label}");
}

#[test]
fn an_imported_model_is_checked_on_the_renders_and_held_only_when_confirmed() {
    let (dir, scene) = tiny_scene();
    // The imported model: the built-in SfM's, written where a user's COLMAP model would be.
    let imported =
        gems_pipeline::run_sfm(&scene, &dir.path().join("imported"), 5, None, None, None)
            .expect("the SfM registers the tiny scene");
    let run = |name: &str, confirm_pct: f64| {
        let out = dir.path().join(name);
        let init = InitRequest {
            colmap_model: Some(imported.clone()),
            ..InitRequest::new(Init::Colmap)
        };
        let mut req = first_pass_request(&scene, &out, init);
        // An imported model's own bound decides, not the one for the built-in SfM's first model
        // (set to the opposite answer).
        req.cfg.init.sfm_rerun_confirm_imported_pct = confirm_pct;
        req.cfg.init.sfm_rerun_confirm_pct = 1e9 - confirm_pct;
        // Whatever the shape of the change: the bound alone decides here.
        req.cfg.init.sfm_rerun_confirm_max_systematic = 1.0;
        train_scene(req).unwrap();
        let choice = gems_pipeline::probe::RerunChoice::read(&out.join("sfm_rerun"))
            .unwrap()
            .expect("the check's choice is written");
        let cfg = TrainConfig::from_toml_file(&out.join("config.toml")).unwrap();
        let trained = gems_train::TrainOutput::load(&out).unwrap();
        (choice, cfg, trained)
    };

    // No SfM on renders lands this far from the model's cameras: confirmed, and held.
    let (choice, cfg, trained) = run("confirmed", 1e9);
    assert!(!choice.kept && choice.first_model_confirmed, "{choice:?}");
    assert!(choice.change_centre_pct.is_some_and(f64::is_finite));
    assert_eq!(
        (
            cfg.steps,
            cfg.pose.straight_fraction,
            cfg.pose.hold_midpoint
        ),
        (20, cfg.init.accurate_poses_straight_fraction, true),
        "all the steps from the imported model, straight paths first, its cameras held"
    );
    assert_trained_from_the_dense_model(&trained);
    let run_init = trained.run.unwrap().init;
    assert!(
        run_init.contains("checked by the built-in SfM")
            && run_init.contains("confirms")
            && run_init.contains("init.sfm_rerun_confirm_imported_pct"),
        "{run_init}"
    );
    // The renders' SfM started from the imported model's focal, not a search of its own.
    let focal =
        |dir: &std::path::Path| gems_data::colmap::read_model(dir).unwrap().cameras[0].params[0];
    let renders_focal = focal(&dir.path().join("confirmed/sfm_rerun/sparse/0"));
    assert!(
        (renders_focal / focal(&imported) - 1.0).abs() < 0.1,
        "{renders_focal} against {}",
        focal(&imported)
    );

    // Nothing confirms it: trained from as it is, never replaced, nothing held.
    let (choice, cfg, trained) = run("unconfirmed", 0.0);
    assert!(!choice.kept && !choice.first_model_confirmed, "{choice:?}");
    assert!(
        choice
            .reason
            .contains("does not confirm the imported model"),
        "{}",
        choice.reason
    );
    assert_eq!(
        (
            cfg.steps,
            cfg.pose.straight_fraction,
            cfg.pose.anchor_weight,
            cfg.pose.hold_midpoint
        ),
        (20, 0.0, 0.0, false)
    );
    assert!(!trained.init_label.contains("sfm_rerun"));

    // Cameras that training does not move are not checked: one pass.
    let out = dir.path().join("fixed");
    let mut req = first_pass_request(
        &scene,
        &out,
        InitRequest {
            colmap_model: Some(imported.clone()),
            ..InitRequest::new(Init::Colmap)
        },
    );
    req.cfg.pose.optimize = false;
    train_scene(req).unwrap();
    assert!(!out.join("first_pass").exists() && !out.join("sfm_rerun").exists());
}

#[test]
fn a_confirmed_model_starts_from_dense_points_when_asked() {
    let (dir, scene) = tiny_scene();
    let imported =
        gems_pipeline::run_sfm(&scene, &dir.path().join("imported"), 5, None, None, None)
            .expect("the SfM registers the tiny scene");
    // The same model as the scene's own (`sparse/0` in its folder, as a dataset ships it), which
    // `--init colmap` reads without `--colmap-model`.
    let own_scene = dir.path().join("scene_with_model");
    copy_dir(&scene, &own_scene);
    copy_dir(&imported, &own_scene.join("sparse").join("0"));
    for (scene, colmap_model, name) in [
        (&scene, Some(imported.clone()), "dense"),
        (&own_scene, None, "dense_own"),
    ] {
        let out = dir.path().join(name);
        let request = |resume: bool| {
            let init = InitRequest {
                colmap_model: colmap_model.clone(),
                ..InitRequest::new(Init::Colmap)
            };
            let mut req = first_pass_request(scene, &out, init);
            req.cfg.init.sfm_rerun_confirm_imported_pct = 1e9;
            req.cfg.init.sfm_rerun_confirm_max_systematic = 1.0;
            req.cfg.init.confirmed_dense_points = true;
            req.resume = resume;
            req
        };
        let run = train_scene(request(false)).unwrap();

        // The run proper trained from the model's cameras with the first pass's dense points
        // beside its own.
        let dense_dir = out.join("sfm_rerun").join("dense").join("sparse").join("0");
        let (model, dense) = (
            gems_data::colmap::read_model(&imported).unwrap(),
            gems_data::colmap::read_model(&dense_dir).unwrap(),
        );
        assert_eq!(model.images, dense.images, "{name}");
        assert_eq!(model.points, dense.points[..model.points.len()], "{name}");
        let added = dense.points.len() - model.points.len();
        assert!(added > 0, "{name}: no dense points");
        let cfg = TrainConfig::from_toml_file(&out.join("config.toml")).unwrap();
        assert!(added + model.points.len() <= cfg.init.min_points);
        let trained = gems_train::TrainOutput::load(&out).unwrap();
        assert!(
            trained.init_label.contains("dense"),
            "{name}: {}",
            trained.init_label
        );
        let run_init = trained.run.unwrap().init;
        assert!(
            run_init.contains(&format!("with {added} dense points")),
            "{name}: {run_init}"
        );

        // Resumed after the first pass: the dense model is reused, and the run is the same.
        let cloud = std::fs::read(&run.point_cloud).unwrap();
        forget_run_proper(&out);
        let resumed = train_scene(request(true)).unwrap();
        assert_eq!(
            cloud,
            std::fs::read(&resumed.point_cloud).unwrap(),
            "{name}"
        );
    }
}

#[test]
fn the_renders_model_starts_from_dense_points_when_asked() {
    let (dir, scene) = tiny_scene();
    let out = dir.path().join("run");
    let request = |resume: bool| {
        let mut req = first_pass_request(&scene, &out, InitRequest::new(Init::Sfm));
        // The renders' model is kept, whatever its cameras.
        req.cfg.init.sfm_rerun_confirm_pct = 0.0;
        req.cfg.init.renders_dense_points = true;
        req.resume = resume;
        req
    };
    let run = train_scene(request(false)).unwrap();
    let choice = gems_pipeline::probe::RerunChoice::read(&out.join("sfm_rerun"))
        .unwrap()
        .expect("the choice is written");
    assert!(choice.kept, "{}", choice.reason);

    // The run proper trained from the renders' model's cameras with dense points beside its own
    // points, in its frame: each lies in front of the cameras that see it.
    let rerun = out.join("sfm_rerun");
    let (model, dense) = (
        gems_data::colmap::read_model(&rerun.join("sparse").join("0")).unwrap(),
        gems_data::colmap::read_model(&rerun.join("dense").join("sparse").join("0")).unwrap(),
    );
    assert_eq!(model.images, dense.images);
    assert_eq!(model.points, dense.points[..model.points.len()]);
    let added = &dense.points[model.points.len()..];
    assert!(!added.is_empty(), "no dense points");
    for p in added {
        let seen_in_front = model.images.iter().filter(|i| {
            let pose = gems_math::Se3::from(&i.pose());
            (pose.rot * gems_math::Vector3::from(p.xyz) + pose.trans).z > 0.0
        });
        assert!(seen_in_front.count() >= 3, "{p:?}");
    }
    let trained = gems_train::TrainOutput::load(&out).unwrap();
    let run_init = trained.run.unwrap().init;
    assert!(
        run_init.contains(&format!("with {} dense points", added.len()))
            && run_init.contains("init.renders_dense_points"),
        "{run_init}"
    );

    // Resumed after the first pass: the dense model is reused, and the run is the same.
    let cloud = std::fs::read(&run.point_cloud).unwrap();
    forget_run_proper(&out);
    let resumed = train_scene(request(true)).unwrap();
    assert_eq!(cloud, std::fs::read(&resumed.point_cloud).unwrap());
}

/// Removes the run proper's checkpoint and exports from `out`, so that a resumed run trains it
/// again from what the first pass left.
fn forget_run_proper(out: &std::path::Path) {
    for f in [
        "checkpoint.json",
        "checkpoint.safetensors",
        "point_cloud.ply",
    ] {
        std::fs::remove_file(out.join(f)).unwrap();
    }
}

/// Copies the folder `from` (files and subfolders) to `to`.
fn copy_dir(from: &std::path::Path, to: &std::path::Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}

#[test]
fn the_probe_scores_exact_cameras_below_perturbed_ones() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("scene");
    gems_synth::generate(&gems_synth::SynthConfig::tiny(), &root).unwrap();
    let scene = gems_data::open_scene(&root, &gems_data::OpenOptions::default()).unwrap();
    let cfg = TrainConfig {
        steps: 100,
        seed: 5,
        ..TrainConfig::default()
    };
    let checkpoint = dir.path().join("probe");
    let score = |mode: &gems_train::InitMode| {
        gems_pipeline::probe::probe(&scene, mode, &cfg, 30, Engine::cpu(), &checkpoint)
            .unwrap()
            .0
    };
    let exact = score(&gems_train::InitMode::Gt);
    let perturbed = score(&gems_train::InitMode::GtNoisy {
        translation_std: 0.05,
        rotation_std: 0.05,
    });
    assert!(exact.is_finite() && perturbed.is_finite());
    assert!(
        exact < perturbed,
        "exact {exact} against perturbed {perturbed}"
    );
    assert_eq!(
        exact,
        score(&gems_train::InitMode::Gt),
        "same seed, same score"
    );
    // The probe's checkpoint is the state after its steps, in the configuration it ran with.
    let (saved_cfg, state) = gems_train::load_checkpoint(&checkpoint).unwrap();
    assert_eq!(state.step, 30);
    assert_eq!(saved_cfg.steps, 100);
    assert_eq!(state.history.loss.len(), 30);
}

#[test]
fn sfm_rerun_keeps_the_renders_model_only_as_its_probe_says() {
    let (dir, scene) = tiny_scene();
    let out = dir.path().join("run");
    let run = |resume: bool| {
        let mut req = first_pass_request(&scene, &out, InitRequest::new(Init::Sfm));
        req.resume = resume;
        req.cfg.init.sfm_rerun_probe_fraction = 0.4;
        // The probes choose, wherever the renders' cameras lie.
        req.cfg.init.sfm_rerun_confirm_pct = 0.0;
        train_scene(req).unwrap()
    };
    let first = run(false);
    let choice = gems_pipeline::probe::RerunChoice::read(&out.join("sfm_rerun"))
        .unwrap()
        .expect("the choice is written");
    assert_eq!(choice.probe_steps, 4, "0.4 of the run proper's 10 steps");
    let (a, b) = (
        choice.loss_first_model.unwrap(),
        choice.loss_renders_model.unwrap(),
    );
    assert!(a.is_finite() && b.is_finite() && a > 0.0 && b > 0.0);
    assert_eq!(choice.kept, b < a);
    // The run proper follows the choice.
    let cfg = TrainConfig::from_toml_file(&out.join("config.toml")).unwrap();
    let trained = gems_train::TrainOutput::load(&out).unwrap();
    let run_description = trained.run.expect("a pipeline run describes itself");
    if choice.kept {
        assert_eq!(cfg.steps, 10);
        assert!(trained.init_label.contains("sfm_rerun"));
        assert!(
            run_description
                .init
                .contains("then again on the first pass's sharp renders")
        );
    } else {
        assert_eq!(cfg.steps, 20);
        assert!(!trained.init_label.contains("sfm_rerun"));
        assert!(run_description.init.contains("tried and not kept"));
    }
    assert!(
        run_description.init.contains(&choice.reason),
        "{}",
        run_description.init
    );
    for probe in ["probe_first", "probe_renders"] {
        assert!(
            !out.join("sfm_rerun").join(probe).exists(),
            "{probe}: the kept probe's checkpoint moved on, the other's was removed"
        );
    }
    // Resumed after the choice: the same choice and the same result, without probing again.
    // Without a checkpoint the run proper trains from scratch, so the same result also says
    // that continuing the kept model's probe is exact.
    let cloud = std::fs::read(&first.point_cloud).unwrap();
    forget_run_proper(&out);
    std::fs::remove_dir_all(out.join("first_pass")).unwrap();
    let resumed = run(true);
    assert_eq!(cloud, std::fs::read(&resumed.point_cloud).unwrap());
    assert!(
        !out.join("first_pass").exists(),
        "a resumed run with a choice does not train the first pass again"
    );
}

/// `pose.focal_lr` learns an estimated focal, and the SfM on the first pass's renders starts
/// from the learned one (here held there: `init.exif_focal_prior = 0`); a focal given on the
/// command line is kept.
#[test]
fn a_learned_focal_starts_the_renders_sfm_and_a_given_focal_is_kept() {
    let (dir, scene) = tiny_scene();
    let run = |out: &std::path::Path, init: InitRequest| {
        let mut req = first_pass_request(&scene, out, init);
        req.cfg.pose.focal_lr = 1e-2;
        req.cfg.init.exif_focal_prior = 0.0;
        train_scene(req).unwrap();
        (
            gems_train::TrainOutput::load(&out.join("first_pass")).unwrap(),
            gems_train::TrainOutput::load(out).unwrap(),
        )
    };
    let photo_width = {
        let first = gems_fs::list_images(&scene.join("images")).unwrap()[0].clone();
        gems_data::load_image(&first).unwrap().width
    };
    let model_focal = |out: &std::path::Path| {
        let m =
            gems_data::colmap::read_model(&out.join("sfm_rerun").join("sparse").join("0")).unwrap();
        m.cameras[0].intrinsics().unwrap().fx
    };

    let out = dir.path().join("learned");
    let (first, proper) = run(&out, InitRequest::new(Init::Sfm));
    assert_ne!(first.focal_factor, 1.0, "the first pass learns the focal");
    assert_ne!(proper.focal_factor, 1.0, "and so does the run proper");
    let v = &first.views[0];
    let learned = v.intrinsics.fx * f64::from(photo_width) / f64::from(v.intrinsics.width);
    let started = model_focal(&out);
    assert!(
        (started - learned).abs() < 1e-6 * learned,
        "the renders' SfM held {started}, the first pass learned {learned}"
    );

    let mut given = InitRequest::new(Init::Sfm);
    given.focal_px = Some(learned);
    let out = dir.path().join("given");
    let (first, proper) = run(&out, given);
    assert_eq!((first.focal_factor, proper.focal_factor), (1.0, 1.0));
    assert_eq!(first.config.pose.focal_lr, 0.0);
    assert!((model_focal(&out) - learned).abs() < 1e-6 * learned);
}
