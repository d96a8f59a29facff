//! The whole protocol on a hand-built trained result: deblur at the midpoints, novel views with
//! and without refinement, APE, and every output file.

mod common;

use gems_eval::tum::read_tum;
use gems_eval::*;
use gems_math::Pose;
use gems_math::Se3;
use gems_train::Normalization;
use gems_train::{TrainOutput, ViewResult};

fn output(mid_noise: f64) -> (TrainOutput, EvalData) {
    let g = common::scene(60, -2.6, 0.5);
    let k = common::intrinsics();
    let mut engine = gems_gpu::Engine::cpu();
    let mut r = engine.freeze(&g).unwrap();
    let mut views = Vec::new();
    let mut data = EvalData::default();
    for i in 0..5 {
        let truth = common::camera(0.15 * i as f64 - 0.3);
        let s = mid_noise * if i % 2 == 0 { 1.0 } else { -1.0 };
        let mid = common::perturb(&truth, [s, 0.5 * s, -s, 0.2 * s, 0.1 * s, -0.3 * s]);
        let virt: Vec<Se3> = (0..5)
            .map(|j| common::perturb(&mid, [0.01 * (j as f64 - 2.0), 0.0, 0.0, 0.0, 0.0, 0.0]))
            .collect();
        views.push(ViewResult {
            name: format!("images/{i:04}.png"),
            intrinsics: k,
            c2w_init: Pose::from(&truth),
            c2w_gt: Some(Pose::from(&truth)),
            c2w_gt_subframes: Vec::new(),
            knots: vec![[0.0; 6]; 9],
            virtual_c2w: virt.iter().map(Pose::from).collect(),
            mid_c2w: Pose::from(&mid),
        });
        let gt = refine::render(&mut r, &truth, &k).unwrap();
        data.train_blurry
            .push(Some(gt.iter().map(|v| v * 0.8).collect()));
        data.train_gt.push(Some(gt));
    }
    for (i, a) in [0.05, 0.22].into_iter().enumerate() {
        let truth = common::camera(a);
        data.held_out.push(HeldOutView {
            name: format!("novel{i}"),
            intrinsics: k,
            c2w_init: common::perturb(&truth, [0.02, -0.01, 0.015, 0.008, -0.006, 0.004]),
            gt: refine::render(&mut r, &truth, &k).unwrap(),
        });
    }
    drop(r);
    let out = TrainOutput {
        config: gems_train::TrainConfig::default(),
        normalization: Normalization::identity(),
        scene_scale: 1.0,
        init_label: "gt-noisy (test)".into(),
        gaussians: g,
        views,
        history: gems_train::History {
            loss: (0..50).map(|i| 0.5 / (1.0 + i as f32)).collect(),
            psnr: (0..50).map(|i| 15.0 + 0.2 * i as f32).collect(),
            gaussians: vec![60; 50],
            view: vec![0; 50],
            virtual_views: vec![15; 50],
        },
        seconds: 3.0,
        steps: 50,
        focal_factor: 1.0,
        pose_model: None,
        run: None,
    };
    (out, data)
}

#[test]
fn protocol_and_outputs() {
    let (out, data) = output(0.004);
    let mut seen = Vec::new();
    let eval = evaluate_output_on(
        &mut gems_gpu::Engine::cpu(),
        &out,
        &data,
        &PoseRefineConfig::default(),
        None,
        &mut |n| seen.push(n.to_owned()),
    )
    .unwrap();
    assert_eq!(seen.len(), evaluation_units(&data));
    assert_eq!(
        (seen[0].as_str(), seen[5].as_str(), seen[8].as_str()),
        ("images/0000.png", "novel0", "novel1")
    );
    let m = &eval.metrics;
    let deblur = m.deblur.as_ref().unwrap();
    assert_eq!(deblur.per_image.len(), 5);
    assert!(deblur.psnr > 20.0 && deblur.psnr.is_finite() && deblur.lpips.is_none());
    // The authors' protocol refines each training view from its initial pose, which is the true
    // pose here, while the midpoints carry noise: refined must beat the midpoint figure.
    let refined = m.deblur_refined.as_ref().unwrap();
    assert_eq!(refined.per_image.len(), 5);
    assert!(
        refined.psnr > deblur.psnr + 5.0,
        "refined {} vs midpoint {}",
        refined.psnr,
        deblur.psnr
    );
    // The blurry-input baseline scores each blurry image (here 0.8 × the ground truth) itself.
    let input = m.input.as_ref().unwrap();
    assert_eq!(input.per_image.len(), 5);
    let k = common::intrinsics();
    let (h, w) = (k.height as usize, k.width as usize);
    for (i, score) in input.per_image.iter().enumerate() {
        let (blurry, gt) = (
            data.train_blurry[i].as_ref().unwrap(),
            data.train_gt[i].as_ref().unwrap(),
        );
        let expect = gems_metrics::psnr(blurry, gt, h, w).unwrap();
        assert!(
            (score.psnr - expect).abs() < 1e-9,
            "{} vs {expect}",
            score.psnr
        );
    }
    assert!(
        input.psnr < deblur.psnr,
        "{} vs {}",
        input.psnr,
        deblur.psnr
    );
    let (nvs, raw) = (m.nvs.as_ref().unwrap(), m.nvs_no_pose_opt.as_ref().unwrap());
    assert_eq!(nvs.per_image.len(), 2);
    assert!(
        nvs.psnr > raw.psnr + 5.0,
        "refinement must help: {} vs {}",
        nvs.psnr,
        raw.psnr
    );
    let ape = m.ape.unwrap();
    assert!(ape.rmse > 0.0 && ape.rmse < 0.02, "{ape:?}");
    // The initial poses are the truth here; only the midpoints carry the noise.
    assert!(m.ape_init.unwrap().rmse < 1e-9, "{:?}", m.ape_init);
    assert_eq!(
        (m.steps, m.gaussians, m.init.as_str()),
        (50, 60, "gt-noisy (test)")
    );

    // Exact midpoints: APE vanishes, deblur renders equal the ground truth.
    let (exact, data2) = output(0.0);
    let e2 = evaluate_output(
        &exact,
        &data2,
        &PoseRefineConfig {
            steps: 5,
            ..Default::default()
        },
        None,
    )
    .unwrap();
    assert!(e2.metrics.ape.unwrap().rmse < 1e-9);
    assert!(e2.metrics.deblur.unwrap().psnr.is_infinite());

    let dir = tempfile::tempdir().unwrap();
    write_metrics_json(&dir.path().join("metrics.json"), m).unwrap();
    write_trajectories(dir.path(), &out).unwrap();
    let mid = read_tum(&dir.path().join("trajectories/mid.txt")).unwrap();
    assert_eq!(mid.len(), 5);
    let expect = Se3::from(&out.views[3].mid_c2w);
    assert!((mid[3].1.trans - expect.trans).norm() < 1e-12 && mid[3].0 == 3.0);
    let v0 = read_tum(&dir.path().join("trajectories/0000.txt")).unwrap();
    assert_eq!(v0.len(), 5);
    assert_eq!((v0[0].0, v0[4].0), (0.0, 1.0));
    assert_eq!(
        read_tum(&dir.path().join("trajectories/gt.txt"))
            .unwrap()
            .len(),
        5
    );
    let html = write_report(dir.path(), &report_input(&out, &data, &eval, 3)).unwrap();
    let text = std::fs::read_to_string(html).unwrap();
    let grid_section = &text[text.find("report/grid.png").expect("grid in the report")..];
    let rows: Vec<&str> = grid_section
        .split("<tr><td>")
        .skip(1)
        .filter_map(|r| r.split("</td>").next())
        .filter(|name| name.starts_with("images/"))
        .collect();
    assert_eq!(
        rows,
        ["images/0000.png", "images/0001.png", "images/0002.png"],
        "grid limited to 3 rows, one PSNR row each"
    );
    let grid = gems_data::load_image(&dir.path().join("report/grid.png")).unwrap();
    assert_eq!(grid.height, 3 * 60 + 2 * 4);
}

#[test]
fn mismatched_ground_truth_is_an_error() {
    let (out, mut data) = output(0.0);
    data.train_gt.pop();
    assert!(matches!(
        evaluate_output(&out, &data, &PoseRefineConfig::default(), None),
        Err(EvalError::Input(_))
    ));
    let (out, mut data) = output(0.0);
    data.held_out[0].gt.truncate(10);
    assert!(evaluate_output(&out, &data, &PoseRefineConfig::default(), None).is_err());
}
