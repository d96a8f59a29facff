//! End-to-end tests of scene generation: files, determinism, blur calibration, image formation,
//! events and the blur-level study.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use gems_synth::{
    BLUR_LEVELS, EventOptions, SynthConfig, SynthError, SynthScene, generate, generate_blur_levels,
    image_name, uniform_times,
};

/// Every file under `dir`, relative path → bytes.
fn read_tree(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(
                    p.strip_prefix(dir).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                );
            }
        }
    }
    out
}

fn load_rgb(path: &Path) -> (u32, u32, Vec<u8>) {
    let img = image::open(path).unwrap().to_rgb8();
    (img.width(), img.height(), img.into_raw())
}

/// Mean squared horizontal+vertical gradient of the grey image: a sharpness score.
fn gradient_energy(path: &Path) -> f64 {
    let (w, h, px) = load_rgb(path);
    let (w, h) = (w as usize, h as usize);
    let g = |x: usize, y: usize| {
        px[3 * (y * w + x)..3 * (y * w + x) + 3]
            .iter()
            .map(|&v| f64::from(v))
            .sum::<f64>()
            / 3.0
    };
    let mut sum = 0.0;
    for y in 0..h - 1 {
        for x in 0..w - 1 {
            sum += (g(x + 1, y) - g(x, y)).powi(2) + (g(x, y + 1) - g(x, y)).powi(2);
        }
    }
    sum / ((w - 1) * (h - 1)) as f64
}

fn tiny() -> SynthConfig {
    SynthConfig {
        seed: 11,
        ..SynthConfig::tiny()
    }
}

#[test]
fn writes_the_gems_layout_readable_by_gems_data_and_gems_events() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("scene");
    let cfg = tiny();
    let summary = generate(&cfg, &out).unwrap();
    assert_eq!(summary.views, cfg.views);
    assert_eq!(summary.nvs_views, vec![0]);
    for i in 0..cfg.views {
        for sub in ["images", "images_test"] {
            let (w, h, _) = load_rgb(&out.join(sub).join(image_name(i, cfg.views)));
            assert_eq!((w, h), (cfg.width, cfg.height));
        }
    }
    assert!(out.join("hold=8").is_file());
    assert!(
        !out.join("sparse").exists(),
        "SfM must estimate sparse/0; the generator must not write it"
    );

    let scene = SynthScene::new(&cfg).unwrap();
    // gems-data opens it as a GeMS-layout scene with ground-truth poses and no SfM model.
    let opened = gems_data::open_scene(&out, &gems_data::OpenOptions::default()).unwrap();
    assert_eq!(opened.views.len(), cfg.views);
    assert_eq!(opened.hold, Some(8));
    assert!(opened.sfm.is_none());
    assert_eq!(opened.nvs_eval_views().count(), 1);
    assert_eq!(opened.deblur_eval_views().count(), cfg.views - 1);
    for (v, truth) in opened.views.iter().zip(&scene.views) {
        let gt = v.gt_pose.expect("ground-truth pose");
        let c = gt.center();
        assert!(
            c.iter()
                .zip(truth.mid.centre)
                .all(|(a, b)| (a - b).abs() < 1e-9)
        );
        assert_eq!(
            v.gt_subframe_poses.as_ref().map(Vec::len),
            Some(cfg.subframes)
        );
        assert!(v.sharp_gt.is_some() && v.exposure.is_some());
        assert_eq!((v.width, v.height), (cfg.width, cfg.height));
    }
    let info = gems_data::scene_info(&opened, true).unwrap();
    assert!(info.has_gt_poses && !info.has_sfm);
    let details: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("synth.json")).unwrap()).unwrap();
    assert_eq!(details["config"]["seed"], 11);
    assert_eq!(details["summary"]["events"], summary.events);

    let rows = gems_data::llff::read_poses_bounds(&out.join("poses_bounds.npy")).unwrap();
    assert_eq!(rows.len(), cfg.views);
    for (row, truth) in rows.iter().zip(&scene.views) {
        // The written pose is the ground-truth mid-exposure pose (rotation and centre).
        let (c, r) = (row.pose().center(), row.pose().rotation_c2w());
        assert!(
            c.iter()
                .zip(truth.mid.centre)
                .all(|(a, b)| (a - b).abs() < 1e-9)
        );
        let r_err = r.iter().flatten().zip(truth.mid.rotation.iter().flatten());
        assert!(r_err.map(|(a, b)| (a - b).abs()).fold(0.0, f64::max) < 1e-9);
        assert_eq!(
            (row.height(), row.width()),
            (f64::from(cfg.height), f64::from(cfg.width))
        );
        assert!((row.focal() - scene.intrinsics.fx).abs() < 1e-9);
        assert!(
            row.near > 0.5 && row.near < row.far && row.far < 30.0,
            "bounds {} {}",
            row.near,
            row.far
        );
    }
    let sub = gems_data::llff::read_subframes(&out.join("poses_bounds_subframes.npy")).unwrap();
    assert_eq!(sub.len(), cfg.views);
    assert!(sub.iter().all(|s| s.len() == cfg.subframes));

    let model = gems_data::colmap::read_model(&out.join("gt/sparse/0")).unwrap();
    assert_eq!(model.images.len(), cfg.views);
    assert!(model.points.len() > 100 * cfg.views);
    let img0 = model.image_by_name(&image_name(0, cfg.views)).unwrap();
    let c0 = img0.pose().center();
    assert!((0..3).all(|a| (c0[a] - scene.views[0].mid.centre[a]).abs() < 1e-9));

    let windows =
        gems_events::read_exposure_windows(&out, gems_events::TimeUnit::Microseconds).unwrap();
    assert_eq!(windows.len(), cfg.views);
    let events = gems_events::read_events(
        &out.join("events.npz"),
        &gems_events::ReadOptions::default(),
    )
    .unwrap();
    assert_eq!(events.len(), summary.events);
    assert_eq!(
        (events.width(), events.height()),
        (cfg.width as u16, cfg.height as u16)
    );
    for (v, w) in windows.iter().enumerate() {
        assert_eq!(w.duration(), cfg.exposure_us);
        let n = events.window(w.start, w.end).len();
        assert!(n > 500, "view {v}: only {n} events in its exposure");
    }
    // No event lies outside the exposure windows.
    let inside: usize = windows
        .iter()
        .map(|w| events.window(w.start, w.end).len())
        .sum();
    assert_eq!(inside, events.len());
}

#[test]
fn same_seed_gives_identical_files_and_another_seed_does_not() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = tiny();
    generate(&cfg, &dir.path().join("a")).unwrap();
    // The second run renders on a single thread: results must not depend on the thread count.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    pool.install(|| generate(&cfg, &dir.path().join("b")))
        .unwrap();
    let (a, b) = (
        read_tree(&dir.path().join("a")),
        read_tree(&dir.path().join("b")),
    );
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (k, v) in &a {
        if k == Path::new("synth.json") {
            continue; // holds the output path
        }
        if k == Path::new("events.npz") {
            // gems-events' npz writer stamps the zip entries with the wall-clock time, so
            // compare the decoded event columns.
            let opts = gems_events::ReadOptions::default();
            let ea = gems_events::read_events(&dir.path().join("a/events.npz"), &opts).unwrap();
            let eb = gems_events::read_events(&dir.path().join("b/events.npz"), &opts).unwrap();
            assert!(ea.t() == eb.t() && ea.x() == eb.x() && ea.y() == eb.y() && ea.p() == eb.p());
            continue;
        }
        assert!(v == &b[k], "{} differs", k.display());
    }
    generate(&SynthConfig { seed: 12, ..cfg }, &dir.path().join("c")).unwrap();
    let c = read_tree(&dir.path().join("c"));
    let name = PathBuf::from("images_test").join(image_name(1, 8));
    assert_ne!(a[&name], c[&name]);
}

/// Projects with an independent pinhole model from the *written* LLFF files and checks the mean
/// image-space path of scene points over the sub-frames against the requested blur.
#[test]
fn blur_magnitude_matches_the_request() {
    for blur in [12.0, 40.0] {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("scene");
        let cfg = SynthConfig {
            blur_px: blur,
            subframes: 16,
            events: None,
            ..tiny()
        };
        generate(&cfg, &out).unwrap();
        let scene = SynthScene::new(&cfg).unwrap();
        let mids = gems_data::llff::read_poses_bounds(&out.join("poses_bounds.npy")).unwrap();
        let subs =
            gems_data::llff::read_subframes(&out.join("poses_bounds_subframes.npy")).unwrap();
        for (v, (mid, sub)) in mids.iter().zip(&subs).enumerate() {
            let f = mid.focal();
            let (cx, cy) = (mid.width() / 2.0, mid.height() / 2.0);
            let mid_pose = mid.pose();
            let (r, c) = (mid_pose.rotation_c2w(), mid_pose.center());
            // Scene points: ray-cast the ground-truth world through a grid of pixels at mid-exposure.
            let mut pts = Vec::new();
            for j in 0..12 {
                for i in 0..16 {
                    let (u, w) = (
                        (i as f64 + 0.5) / 16.0 * mid.width(),
                        (j as f64 + 0.5) / 12.0 * mid.height(),
                    );
                    let d = [(u - cx) / f, (w - cy) / f, 1.0];
                    let dw: Vec<f64> = (0..3)
                        .map(|a| r[a][0] * d[0] + r[a][1] * d[1] + r[a][2] * d[2])
                        .collect();
                    let o = gems_synth::V3::new(c[0] as f32, c[1] as f32, c[2] as f32);
                    let dv =
                        gems_synth::V3::new(dw[0] as f32, dw[1] as f32, dw[2] as f32).normalized();
                    if let Some(hit) = scene.world.intersect(o, dv) {
                        let p = o + dv * hit.t;
                        pts.push([f64::from(p.x), f64::from(p.y), f64::from(p.z)]);
                    }
                }
            }
            assert!(pts.len() > 100);
            let project = |row: &gems_data::llff::LlffRow, p: [f64; 3]| {
                let pose = row.pose();
                let x = pose.transform_point(p);
                [f * x[0] / x[2] + cx, f * x[1] / x[2] + cy]
            };
            let mut total = 0.0;
            for p in &pts {
                let q: Vec<[f64; 2]> = sub.iter().map(|row| project(row, *p)).collect();
                total += q
                    .windows(2)
                    .map(|w| ((w[1][0] - w[0][0]).powi(2) + (w[1][1] - w[0][1]).powi(2)).sqrt())
                    .sum::<f64>();
            }
            let measured = total / pts.len() as f64;
            // 16 samples of a smooth cubic path under-measure its length slightly.
            assert!(
                (measured / blur - 1.0).abs() < 0.08,
                "view {v}: blur {measured:.2} px, requested {blur}"
            );
        }
    }
}

#[test]
fn blurry_image_is_the_mean_of_the_sharp_subframes_and_gt_is_mid_exposure() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("scene");
    // Events on: the blur frames are then a subset of the denser event frames.
    let cfg = SynthConfig {
        events: Some(EventOptions {
            max_step_px: 0.5,
            ..EventOptions::default()
        }),
        ..tiny()
    };
    generate(&cfg, &out).unwrap();
    let scene = SynthScene::new(&cfg).unwrap();
    for v in [1, 6] {
        let mut mean = vec![0.0f32; 3 * (cfg.width * cfg.height) as usize];
        for u in uniform_times(cfg.subframes) {
            let f = scene.render_sharp(v, u);
            mean.iter_mut()
                .zip(&f.data)
                .for_each(|(m, x)| *m += x / cfg.subframes as f32);
        }
        let (_, _, blurry) = load_rgb(&out.join("images").join(image_name(v, cfg.views)));
        let worst = blurry
            .iter()
            .zip(&mean)
            .map(|(&b, &m)| (f32::from(b) - m * 255.0).abs())
            .fold(0.0, f32::max);
        assert!(
            worst <= 0.5 + 1e-3,
            "view {v}: blurry PNG is {worst} levels from the sub-frame mean"
        );
        let sharp = scene.render_sharp(v, 0.5).to_rgb8();
        let (_, _, gt) = load_rgb(&out.join("images_test").join(image_name(v, cfg.views)));
        assert_eq!(gt, sharp);
    }
}

#[test]
fn sharp_ground_truth_is_sharper_than_the_blurry_image() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("scene");
    let cfg = SynthConfig {
        blur_px: 20.0,
        events: None,
        ..tiny()
    };
    generate(&cfg, &out).unwrap();
    for v in 0..cfg.views {
        let name = image_name(v, cfg.views);
        let (sharp, blurry) = (
            gradient_energy(&out.join("images_test").join(&name)),
            gradient_energy(&out.join("images").join(&name)),
        );
        assert!(
            sharp > 2.0 * blurry,
            "view {v}: sharp {sharp:.1} vs blurry {blurry:.1}"
        );
    }
}

#[test]
fn blur_levels_make_six_scenes_with_increasing_blur() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("levels");
    let cfg = SynthConfig {
        views: 4,
        blur_px: 30.0,
        ..tiny()
    };
    let summaries = generate_blur_levels(&cfg, &out, &mut |_, _| {}).unwrap();
    assert_eq!(summaries.len(), 6);
    let mut prev_blur = -1.0;
    let mut prev_energy = f64::INFINITY;
    for (s, &n) in summaries.iter().zip(&BLUR_LEVELS) {
        let level = out.join(format!("blur_{n:02}"));
        assert_eq!(s.out_dir, level);
        assert_eq!(s.subframes, n);
        assert!(!level.join("events.npz").exists());
        let sub =
            gems_data::llff::read_subframes(&level.join("poses_bounds_subframes.npy")).unwrap();
        assert!(sub.iter().all(|v| v.len() == n));
        let blur = s.blur_px.iter().sum::<f64>() / s.blur_px.len() as f64;
        assert!(
            blur > prev_blur,
            "level {n}: blur {blur} not above {prev_blur}"
        );
        prev_blur = blur;
        let energy: f64 = (0..cfg.views)
            .map(|v| gradient_energy(&level.join("images").join(image_name(v, cfg.views))))
            .sum();
        assert!(
            energy < prev_energy,
            "level {n}: images are not blurrier than the previous level"
        );
        prev_energy = energy;
        // The middle burst frame is the ground truth of every level, and level 1 is that frame.
        let gt = read_tree(&level.join("images_test"));
        assert_eq!(gt, read_tree(&out.join("blur_01/images_test")));
    }
    assert_eq!(
        read_tree(&out.join("blur_01/images")),
        read_tree(&out.join("blur_01/images_test"))
    );
    assert!(
        (prev_blur / cfg.blur_px - 1.0).abs() < 0.05,
        "full burst blur {prev_blur}"
    );
}

#[test]
fn never_overwrites_and_never_leaves_partial_output() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("scene");
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("keep.txt"), "mine").unwrap();
    let err = generate(&tiny(), &out).unwrap_err();
    assert!(matches!(err, SynthError::OutputExists(_)), "{err}");
    assert_eq!(
        std::fs::read_to_string(out.join("keep.txt")).unwrap(),
        "mine"
    );

    let bad = SynthConfig { views: 0, ..tiny() };
    let fresh = dir.path().join("fresh");
    assert!(matches!(generate(&bad, &fresh), Err(SynthError::Config(_))));
    // A failure while writing (the event simulator rejects this threshold) leaves nothing behind.
    let failing = SynthConfig {
        events: Some(EventOptions {
            threshold_pos: 0.001,
            ..EventOptions::default()
        }),
        ..tiny()
    };
    assert!(generate(&failing, &fresh).is_err());
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(
        left,
        vec![std::ffi::OsString::from("scene")],
        "left behind: {left:?}"
    );

    // An existing empty folder is fine.
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    generate(
        &SynthConfig {
            events: None,
            views: 2,
            ..tiny()
        },
        &empty,
    )
    .unwrap();
    assert!(empty.join("images").is_dir());
}

#[test]
fn events_encode_the_log_intensity_change_of_the_exposure() {
    let cfg = SynthConfig { views: 2, ..tiny() };
    let scene = SynthScene::new(&cfg).unwrap();
    let render = scene.render_view(1).unwrap();
    let events = render.events.unwrap();
    let (t0, t1) = scene.exposure_window_us(1);
    assert_eq!(events.window(t0, t1).len(), events.len());
    let c = cfg.events.as_ref().unwrap().threshold_pos;
    let lum = |img: &gems_synth::Image| -> Vec<f32> {
        img.data
            .chunks_exact(3)
            .map(|p| {
                (0.2126 * p[0].min(1.0) + 0.7152 * p[1].min(1.0) + 0.0722 * p[2].min(1.0) + 1e-3)
                    .ln()
            })
            .collect()
    };
    let (first, last) = (
        lum(&scene.render_linear(1, 0.0)),
        lum(&scene.render_linear(1, 1.0)),
    );
    let mut net = vec![0.0f32; first.len()];
    for i in 0..events.len() {
        net[events.y()[i] as usize * cfg.width as usize + events.x()[i] as usize] +=
            f32::from(events.p()[i]) * c;
    }
    for (i, n) in net.iter().enumerate() {
        let change = last[i] - first[i];
        assert!(
            (n - change).abs() <= c + 1e-4,
            "pixel {i}: events sum {n}, log change {change}"
        );
    }
}

/// Cases where the calibration used to stop short. Seed 197 at 77.5 px (found by the property
/// below): the proportional correction overshot back and forth (59.5 → 86.6 → 73.6 → 79.4 →
/// 76.7 px) and stopped 1.1 % short. Seed 145 at 79.9 px: one view's blur jumps from 75.9 to
/// 84.3 px between two nearby scales (scene points pass behind the camera), so no scale of that
/// motion reaches the target and another motion must be drawn.
#[test]
fn calibration_converges_where_proportional_steps_oscillate_or_the_blur_jumps() {
    for (seed, blur) in [(197, 77.54899460797411), (145, 79.9)] {
        let scene = SynthScene::new(&SynthConfig {
            seed,
            blur_px: blur,
            ..SynthConfig::tiny()
        })
        .unwrap();
        for v in &scene.views {
            assert!(
                (v.blur_px / blur - 1.0).abs() < 0.01,
                "seed {seed}: achieved {} for {blur}",
                v.blur_px
            );
        }
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(12))]
    /// Calibration reaches the requested blur for any seed and blur strength (no rendering).
    #[test]
    fn calibration_hits_any_requested_blur(seed in 0u64..1000, blur in 2.0f64..80.0) {
        let scene = SynthScene::new(&SynthConfig { seed, blur_px: blur, ..SynthConfig::tiny() }).unwrap();
        for v in &scene.views {
            proptest::prop_assert!((v.blur_px / blur - 1.0).abs() < 0.01, "achieved {} for {blur}", v.blur_px);
            proptest::prop_assert!(v.near > 0.0 && v.near < v.far);
        }
    }
}
