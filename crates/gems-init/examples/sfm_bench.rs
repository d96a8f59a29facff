//! Side-by-side benchmark of the built-in SfM and COLMAP on `gems synth --blur-levels` scenes.
//! Not part of CI; run via `crates/gems-init/scripts/bench_sfm_vs_colmap.sh`.
//!
//! Usage: sfm_bench <work_dir> <seed>... [--no-colmap] [--width W --height H --blur PX]
//! Prints one markdown row per (seed, level, method) and a JSON line per result.

use gems_init::sfm::{ColmapCliOptions, SfmOptions, load_images, run_colmap_cli, run_sfm};
use std::path::PathBuf;

struct Outcome {
    registered: usize,
    points: usize,
    rmse_frac: Option<f64>,
    seconds: f64,
}

/// Translation RMSE after Sim(3) alignment of camera centres, over the path extent.
fn rmse_fraction(est: &[[f64; 3]], gt: &[[f64; 3]], gt_all: &[[f64; 3]]) -> Option<f64> {
    if est.len() < 3 {
        return None;
    }
    let sim = gems_math::align::umeyama(est, gt, true).ok()?;
    let mse = est
        .iter()
        .zip(gt)
        .map(|(s, d)| {
            let a = sim.act(s);
            (0..3).map(|k| (a[k] - d[k]).powi(2)).sum::<f64>()
        })
        .sum::<f64>()
        / est.len() as f64;
    let mut extent: f64 = 0.0;
    for a in gt_all {
        for b in gt_all {
            extent = extent.max((0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt());
        }
    }
    Some(mse.sqrt() / extent)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let work = PathBuf::from(&args[0]);
    let mut seeds = Vec::new();
    let mut colmap = true;
    let mut cfg = gems_synth::SynthConfig::small();
    cfg.views = 20;
    let mut it = args[1..].iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--no-colmap" => colmap = false,
            "--width" => cfg.width = it.next().unwrap().parse().unwrap(),
            "--height" => cfg.height = it.next().unwrap().parse().unwrap(),
            "--blur" => cfg.blur_px = it.next().unwrap().parse().unwrap(),
            s => seeds.push(s.parse::<u64>().unwrap()),
        }
    }
    println!(
        "| seed | level | blur px | method | registered | points | trans. RMSE / path extent | seconds |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for seed in seeds {
        cfg.seed = seed;
        let dir = work.join(format!("seed{seed}"));
        let blur_file = work.join(format!("seed{seed}_blur.txt"));
        if !dir.join("blur_11").exists() {
            let sums = gems_synth::generate_blur_levels(&cfg, &dir, &mut |_, _| {}).unwrap();
            let means: Vec<String> = sums
                .iter()
                .map(|s| {
                    format!(
                        "{}",
                        s.blur_px.iter().sum::<f64>() / s.blur_px.len().max(1) as f64
                    )
                })
                .collect();
            std::fs::write(&blur_file, means.join("\n")).unwrap();
        }
        let blurs: Vec<f64> = std::fs::read_to_string(&blur_file)
            .map(|s| s.lines().filter_map(|l| l.parse().ok()).collect())
            .unwrap_or_default();
        for (li, level) in [1, 3, 5, 7, 9, 11].into_iter().enumerate() {
            let ld = dir.join(format!("blur_{level:02}"));
            let rows = gems_data::llff::read_poses_bounds(&ld.join("poses_bounds.npy")).unwrap();
            let images = load_images(&ld).unwrap();
            let gt: Vec<[f64; 3]> = rows.iter().map(|r| r.pose().center()).collect();
            let blur = blurs.get(li).copied().unwrap_or(f64::NAN);
            // gems sfm, focal estimated and focal from the scene metadata (hwf of poses_bounds).
            let mut results = Vec::new();
            for (label, focal) in [
                ("gems sfm (focal estimated)", None),
                ("gems sfm (focal from metadata)", Some(rows[0].focal())),
            ] {
                let t = std::time::Instant::now();
                let opts = SfmOptions {
                    focal_px: focal,
                    ..SfmOptions::default()
                };
                let ours = match run_sfm(&images, &opts) {
                    Ok(r) => {
                        let (est, g): (Vec<[f64; 3]>, Vec<[f64; 3]>) = r
                            .views
                            .iter()
                            .zip(&gt)
                            .filter_map(|(v, g)| {
                                v.pose.map(|p| -> ([f64; 3], [f64; 3]) {
                                    (gems_math::camera_center_from_w2c(&p).into(), *g)
                                })
                            })
                            .unzip();
                        Outcome {
                            registered: r.stats.registered,
                            points: r.stats.points,
                            rmse_frac: rmse_fraction(&est, &g, &gt),
                            seconds: t.elapsed().as_secs_f64(),
                        }
                    }
                    Err(e) => {
                        eprintln!("gems sfm failed on {}: {e}", ld.display());
                        Outcome {
                            registered: 0,
                            points: 0,
                            rmse_frac: None,
                            seconds: t.elapsed().as_secs_f64(),
                        }
                    }
                };
                results.push((label, ours));
            }
            if colmap {
                let t = std::time::Instant::now();
                let cw = ld.join("colmap_run");
                let _ = std::fs::remove_dir_all(&cw);
                let out =
                    match run_colmap_cli(&ld.join("images"), &cw, &ColmapCliOptions::default()) {
                        Ok((m, _)) => {
                            let (est, g): (Vec<[f64; 3]>, Vec<[f64; 3]>) = m
                                .images
                                .iter()
                                .filter_map(|im| {
                                    let k = images.iter().position(|x| x.name == im.name)?;
                                    Some((im.pose().center(), gt[k]))
                                })
                                .unzip();
                            Outcome {
                                registered: m.images.len(),
                                points: m.points.len(),
                                rmse_frac: rmse_fraction(&est, &g, &gt),
                                seconds: t.elapsed().as_secs_f64(),
                            }
                        }
                        Err(e) => {
                            eprintln!("colmap failed on {}: {e}", ld.display());
                            Outcome {
                                registered: 0,
                                points: 0,
                                rmse_frac: None,
                                seconds: t.elapsed().as_secs_f64(),
                            }
                        }
                    };
                results.push(("COLMAP 3.8", out));
            }
            for (name, o) in results {
                let rm = o.rmse_frac.map_or("–".to_owned(), |v| format!("{v:.4}"));
                println!(
                    "| {seed} | {level} | {blur:.1} | {name} | {}/{} | {} | {rm} | {:.1} |",
                    o.registered,
                    images.len(),
                    o.points,
                    o.seconds
                );
            }
        }
    }
}
