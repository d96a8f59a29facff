//! `gems bench-quality`: how far GeMS is from what the same engine reaches on sharp inputs.
//!
//! On `gems synth` scenes of several seeds, at one schedule, four rows per seed:
//! 1. the blurry input against the sharp ground truth (where a user starts);
//! 2. GeMS initialised by the built-in SfM on the blurry images;
//! 3. GeMS initialised by the built-in SfM run on the **sharp** mid-exposure frames (what the
//!    GeMS paper's comparators start from: COLMAP on sharp frames), trained on the blurry
//!    images: how well training keeps accurate cameras accurate (APE before → after);
//! 4. GeMS initialised by the ground-truth poses;
//! 5. the sharp ceiling: the same engine and schedule with n = 1 on the sharp mid-exposure frames,
//!    SfM on them, in one pass: the SfM again on a first pass's renders
//!    (`init.sfm_rerun_fraction`) is there to undo what blur does to the SfM, and on sharp frames
//!    it only shortens the last training (seed 7 at 3000 steps: 33.47 dB refined deblurring
//!    with it, 34.37 dB in one pass; novel views 30.56 / 30.51 dB).
//!
//! `--rows` trains only some of 2–5 (e.g. the ceiling of a seed whose other rows were already
//! run by `gems train`); the blurry-input row comes with either blurry run.
//!
//! Columns: deblurring at the trajectory midpoint and after the GeMS authors' 100-step pose
//! refinement, novel views refined and at their initial pose, APE, and the wall time of the run
//! (the SfM rows' initialisation included, training, evaluation). Writes `quality.md` (the table) and `quality.json` into the output folder;
//! every run keeps its own folder (metrics, report) beside them.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use gems_eval::MetricsReport;
use gems_pipeline::Init;
use gems_synth::SynthConfig;
use gems_train::TrainConfig;
use serde::Serialize;

/// Arguments of `gems bench-quality`.
#[derive(clap::Args)]
pub struct Args {
    /// Output folder (must not exist or be empty).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Scene seeds, one scene each.
    #[arg(long, value_delimiter = ',', default_values_t = [1u64, 2])]
    pub seeds: Vec<u64>,
    /// Scene preset (sizes below override it).
    #[arg(long, value_enum, default_value = "small")]
    pub preset: super::synth::PresetArg,
    /// Image width in pixels.
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height in pixels.
    #[arg(long)]
    pub height: Option<u32>,
    /// Training steps of every run.
    #[arg(long, default_value_t = 1500)]
    pub steps: usize,
    /// TOML configuration of every run (missing fields take the defaults); the ceiling run
    /// takes it with `num_virtual_views = 1` and `init.sfm_rerun_fraction = 0`.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Where the splatting runs (see `gems train --device`).
    #[arg(long, default_value = "auto")]
    pub device: gems_gpu::DeviceChoice,
    /// Which training rows to run, in the table's order whatever the order given here.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [RowKind::Sfm, RowKind::SharpSfm, RowKind::Gt, RowKind::Ceiling])]
    pub rows: Vec<RowKind>,
}

/// A training row of the table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RowKind {
    /// GeMS from the built-in SfM on the blurry images.
    Sfm,
    /// GeMS on the blurry images from the built-in SfM run on the sharp frames.
    SharpSfm,
    /// GeMS from the ground-truth poses.
    Gt,
    /// The sharp ceiling (n = 1 on the sharp frames, SfM on them).
    Ceiling,
}

/// One row of the table.
#[derive(Debug, Serialize)]
struct Row {
    seed: u64,
    run: &'static str,
    deblur_midpoint: Option<f64>,
    deblur_refined: Option<f64>,
    nvs_refined: Option<f64>,
    nvs_initial: Option<f64>,
    ape_rmse: Option<f64>,
    /// APE of the initial poses the run trained from.
    ape_init_rmse: Option<f64>,
    /// Relative rotation error RMSE (degrees) of the trained midpoints and of the initial poses.
    rotation_error_deg: Option<f64>,
    rotation_error_init_deg: Option<f64>,
    seconds: Option<f64>,
    /// Why the run has no figures (e.g. the SfM failed).
    failure: Option<String>,
}

impl Row {
    fn from_metrics(seed: u64, run: &'static str, m: &MetricsReport, seconds: f64) -> Self {
        Row {
            seed,
            run,
            deblur_midpoint: m.deblur.as_ref().map(|s| s.psnr),
            deblur_refined: m.deblur_refined.as_ref().map(|s| s.psnr),
            nvs_refined: m.nvs.as_ref().map(|s| s.psnr),
            nvs_initial: m.nvs_no_pose_opt.as_ref().map(|s| s.psnr),
            ape_rmse: m.ape.as_ref().map(|a| a.rmse),
            ape_init_rmse: m.ape_init.as_ref().map(|a| a.rmse),
            rotation_error_deg: m.rotation_error.as_ref().map(|r| r.rmse_deg),
            rotation_error_init_deg: m.rotation_error_init.as_ref().map(|r| r.rmse_deg),
            seconds: Some(seconds),
            failure: None,
        }
    }

    fn failed(seed: u64, run: &'static str, why: String) -> Self {
        Row {
            seed,
            run,
            deblur_midpoint: None,
            deblur_refined: None,
            nvs_refined: None,
            nvs_initial: None,
            ape_rmse: None,
            ape_init_rmse: None,
            rotation_error_deg: None,
            rotation_error_init_deg: None,
            seconds: None,
            failure: Some(why),
        }
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let out = &args.output;
    if out.exists() && std::fs::read_dir(out)?.next().is_some() {
        anyhow::bail!("{} exists and is not empty", out.display());
    }
    crate::console::log_to(out)?;
    let base = match &args.config {
        Some(p) => TrainConfig::from_toml_file(p)?,
        None => TrainConfig::default(),
    };
    let mut rows = Vec::new();
    for &seed in &args.seeds {
        let dir = out.join(format!("seed{seed}"));
        let mut synth = SynthConfig::preset(args.preset.preset());
        synth.seed = seed;
        synth.width = args.width.unwrap_or(synth.width);
        synth.height = args.height.unwrap_or(synth.height);
        let scene = dir.join("scene");
        let summary = gems_synth::generate(&synth, &scene)?;
        let sharp = dir.join("sharp");
        sharp_scene(&scene, &sharp)?;
        let cfg = TrainConfig {
            steps: args.steps,
            seed,
            ..base.clone()
        };
        let focal = Some(summary.intrinsics.fx);
        // Every row runs the whole pipeline a user's `gems train --init sfm|gt` runs (for the
        // SfM, a first pass and the SfM again on its renders when the configuration asks for
        // it; from ground truth, straight paths first).
        let row = |name: &'static str,
                   init: gems_pipeline::InitRequest,
                   scene: &Path,
                   out: &Path,
                   cfg: &TrainConfig| {
            tracing::info!(seed, run = name, "bench-quality run");
            let start = Instant::now();
            let run = gems_pipeline::train_scene(gems_pipeline::TrainRequest {
                scene: scene.to_path_buf(),
                output: out.to_path_buf(),
                init: gems_pipeline::InitRequest {
                    focal_px: focal,
                    ..init
                },
                cfg: cfg.clone(),
                open: gems_data::OpenOptions::default(),
                resume: false,
                evaluate: true,
                lpips: Vec::new(),
                engine: super::open_engine(args.device)?,
                progress: true,
                protocol: None,
            });
            match run {
                Ok(_) => {
                    let seconds = start.elapsed().as_secs_f64();
                    Ok(Row::from_metrics(seed, name, &read_metrics(out)?, seconds))
                }
                Err(gems_pipeline::PipelineError::Sfm(e)) => {
                    Ok(Row::failed(seed, name, format!("SfM failed: {e:#}")))
                }
                Err(e) => Err(anyhow::Error::from(e)),
            }
        };
        let wants = |k: RowKind| args.rows.contains(&k);
        let gems_sfm = wants(RowKind::Sfm)
            .then(|| {
                row(
                    "GeMS, built-in SfM",
                    gems_pipeline::InitRequest::new(Init::Sfm),
                    &scene,
                    &dir.join("gems_sfm"),
                    &cfg,
                )
            })
            .transpose()?;
        const SHARP_SFM: &str = "GeMS, built-in SfM on the sharp frames";
        let gems_sharp_sfm = wants(RowKind::SharpSfm)
            .then(|| {
                match gems_pipeline::run_sfm(
                    &sharp,
                    &dir.join("sharp_sfm"),
                    seed,
                    focal,
                    None,
                    None,
                ) {
                    Ok(model) => row(
                        SHARP_SFM,
                        gems_pipeline::InitRequest {
                            colmap_model: Some(model),
                            ..gems_pipeline::InitRequest::new(Init::Colmap)
                        },
                        &scene,
                        &dir.join("gems_sharp_sfm"),
                        &cfg,
                    ),
                    Err(e) => Ok(Row::failed(seed, SHARP_SFM, format!("SfM failed: {e:#}"))),
                }
            })
            .transpose()?;
        let gems_gt = wants(RowKind::Gt)
            .then(|| {
                row(
                    "GeMS, ground-truth poses",
                    gems_pipeline::InitRequest::new(Init::Gt),
                    &scene,
                    &dir.join("gems_gt"),
                    &cfg,
                )
            })
            .transpose()?;
        // The blurry input is every blurry run's `input` figure: read it from whichever ran.
        let input = ["gems_sfm", "gems_sharp_sfm", "gems_gt"]
            .iter()
            .find_map(|run| read_metrics(&dir.join(run)).ok().and_then(|m| m.input));
        if let Some(input) = input {
            rows.push(Row {
                deblur_midpoint: Some(input.psnr),
                ..Row::failed(seed, "blurry input", String::new())
            });
        }
        rows.extend(gems_sfm);
        rows.extend(gems_sharp_sfm);
        rows.extend(gems_gt);
        if wants(RowKind::Ceiling) {
            let mut ceiling = TrainConfig {
                num_virtual_views: 1,
                ..cfg.clone()
            };
            ceiling.init.sfm_rerun_fraction = 0.0;
            rows.push(row(
                "sharp ceiling (n = 1, sharp frames, SfM)",
                gems_pipeline::InitRequest::new(Init::Sfm),
                &sharp,
                &dir.join("ceiling"),
                &ceiling,
            )?);
        }
    }
    for r in &mut rows {
        if r.failure.as_deref() == Some("") {
            r.failure = None;
        }
    }
    let table = markdown(&rows, &args);
    gems_fs::write_atomic(&out.join("quality.md"), table.as_bytes())?;
    let json = serde_json::to_string_pretty(&rows)?;
    gems_fs::write_atomic(&out.join("quality.json"), json.as_bytes())?;
    println!("{table}");
    println!("written to {}", out.join("quality.md").display());
    Ok(())
}

fn read_metrics(run: &Path) -> anyhow::Result<MetricsReport> {
    let path = run.join("metrics.json");
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))
}

/// A copy of a generated scene whose `images/` are its sharp mid-exposure frames (the input of
/// the sharp ceiling); events are left out (they belong to the blurry exposures).
fn sharp_scene(scene: &Path, sharp: &Path) -> anyhow::Result<()> {
    copy_dir(scene, sharp, &|rel: &Path| {
        !(rel.starts_with("images")
            || rel.starts_with("events.npz")
            || rel.starts_with("exposure_start_ts.txt")
            || rel.starts_with("exposure_end_ts.txt"))
            || rel.starts_with("images_test")
    })?;
    copy_dir(&scene.join("images_test"), &sharp.join("images"), &|_| true)
}

/// Copies the files under `from` whose path relative to it `keep` accepts.
fn copy_dir(from: &Path, to: &Path, keep: &dyn Fn(&Path) -> bool) -> anyhow::Result<()> {
    let mut stack = vec![from.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).with_context(|| format!("reading {}", d.display()))? {
            let p = e?.path();
            let rel = p.strip_prefix(from).unwrap_or(&p).to_path_buf();
            if !keep(&rel) {
                continue;
            }
            if p.is_dir() {
                stack.push(p);
            } else {
                let dst = to.join(&rel);
                if let Some(parent) = dst.parent() {
                    std::fs::create_dir_all(parent)
                        .with_context(|| format!("creating {}", parent.display()))?;
                }
                std::fs::copy(&p, &dst)
                    .with_context(|| format!("copying {} to {}", p.display(), dst.display()))?;
            }
        }
    }
    Ok(())
}

fn markdown(rows: &[Row], args: &Args) -> String {
    let f = |v: Option<f64>, unit: &str| v.map_or("—".to_owned(), |v| format!("{v:.2}{unit}"));
    let mut s = format!(
        "Schedule: {} steps; scenes: `gems synth --preset {}`{}, seeds {:?}.\n\n\
         | seed | run | deblur midpoint | deblur refined | novel views refined | novel views at initial pose | APE RMSE (initial → trained) | relative rotation error RMSE (initial → trained) | wall time |\n\
         |---|---|---|---|---|---|---|---|---|\n",
        args.steps,
        format!("{:?}", args.preset).to_lowercase(),
        match (args.width, args.height) {
            (Some(w), Some(h)) => format!(" at {w}×{h}"),
            _ => String::new(),
        },
        args.seeds
    );
    for r in rows {
        if let Some(why) = &r.failure {
            s.push_str(&format!("| {} | {} | {why} | | | | | | |\n", r.seed, r.run));
            continue;
        }
        s.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
            r.seed,
            r.run,
            f(r.deblur_midpoint, " dB"),
            f(r.deblur_refined, " dB"),
            f(r.nvs_refined, " dB"),
            f(r.nvs_initial, " dB"),
            match (r.ape_init_rmse, r.ape_rmse) {
                (Some(i), Some(t)) => format!("{i:.4} → {t:.4}"),
                (None, Some(t)) => format!("{t:.4}"),
                _ => "—".to_owned(),
            },
            match (r.rotation_error_init_deg, r.rotation_error_deg) {
                (Some(i), Some(t)) => format!("{i:.2}° → {t:.2}°"),
                (None, Some(t)) => format!("{t:.2}°"),
                _ => "—".to_owned(),
            },
            f(r.seconds, " s"),
        ));
    }
    s
}
