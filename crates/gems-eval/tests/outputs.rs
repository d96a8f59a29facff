//! Scores, metrics.json, TUM files, APE and the HTML report.

mod common;

use gems_eval::tum::{format_tum, read_tum, write_tum};
use gems_eval::*;

#[test]
fn scores_and_split_means() {
    let (h, w) = (20, 24);
    let a: Vec<f32> = (0..h * w * 3).map(|i| (i % 17) as f32 / 16.0).collect();
    let mut b = a.clone();
    b[5] += 0.3;
    let same = score_image("a", &a, &a, h, w, None).unwrap();
    assert!(same.psnr.is_infinite() && (same.ssim - 1.0).abs() < 1e-12 && same.lpips.is_none());
    // Renders are clamped before scoring: overshoot above 1 where the target is 1 costs nothing.
    let over: Vec<f32> = a.iter().map(|&v| if v == 1.0 { 1.5 } else { v }).collect();
    assert!(
        score_image("o", &over, &a, h, w, None)
            .unwrap()
            .psnr
            .is_infinite()
    );
    let s1 = score_image("x", &b, &a, h, w, None).unwrap();
    let mk = |name: &str, psnr: f64, lpips: Option<f64>| ImageScore {
        name: name.into(),
        psnr,
        ssim: 0.5,
        lpips,
    };
    let split =
        SplitScores::from_images(vec![mk("p", 20.0, Some(0.1)), mk("q", 30.0, Some(0.3))]).unwrap();
    assert_eq!(split.psnr, 25.0);
    assert!((split.lpips.unwrap() - 0.2).abs() < 1e-15);
    let partial =
        SplitScores::from_images(vec![mk("p", 20.0, Some(0.1)), mk("q", 30.0, None)]).unwrap();
    assert_eq!(
        partial.lpips, None,
        "LPIPS absent as soon as one image lacks it"
    );
    assert!(SplitScores::from_images(vec![]).is_none());
    assert!(s1.psnr > 30.0 && s1.psnr.is_finite());
}

fn run_description() -> gems_train::RunDescription {
    gems_train::RunDescription {
        protocol: Some("deblur-nerf-real".into()),
        scene: "blurball".into(),
        dataset: "Deblur-NeRF / LLFF".into(),
        downscale: 4,
        hold: Some(7),
        train_views: 23,
        held_out_views: 4,
        init: "the dataset's COLMAP model".into(),
        steps: 7000,
        virtual_views: 15,
        mean_virtual_views: Some(6.5),
        device: "cpu (2 threads)".into(),
        wall_seconds: 95.0,
        peak_memory_bytes: Some(3 << 29),
    }
}

#[test]
fn metrics_json_round_trip_and_keys() {
    let dir = tempfile::tempdir().unwrap();
    let img = ImageScore {
        name: "v0".into(),
        psnr: 25.0,
        ssim: 0.8,
        lpips: None,
    };
    let report = MetricsReport {
        deblur: SplitScores::from_images(vec![img.clone()]),
        deblur_refined: SplitScores::from_images(vec![img.clone()]),
        input: SplitScores::from_images(vec![img.clone()]),
        nvs: None,
        nvs_no_pose_opt: SplitScores::from_images(vec![img]),
        ape: Some(ApeSummary {
            rmse: 0.1,
            mean: 0.09,
            median: 0.08,
            std: 0.02,
            max: 0.2,
        }),
        ape_init: Some(ApeSummary {
            rmse: 0.3,
            mean: 0.25,
            median: 0.2,
            std: 0.1,
            max: 0.6,
        }),
        rotation_error: Some(RotationErrorSummary {
            rmse_deg: 1.5,
            mean_deg: 1.2,
            median_deg: 1.1,
            max_deg: 3.0,
        }),
        rotation_error_init: None,
        focal: Some(FocalSummary {
            initial_px: 146.5,
            trained_px: 170.25,
            scene_px: Some(173.2),
        }),
        steps: 7000,
        seconds: 12.5,
        gaussians: 1234,
        init: "gt-noisy".into(),
        labels: split_labels()
            .into_iter()
            .map(|(k, v)| (k.to_owned(), v.to_owned()))
            .collect(),
        held_out_pose: Some(HeldOutPosing {
            source: "the dataset's poses (its COLMAP model)".into(),
            frame: HeldOutFrame::Trained,
            similarity_cameras: 23,
        }),
        camera_shift: Some(CameraShift {
            views: 23,
            centre_pct: 0.5,
            rotation_deg: 0.25,
            initial_centre_pct: 0.0,
            initial_rotation_deg: 0.0,
        }),
        run: Some(run_description()),
        eval_seconds: Some(3.5),
    };
    let path = dir.path().join("metrics.json");
    write_metrics_json(&path, &report).unwrap();
    assert_eq!(read_metrics_json(&path).unwrap(), report);
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    for key in [
        "deblur",
        "deblur_refined",
        "input",
        "nvs",
        "nvs_no_pose_opt",
        "ape",
        "ape_init",
        "rotation_error",
        "focal",
        "steps",
        "seconds",
        "gaussians",
        "labels",
        "held_out_pose",
        "camera_shift",
        "run",
    ] {
        assert!(v.get(key).is_some(), "missing key {key}");
    }
    // Every split is labelled with what it measures.
    for key in [
        "input",
        "deblur",
        "deblur_refined",
        "nvs",
        "nvs_no_pose_opt",
    ] {
        assert!(v["labels"][key].is_string(), "no label for {key}");
    }
    assert_eq!(v["run"]["protocol"], "deblur-nerf-real");
    assert!(v["deblur"]["lpips"].is_null() && v["nvs"].is_null());
    for key in ["psnr", "ssim", "lpips", "per_image"] {
        assert!(v["deblur"].get(key).is_some(), "missing deblur.{key}");
    }
    for key in ["rmse", "mean", "median", "std", "max"] {
        assert!(v["ape"][key].is_number(), "missing ape.{key}");
        assert!(v["ape_init"][key].is_number(), "missing ape_init.{key}");
    }
    // A perfect render's infinite PSNR survives the JSON round trip (written as null).
    let mut perfect = report;
    perfect.deblur.as_mut().unwrap().per_image[0].psnr = f64::INFINITY;
    perfect.deblur.as_mut().unwrap().psnr = f64::INFINITY;
    write_metrics_json(&path, &perfect).unwrap();
    assert_eq!(read_metrics_json(&path).unwrap(), perfect);
    // A file written before `deblur_refined` and `input` existed still reads, without them.
    let mut old = v.clone();
    let obj = old.as_object_mut().unwrap();
    obj.remove("deblur_refined");
    obj.remove("input");
    std::fs::write(&path, old.to_string()).unwrap();
    let read = read_metrics_json(&path).unwrap();
    assert!(read.deblur_refined.is_none() && read.input.is_none() && read.deblur.is_some());
    // A broken file gives an error naming it.
    std::fs::write(&path, "{ not json").unwrap();
    assert!(
        read_metrics_json(&path)
            .unwrap_err()
            .to_string()
            .contains("metrics.json")
    );
}

#[test]
fn tum_round_trip() {
    let poses: Vec<(f64, gems_math::Se3)> = (0..5)
        .map(|i| {
            (
                i as f64 / 4.0,
                common::perturb(&common::camera(i as f64), [0.1, 0.2, 0.3, 0.1, -0.2, 0.3]),
            )
        })
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.txt");
    write_tum(&path, &poses).unwrap();
    let back = read_tum(&path).unwrap();
    assert_eq!(back.len(), 5);
    for ((ta, a), (tb, b)) in poses.iter().zip(&back) {
        assert!((ta - tb).abs() < 1e-9);
        assert!((a.trans - b.trans).norm() < 1e-14 && (a.rot - b.rot).abs().max() < 1e-14);
    }
    // tx ty tz qx qy qz qw order: identity pose line.
    let line = format_tum(&[(0.0, gems_math::Se3::identity())]);
    let vals: Vec<f64> = line
        .lines()
        .nth(1)
        .unwrap()
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    assert_eq!(vals, vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
    std::fs::write(&path, "0 1 2 3\n").unwrap();
    let err = read_tum(&path).unwrap_err().to_string();
    assert!(err.contains("t.txt") && err.contains("line 1"), "{err}");
}

#[test]
fn relative_rotation_error_ignores_the_frame_and_measures_each_view() {
    use gems_math::{Matrix3, So3, Vector3};
    let gt: Vec<Matrix3<f64>> = (0..6)
        .map(|i| So3::exp(&Vector3::new(0.05 * i as f64, 0.3 - 0.1 * i as f64, 0.02)).0)
        .collect();
    // A different world frame (any global rotation) changes nothing.
    let frame = So3::exp(&Vector3::new(0.7, -0.4, 1.9)).0;
    let est: Vec<_> = gt.iter().map(|r| frame * r).collect();
    let same = relative_rotation_error(&est, &gt).unwrap();
    assert!(same.rmse_deg < 1e-9 && same.max_deg < 1e-9, "{same:?}");
    // Turning one camera by 2° about its own axis gives 2° on each of its 5 pairs, 0 on the
    // other 10: mean 2/3°, median 0, max 2°, RMSE 2/√3°.
    let mut turned = est;
    let angle = 2f64.to_radians();
    turned[3] *= So3::exp(&Vector3::new(0.0, angle, 0.0)).0;
    let e = relative_rotation_error(&turned, &gt).unwrap();
    assert!((e.max_deg - 2.0).abs() < 1e-9, "{e:?}");
    assert!((e.mean_deg - 2.0 / 3.0).abs() < 1e-9, "{e:?}");
    assert!(e.median_deg.abs() < 1e-9, "{e:?}");
    assert!((e.rmse_deg - 2.0 / 3f64.sqrt()).abs() < 1e-9, "{e:?}");
    // Fewer than two views, or mismatched lengths: one clear error.
    let err = relative_rotation_error(&gt[..1], &gt[..1])
        .unwrap_err()
        .to_string();
    assert!(err.contains("two or more views"), "{err}");
    assert!(relative_rotation_error(&gt[..3], &gt[..4]).is_err());
}

#[test]
fn ape_is_invariant_to_similarity() {
    let gt: Vec<[f64; 3]> = (0..8)
        .map(|i| common::camera(i as f64 * 0.4).trans.into())
        .collect();
    let sim = gems_math::Sim3 {
        scale: 0.37,
        rot: gems_math::So3::exp(&gems_math::Vector3::new(0.4, 0.1, -0.7)).0,
        trans: gems_math::Vector3::new(3.0, -1.0, 2.0),
    };
    let est: Vec<[f64; 3]> = gt.iter().map(|p| sim.act(p)).collect();
    let a = ape_of_centres(&est, &gt).unwrap();
    assert!(a.rmse < 1e-10 && a.max < 1e-10);
    let mut noisy = est;
    noisy[3][0] += 0.37; // 1 GT unit after undoing the scale
    let b = ape_of_centres(&noisy, &gt).unwrap();
    assert!(b.max > 0.5 && b.max < 1.0 && b.rmse < b.max);
}

#[test]
fn report_writes_html_and_figures() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (16u32, 12u32);
    let img = |v: f32| vec![v; (w * h * 3) as usize];
    let metrics = MetricsReport {
        deblur: SplitScores::from_images(vec![ImageScore {
            name: "<v0>".into(),
            psnr: 25.0,
            ssim: 0.8,
            lpips: None,
        }]),
        deblur_refined: None,
        input: None,
        nvs: None,
        nvs_no_pose_opt: None,
        ape: None,
        ape_init: None,
        rotation_error: Some(RotationErrorSummary {
            rmse_deg: 2.345,
            mean_deg: 2.0,
            median_deg: 1.9,
            max_deg: 4.5,
        }),
        rotation_error_init: Some(RotationErrorSummary {
            rmse_deg: 6.789,
            mean_deg: 6.0,
            median_deg: 5.9,
            max_deg: 9.5,
        }),
        focal: Some(FocalSummary {
            initial_px: 146.5,
            trained_px: 170.25,
            scene_px: Some(173.2),
        }),
        steps: 10,
        seconds: 1.0,
        gaussians: 5,
        init: "gt-noisy (σ 0.01)".into(),
        labels: Default::default(),
        held_out_pose: Some(HeldOutPosing {
            source: "the dataset's poses (its poses file)".into(),
            frame: HeldOutFrame::Initial,
            similarity_cameras: 4,
        }),
        camera_shift: None,
        run: Some(run_description()),
        eval_seconds: Some(2.0),
    };
    let traj: Vec<Vec<[f64; 3]>> = (0..4)
        .map(|v| {
            (0..5)
                .map(|k| [v as f64 + 0.1 * k as f64, 0.05 * k as f64, v as f64 * 0.3])
                .collect()
        })
        .collect();
    let input = ReportInput {
        title: "test".into(),
        metrics,
        loss: (0..100).map(|i| 1.0 / (1.0 + i as f32)).collect(),
        psnr: (0..100).map(|i| 10.0 + i as f32 * 0.1).collect(),
        gt_centres: traj.iter().map(|t| Some(t[2])).collect(),
        gt_paths: Vec::new(),
        trajectories: traj,
        grid: vec![GridRow {
            name: "v0".into(),
            width: w,
            height: h,
            blurry: img(0.2),
            edi: None,
            ours: img(0.5),
            gt: Some(img(0.9)),
        }],
        viewer: None,
        registration: Some(report::Registration {
            views: vec![report::RegisteredPhoto {
                name: "blurred_<9>.png".into(),
                registered: false,
                blur_px: 61.5,
                points: 0,
                reprojection_error_px: None,
                why_not: Some("much more blurred than the others".into()),
            }],
            advice: vec!["1 of 1 photos were not registered".into()],
            focal_barely_determined: false,
        }),
    };
    let html_path = write_report(dir.path(), &input).unwrap();
    let html_text = std::fs::read_to_string(&html_path).unwrap();
    assert!(
        html_text.contains("blurred_&lt;9&gt;.png")
            && html_text.contains("61.5")
            && html_text.contains("1 of 1 photos were not registered")
            && html_text.contains("much more blurred"),
        "the registration table"
    );
    let html = std::fs::read_to_string(&html_path).unwrap();
    assert!(
        html.contains("&lt;v0&gt;")
            && html.contains("gt-noisy")
            && html.contains("LPIPS is absent")
    );
    // The report opens with what ran, before any figure.
    let what_ran = html.find("What ran").expect("a 'What ran' table");
    assert!(what_ran < html.find("Metrics").unwrap());
    for needle in [
        "deblur-nerf-real",
        "×4",
        "every 7th view held out",
        "23 training, 4 held out",
        "the dataset's COLMAP model",
        "7000 steps, up to 15 virtual views per exposure (6.5 per step on average",
        "cpu (2 threads)",
        "95 s initialisation and training, evaluation 2 s",
        "1.50 GiB",
        "poses file), carried into the result's initial frame by the similarity of 4 training cameras",
    ] {
        assert!(html.contains(needle), "report lacks {needle:?}");
    }
    for f in ["loss.png", "psnr.png", "trajectory.png", "grid.png"] {
        let p = dir.path().join("report").join(f);
        let im = gems_data::load_image(&p).unwrap();
        assert!(html.contains(&format!("report/{f}")));
        // Not blank: some pixels differ from the white background.
        assert!(im.data.iter().any(|&v| v < 0.9), "{f} is blank");
    }
    let grid = gems_data::load_image(&dir.path().join("report/grid.png")).unwrap();
    assert_eq!((grid.width, grid.height), (3 * w + 8, h));
    assert!(
        (grid.pixel(1, 1)[0] - 0.2).abs() < 0.01 && (grid.pixel(w + 5, 1)[0] - 0.5).abs() < 0.01
    );
    assert!(!html.contains("EDI"), "no EDI column without EDI images");
    // blurry 0.2 vs gt 0.9: 20·log10(1/0.7) = 3.10 dB; ours 0.5: 7.96 dB
    assert!(html.contains("3.10 dB") && html.contains("7.96 dB"));
    assert!(html.contains("RMSE 2.345°") && html.contains("RMSE 6.789°"));
    assert!(
        html.contains("146.5 px at the start, 170.2 px trained")
            && html.contains("173.2 px: -15.42 % at the start, -1.70 % trained"),
        "the focal line"
    );

    // Ground-truth sub-frame paths are drawn as green lines beside the estimate.
    let green = |dir: &std::path::Path| {
        let im = gems_data::load_image(&dir.join("report/trajectory.png")).unwrap();
        im.data
            .chunks_exact(3)
            .filter(|p| (p[0] - 20.0 / 255.0).abs() < 0.02 && (p[1] - 150.0 / 255.0).abs() < 0.02)
            .count()
    };
    let mut with_paths = input.clone();
    with_paths.gt_paths = with_paths
        .trajectories
        .iter()
        .map(|t| t.iter().map(|p| [p[0], p[1] + 0.08, p[2]]).collect())
        .collect();
    let dir3 = tempfile::tempdir().unwrap();
    write_report(dir3.path(), &with_paths).unwrap();
    assert!(
        green(dir3.path()) > green(dir.path()) + 50,
        "{} vs {} green pixels",
        green(dir3.path()),
        green(dir.path())
    );

    // With an EDI image the grid gains a column between the input and ours.
    let mut with_edi = input;
    with_edi.grid[0].edi = Some(img(0.7));
    let dir2 = tempfile::tempdir().unwrap();
    let html = std::fs::read_to_string(write_report(dir2.path(), &with_edi).unwrap()).unwrap();
    assert!(html.contains("EDI from events") && html.contains("13.98 dB"));
    let grid = gems_data::load_image(&dir2.path().join("report/grid.png")).unwrap();
    assert_eq!((grid.width, grid.height), (4 * w + 12, h));
    let col = |k: u32| grid.pixel(k * (w + 4) + 1, 1)[0];
    for (k, v) in [(0, 0.2), (1, 0.7), (2, 0.5), (3, 0.9)] {
        assert!((col(k) - v).abs() < 0.01, "column {k}: {} vs {v}", col(k));
    }
}
