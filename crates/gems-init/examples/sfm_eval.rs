//! Accuracy of the built-in SfM on one `gems synth` scene (the `gems demo` scene by default:
//! small preset, 24 views, 240×160, 30 px blur). Not part of CI.
//!
//! Usage: sfm_eval <work_dir> [--views N] [--seed S] [--estimate-focal] [--levels-dir DIR]
//!        [--working-sizes 192,128] [--grid SPACING_FRAC] [--neighbours N]
//!        [--max-reproj PX] [--focal F] [--focal-prior REL]
//!        [--order detect|ordered|unordered] [--path-centre SIGMA] [--path-rot DEG]
//!        [--refine-max-blur PX] [--refine-patch RATIO] [--initial-pairs N]
//! With `--levels-dir`, the scene is an existing folder with `images/` and `poses_bounds.npy`
//! (e.g. a `blur_09` level of `gems synth --blur-levels`, or a Deblur-NeRF real scene, whose
//! poses file is its COLMAP model's) instead of a generated one. `--focal` gives the SfM that
//! focal (e.g. the photos' EXIF one) instead of the reference's; `--focal-prior` refines it in
//! the final bundle adjustment under a prior of that relative width.
//! Prints registered views, points, translation RMSE over the path extent after Sim(3)
//! alignment, the mean relative-rotation error over all registered pairs (degrees), the focal
//! and its error; per-view centre errors go to stderr.

use gems_init::sfm::{CaptureOrder, SfmOptions, load_images, run_sfm};
use std::path::PathBuf;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let work = PathBuf::from(&args[0]);
    let mut cfg = gems_synth::SynthConfig {
        views: 24,
        events: None,
        ..gems_synth::SynthConfig::small()
    };
    let mut estimate = false;
    let mut working_sizes: Option<Vec<u32>> = None;
    let mut grid: Option<f32> = None;
    let mut reproj: Option<f64> = None;
    let mut neighbours: Option<usize> = None;
    let mut level_dir: Option<PathBuf> = None;
    let mut given_focal: Option<f64> = None;
    let mut focal_prior: Option<f64> = None;
    let mut order: Option<CaptureOrder> = None;
    let mut path_centre: Option<f64> = None;
    let mut path_rot: Option<f64> = None;
    let mut refine: Option<f64> = None;
    let mut refine_patch: Option<f64> = None;
    let mut initial_pairs: Option<usize> = None;
    let mut trim: Option<f64> = None;
    let mut affine: Option<f64> = None;
    let mut it = args[1..].iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--views" => cfg.views = it.next().unwrap().parse().unwrap(),
            "--seed" => cfg.seed = it.next().unwrap().parse().unwrap(),
            "--estimate-focal" => estimate = true,
            "--max-reproj" => reproj = Some(it.next().unwrap().parse().unwrap()),
            "--grid" => grid = Some(it.next().unwrap().parse().unwrap()),
            "--neighbours" => neighbours = Some(it.next().unwrap().parse().unwrap()),
            "--working-sizes" => {
                working_sizes = Some(
                    it.next()
                        .unwrap()
                        .split(',')
                        .map(|v| v.parse().unwrap())
                        .collect(),
                );
            }
            "--levels-dir" => level_dir = Some(PathBuf::from(it.next().unwrap())),
            "--focal" => given_focal = Some(it.next().unwrap().parse().unwrap()),
            "--focal-prior" => focal_prior = Some(it.next().unwrap().parse().unwrap()),
            "--order" => {
                order = Some(match it.next().unwrap().as_str() {
                    "ordered" => CaptureOrder::Ordered,
                    "unordered" => CaptureOrder::Unordered,
                    "detect" => CaptureOrder::Detect,
                    o => panic!("unknown order {o}"),
                });
            }
            "--path-centre" => path_centre = Some(it.next().unwrap().parse().unwrap()),
            "--path-rot" => path_rot = Some(it.next().unwrap().parse().unwrap()),
            "--refine-max-blur" => refine = Some(it.next().unwrap().parse().unwrap()),
            "--refine-patch" => refine_patch = Some(it.next().unwrap().parse().unwrap()),
            "--initial-pairs" => initial_pairs = Some(it.next().unwrap().parse().unwrap()),
            "--trim" => trim = Some(it.next().unwrap().parse().unwrap()),
            "--affine-max-blur" => affine = Some(it.next().unwrap().parse().unwrap()),
            s => panic!("unknown argument {s}"),
        }
    }
    let dir = match level_dir {
        Some(d) => d,
        None => {
            let d = work.join(format!("small_v{}_s{}", cfg.views, cfg.seed));
            if !d.join("poses_bounds.npy").exists() {
                gems_synth::generate(&cfg, &d).unwrap();
            }
            d
        }
    };
    let rows = gems_data::llff::read_poses_bounds(&dir.join("poses_bounds.npy")).unwrap();
    let images = load_images(&dir).unwrap();
    let gt_focal = rows[0].focal();
    let mut opts = SfmOptions {
        focal_px: (!estimate).then_some(given_focal.unwrap_or(gt_focal)),
        focal_prior,
        seed: cfg.seed,
        ..SfmOptions::default()
    };
    if let Some(v) = reproj {
        opts.max_reproj_px = v;
    }
    if let Some(g) = grid {
        opts.grid_spacing_frac = g;
    }
    if let Some(n) = neighbours {
        opts.track_neighbours = n;
    }
    if let Some(b) = refine {
        opts.refine_max_blur_px = b;
    }
    if let Some(r) = refine_patch {
        opts.refine_patch_blur_ratio = r;
    }
    if let Some(b) = affine {
        opts.refine_affine_max_blur_px = b;
    }
    if let Some(f) = trim {
        opts.trim_fraction = f;
    }
    if let Some(n) = initial_pairs {
        opts.initial_pairs = n;
    }
    if let Some(o) = order {
        opts.capture_order = o;
    }
    if let Some(s) = path_centre {
        opts.path_centre_sigma = s;
    }
    if let Some(s) = path_rot {
        opts.path_rotation_sigma_deg = s;
    }
    if let Some(ws) = working_sizes {
        opts.working_sizes = ws;
    }
    let r = match run_sfm(&images, &opts) {
        Ok(r) => r,
        Err(e) => {
            println!("{}: sfm failed: {e}", dir.display());
            return;
        }
    };
    let gt: Vec<gems_math::Pose> = rows.iter().map(|r| r.pose()).collect();
    let m = |r: &[[f64; 3]; 3]| nalgebra::Matrix3::from_fn(|i, j| r[i][j]);
    let (mut est, mut g, mut rots) = (Vec::new(), Vec::new(), Vec::new());
    for (v, gp) in r.views.iter().zip(&gt) {
        if let Some(p) = v.pose {
            est.push(<[f64; 3]>::from(gems_math::camera_center_from_w2c(&p)));
            g.push(gp.center());
            rots.push((p.rot, m(&gp.rotation)));
        }
    }
    let sim = gems_math::align::umeyama(&est, &g, true).unwrap();
    let dist =
        |a: &[f64; 3], b: &[f64; 3]| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt();
    let mse = est
        .iter()
        .zip(&g)
        .map(|(s, d)| dist(&sim.act(s), d).powi(2))
        .sum::<f64>()
        / est.len() as f64;
    let mut extent: f64 = 0.0;
    for a in &gt {
        for b in &gt {
            extent = extent.max(dist(&a.center(), &b.center()));
        }
    }
    // Gauge-free: mean over all registered pairs of the angle between the estimated and the
    // true relative rotation (an arc of centres leaves the Sim(3) rotation poorly determined).
    let (mut rot_sum, mut npairs) = (0.0, 0usize);
    for a in 0..rots.len() {
        for b in a + 1..rots.len() {
            let re = rots[b].0 * rots[a].0.transpose();
            let rg = rots[b].1 * rots[a].1.transpose();
            let d = re * rg.transpose();
            rot_sum += ((d.trace() - 1.0) * 0.5)
                .clamp(-1.0, 1.0)
                .acos()
                .to_degrees();
            npairs += 1;
        }
    }
    // Absolute rotation errors after the best common rotation (chordal mean of R_gtᵀ·R_est).
    let q = rots
        .iter()
        .fold(nalgebra::Matrix3::zeros(), |acc, (re, rg)| {
            acc + rg.transpose() * re
        });
    let svd = q.svd(true, true);
    let q = svd.u.unwrap() * svd.v_t.unwrap();
    let mut k = 0;
    for (vi, v) in r.views.iter().enumerate() {
        if v.pose.is_some() {
            let d = rots[k].1.transpose() * rots[k].0 * q.transpose();
            eprintln!(
                "view {vi:2}: centre error / extent {:.3}, rotation error {:.2}°",
                dist(&sim.act(&est[k]), &g[k]) / extent,
                ((d.trace() - 1.0) * 0.5)
                    .clamp(-1.0, 1.0)
                    .acos()
                    .to_degrees()
            );
            k += 1;
        }
    }
    // The rotation between the first and the last registered camera, estimated and true: a
    // path whose rotation errors grow from the middle outwards turns too much or too little.
    let angle = |m: nalgebra::Matrix3<f64>| ((m.trace() - 1.0) * 0.5).clamp(-1.0, 1.0).acos();
    let (first, last) = (&rots[0], &rots[rots.len() - 1]);
    eprintln!(
        "first to last camera: rotation {:.2}° estimated, {:.2}° true",
        angle(last.0 * first.0.transpose()).to_degrees(),
        angle(last.1 * first.1.transpose()).to_degrees()
    );
    println!(
        "{}: registered {}/{}, points {}, rmse/extent {:.5} (rmse {:.4}, extent {:.3}), rel. rot err {:.2}°, focal {:.1} (gt {:.1}, err {:+.1} %), reproj {:.2}px, {:.1}s (features {:.1}s), blur est {:.1}px, working size {} (final {}), unregistered {:?}",
        dir.display(),
        r.stats.registered,
        r.stats.total,
        r.stats.points,
        mse.sqrt() / extent,
        mse.sqrt(),
        extent,
        rot_sum / npairs.max(1) as f64,
        r.camera.focal,
        gt_focal,
        100.0 * (r.camera.focal / gt_focal - 1.0),
        r.stats.mean_reprojection_error,
        r.stats.seconds,
        r.stats.seconds_features,
        r.stats.blur_px_estimate,
        r.stats.working_size,
        r.stats.final_size,
        r.stats.unregistered
    );
}
