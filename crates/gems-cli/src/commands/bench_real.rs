//! `gems bench-real`: gems on a real (or any) scene folder beside the published tables.
//!
//! Rows, each a whole `gems train` run of this same executable in its own process (so that its
//! peak memory is its own), under one published protocol (`--protocol`, default
//! deblur-nerf-real):
//! 1. **naive**: plain 3DGS on the blurry photos (n = 1, the dataset's poses held fixed): the
//!    published "3DGS on blurry images" row, which shows the protocol is the same;
//! 2. **dataset**: gems from the dataset's poses (its COLMAP model, else its poses file): the
//!    published deblurring methods' setting;
//! 3. **sfm**: gems from the built-in SfM on the blurry photos alone;
//! 4. **events**: GeMS-E (EDI-deblurred images for the SfM), when the scene has events.
//!
//! Columns: held-out PSNR/SSIM/LPIPS at the dataset's pose (carried into the result's frame) and
//! after test-time pose refinement, how far training moved the cameras from the dataset's, wall
//! time (initialisation, training, evaluation) and peak memory. Writes `bench.md` and
//! `bench.json`; each run keeps its folder (`<output>/<row>/`: metrics, report). A row whose
//! folder already holds `metrics.json` is read, not run again; an interrupted row resumes from
//! its checkpoint.

use std::path::PathBuf;
use std::process::Command;

use anyhow::Context;
use gems_eval::MetricsReport;
use gems_pipeline::Protocol;
use gems_train::TrainConfig;
use serde::Serialize;

/// Arguments of `gems bench-real`.
#[derive(clap::Args)]
pub struct Args {
    /// Scene folder (any layout `gems info` reads); never written to.
    pub scene: PathBuf,
    /// Output folder (one subfolder per row).
    #[arg(short, long)]
    pub output: PathBuf,
    /// The published protocol every row follows (downscale, hold-out, steps).
    #[arg(long, value_enum, default_value = "deblur-nerf-real")]
    pub protocol: Protocol,
    /// Override the protocol's downscale factor (e.g. 8 for a CPU run of a ×4 protocol).
    #[arg(long)]
    pub downscale: Option<u32>,
    /// Override the protocol's steps.
    #[arg(long)]
    pub steps: Option<usize>,
    /// TOML configuration of every row (the naive row takes it with `num_virtual_views = 1` and
    /// `pose.optimize = false`).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Which rows to run, in the table's order whatever the order given here.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [RowKind::Naive, RowKind::Dataset, RowKind::Sfm, RowKind::Events])]
    pub rows: Vec<RowKind>,
    /// LPIPS weights for every row's evaluation (see `gems eval --help`).
    #[arg(long, num_args = 1..)]
    pub lpips: Vec<PathBuf>,
    /// Where the splatting runs (see `gems train --device`).
    #[arg(long, default_value = "auto")]
    pub device: String,
}

/// A row of the table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, clap::ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RowKind {
    /// Plain 3DGS on the blurry photos: n = 1, the dataset's poses fixed.
    Naive,
    /// gems from the dataset's poses.
    Dataset,
    /// gems from the built-in SfM on the blurry photos.
    Sfm,
    /// GeMS-E: the built-in SfM on the EDI-deblurred images (scenes with events only).
    Events,
}

impl RowKind {
    fn folder(self) -> &'static str {
        match self {
            RowKind::Naive => "naive",
            RowKind::Dataset => "dataset",
            RowKind::Sfm => "sfm",
            RowKind::Events => "events",
        }
    }

    fn title(self) -> &'static str {
        match self {
            RowKind::Naive => "naive 3DGS (n = 1, poses fixed), dataset's poses",
            RowKind::Dataset => "gems, dataset's poses",
            RowKind::Sfm => "gems, built-in SfM on the blurry photos",
            RowKind::Events => "GeMS-E, built-in SfM on EDI images",
        }
    }

    /// `gems train` arguments of this row's initialisation.
    fn init_args(self) -> &'static [&'static str] {
        match self {
            RowKind::Naive | RowKind::Dataset => &["--init", "colmap"],
            RowKind::Sfm => &["--init", "sfm"],
            RowKind::Events => &["--init", "sfm", "--events"],
        }
    }
}

/// Held-out PSNR / SSIM / LPIPS of one split.
#[derive(Debug, Serialize)]
struct Scores {
    psnr: f64,
    ssim: f64,
    lpips: Option<f64>,
}

/// One row of the table.
#[derive(Debug, Serialize)]
struct Row {
    row: RowKind,
    title: &'static str,
    /// What the run says it started from.
    init: Option<String>,
    at_dataset_pose: Option<Scores>,
    refined: Option<Scores>,
    /// How the held-out views were posed.
    held_out_pose: Option<String>,
    /// Trained cameras against the dataset's: centre RMSE (% of extent), rotation RMSE (°).
    camera_shift_pct: Option<f64>,
    camera_shift_deg: Option<f64>,
    /// Initialisation, training and evaluation, s.
    wall_seconds: Option<f64>,
    peak_memory_gib: Option<f64>,
    /// Why the row has no figures.
    failure: Option<String>,
}

impl Row {
    fn from_metrics(row: RowKind, m: &MetricsReport) -> Row {
        let scores = |s: &Option<gems_eval::SplitScores>| {
            s.as_ref().map(|s| Scores {
                psnr: s.psnr,
                ssim: s.ssim,
                lpips: s.lpips,
            })
        };
        Row {
            row,
            title: row.title(),
            init: m.run.as_ref().map(|r| r.init.clone()),
            at_dataset_pose: scores(&m.nvs_no_pose_opt),
            refined: scores(&m.nvs),
            held_out_pose: m.held_out_pose.as_ref().map(|p| p.describe()),
            camera_shift_pct: m.camera_shift.map(|c| c.centre_pct),
            camera_shift_deg: m.camera_shift.map(|c| c.rotation_deg),
            wall_seconds: m
                .run
                .as_ref()
                .map(|r| r.wall_seconds + m.eval_seconds.unwrap_or(0.0)),
            peak_memory_gib: m
                .run
                .as_ref()
                .and_then(|r| r.peak_memory_bytes)
                .map(|b| b as f64 / f64::from(1u32 << 30)),
            failure: None,
        }
    }

    fn failed(row: RowKind, why: String) -> Row {
        Row {
            row,
            title: row.title(),
            init: None,
            at_dataset_pose: None,
            refined: None,
            held_out_pose: None,
            camera_shift_pct: None,
            camera_shift_deg: None,
            wall_seconds: None,
            peak_memory_gib: None,
            failure: Some(why),
        }
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    args.device
        .parse::<gems_gpu::DeviceChoice>()
        .map_err(|e| anyhow::anyhow!("--device {}: {e}", args.device))?;
    let out = &args.output;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    crate::console::log_to(out)?;
    let scene = gems_data::open_scene(&args.scene, &gems_data::OpenOptions::default())
        .with_context(|| format!("opening {}", args.scene.display()))?;
    let base = match &args.config {
        Some(p) => TrainConfig::from_toml_file(p)?,
        None => TrainConfig::default(),
    };
    let exe = std::env::current_exe().context("locating the gems executable")?;
    let mut kinds = args.rows.clone();
    kinds.sort();
    kinds.dedup();
    let mut rows = Vec::new();
    for kind in kinds {
        if kind == RowKind::Events && scene.events.is_empty() {
            tracing::info!("the scene has no events: no GeMS-E row");
            continue;
        }
        let dir = out.join(kind.folder());
        let metrics = dir.join("metrics.json");
        if metrics.is_file() {
            tracing::info!(
                row = kind.folder(),
                "reading the finished run in {}",
                dir.display()
            );
        } else {
            let mut cfg = base.clone();
            if kind == RowKind::Naive {
                // 3DGS: one sharp render per photo, cameras as the dataset gives them.
                cfg.num_virtual_views = 1;
                cfg.pose.optimize = false;
            }
            // Only an interrupted row has anything to resume; a fresh one would be warned that
            // there is no checkpoint.
            let interrupted = std::fs::read_dir(&dir).is_ok_and(|mut d| d.next().is_some());
            std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
            let cfg_path = out.join(format!("{}.toml", kind.folder()));
            gems_fs::write_atomic(&cfg_path, cfg.to_toml().as_bytes())?;
            let mut cmd = Command::new(&exe);
            cmd.arg("train")
                .arg(&args.scene)
                .arg("--output")
                .arg(&dir)
                .args(["--protocol", args.protocol.name()])
                .arg("--config")
                .arg(&cfg_path)
                .args(kind.init_args())
                .args(["--device", &args.device]);
            if interrupted {
                cmd.arg("--resume");
            }
            if let Some(f) = args.downscale {
                cmd.args(["--downscale", &f.to_string()]);
            }
            if let Some(s) = args.steps {
                cmd.args(["--steps", &s.to_string()]);
            }
            if !args.lpips.is_empty() {
                cmd.arg("--lpips").args(&args.lpips);
            }
            tracing::info!(row = kind.folder(), "running {:?}", cmd);
            let status = cmd
                .status()
                .with_context(|| format!("running {}", exe.display()))?;
            if !status.success() {
                rows.push(Row::failed(
                    kind,
                    format!("gems train exited with {status} (its output is above)"),
                ));
                continue;
            }
        }
        rows.push(Row::from_metrics(
            kind,
            &gems_eval::read_metrics_json(&metrics)?,
        ));
    }
    let table = markdown(&rows, &args);
    gems_fs::write_atomic(&out.join("bench.md"), table.as_bytes())?;
    gems_fs::write_atomic(
        &out.join("bench.json"),
        serde_json::to_string_pretty(&rows)?.as_bytes(),
    )?;
    println!("{table}");
    println!("written to {}", out.join("bench.md").display());
    Ok(())
}

fn markdown(rows: &[Row], args: &Args) -> String {
    let s = args.protocol.settings(&args.scene);
    let scores = |s: &Option<Scores>| {
        s.as_ref().map_or("—".to_owned(), |s| {
            let lpips = s.lpips.map_or(String::new(), |l| format!(" / {l:.3}"));
            format!("{:.2} / {:.4}{lpips}", s.psnr, s.ssim)
        })
    };
    let opt = |v: Option<f64>, f: &dyn Fn(f64) -> String| v.map_or("—".to_owned(), f);
    let mut md = format!(
        "Scene `{}`, protocol {} at ×{}, {} steps{}.\n\n\
         | run | held-out at the dataset's pose (PSNR / SSIM{}) | held-out refined | cameras moved from the dataset's (centres, rotations) | wall time | peak memory |\n\
         |---|---|---|---|---|---|\n",
        args.scene.display(),
        args.protocol,
        args.downscale.unwrap_or(s.downscale),
        args.steps.unwrap_or(s.steps),
        if args.downscale.is_some_and(|f| f != s.downscale) || args.steps.is_some() {
            " (overridden; the protocol's own values are in `gems train --help`)"
        } else {
            ""
        },
        if args.lpips.is_empty() {
            ""
        } else {
            " / LPIPS"
        },
    );
    for r in rows {
        if let Some(why) = &r.failure {
            md.push_str(&format!("| {} | {why} | | | | |\n", r.title));
            continue;
        }
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} |\n",
            r.title,
            scores(&r.at_dataset_pose),
            scores(&r.refined),
            match (r.camera_shift_pct, r.camera_shift_deg) {
                (Some(c), Some(d)) => format!("{c:.2} %, {d:.2}°"),
                _ => "—".to_owned(),
            },
            opt(r.wall_seconds, &|v| format!("{:.1} min", v / 60.0)),
            opt(r.peak_memory_gib, &|v| format!("{v:.2} GiB")),
        ));
    }
    if let Some(p) = rows.iter().find_map(|r| r.held_out_pose.as_ref()) {
        md.push_str(&format!("\nHeld-out views posed at {p}.\n"));
    }
    md
}
