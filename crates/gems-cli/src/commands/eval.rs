//! `gems eval`: re-run the evaluation protocol on a trained output folder (deblurring at the
//! trajectory midpoints, novel views with and without test-time pose refinement, APE) and
//! rewrite `metrics.json`, `trajectories/`, `renders/` and `report.html` there. The work is in `gems-eval`.

use std::path::PathBuf;

use anyhow::Context;
use gems_eval::{PoseRefineConfig, write_metrics_json, write_report, write_trajectories};

/// `--held-out-frame`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum FrameArg {
    Initial,
    Trained,
}

/// Arguments of `gems eval`.
#[derive(clap::Args)]
pub struct Args {
    /// Output folder of `gems train` (holds model.json + model.safetensors).
    pub output: PathBuf,
    /// The scene folder it was trained on (ground-truth images and held-out views).
    #[arg(long)]
    pub scene: PathBuf,
    /// LPIPS weights: a safetensors file in the lpips layout, or the two official PyTorch files
    /// (lpips `alex.pth` and torchvision `alexnet-owt-7be5be79.pth`). Without them LPIPS is
    /// reported as absent.
    #[arg(long, num_args = 1..)]
    pub lpips: Vec<PathBuf>,
    /// Hold-out interval overriding the scene's `hold=<n>` marker (default: the one training
    /// used, else the protocol's).
    #[arg(long)]
    pub hold: Option<i64>,
    /// Which of the result's frames held-out views are carried into: `initial` (the frame the
    /// Gaussians started in; the dataset's poses exactly when training started from them) or
    /// `trained` (the trained cameras' frame).
    #[arg(long, value_enum, default_value = "initial")]
    pub held_out_frame: FrameArg,
    /// The published protocol to report the figures under (default: the one training ran
    /// with); see `gems train --help`.
    #[arg(long, value_enum)]
    pub protocol: Option<gems_pipeline::Protocol>,
    /// Folder for downscaled copies the scene lacks (default: `<output>/cache`, as in training).
    #[arg(long)]
    pub cache_dir: Option<PathBuf>,
    /// Unit of the scene's event and exposure times (s, ms, us, ns), as given to training.
    #[arg(long)]
    pub time_unit: Option<gems_events::TimeUnit>,
    /// Adam steps of the test-time pose refinement of each held-out view.
    #[arg(long, default_value_t = 100)]
    pub refine_steps: usize,
    /// Learning rate of the test-time pose refinement.
    #[arg(long, default_value_t = 1e-3)]
    pub refine_lr: f64,
    /// Rows of the blurry | ours | ground-truth grid in the report.
    #[arg(long, default_value_t = 4)]
    pub grid_rows: usize,
    /// Where the splatting runs: `auto` takes a hardware GPU when there is one and the CPU
    /// otherwise; `gpu` any GPU adapter (software ones such as Mesa lavapipe included), an error
    /// when there is none; `cpu` the CPU.
    #[arg(long, default_value = "auto")]
    pub device: gems_gpu::DeviceChoice,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let started = std::time::Instant::now();
    let mut output = gems_train::TrainOutput::load(&args.output).with_context(|| {
        format!(
            "cannot read the trained result in {}",
            args.output.display()
        )
    })?;
    crate::console::log_to(&args.output)?;
    let cache = args
        .cache_dir
        .clone()
        .unwrap_or_else(|| args.output.join("cache"));
    let protocol_hold = args.protocol.and_then(|p| p.settings(&args.scene).hold);
    let recorded_hold = output.run.as_ref().and_then(|r| r.hold);
    if let (Some(p), Some(run)) = (args.protocol, output.run.as_mut()) {
        run.protocol = Some(p.name().to_owned());
    }
    let opts = gems_data::OpenOptions {
        hold: args.hold.or(protocol_hold).or(recorded_hold),
        cache_dir: Some(cache),
        time_unit: args.time_unit,
        ..Default::default()
    };
    let scene = gems_eval::open_scene_for(&output, &args.scene, &opts)?;
    let frame = match args.held_out_frame {
        FrameArg::Initial => gems_eval::HeldOutFrame::Initial,
        FrameArg::Trained => gems_eval::HeldOutFrame::Trained,
    };
    let mut data = gems_eval::eval_data_from_scene_in(&output, &scene, frame)?;
    gems_pipeline::attach_edi(&mut data, &output, &args.output)?;
    let lpips = if args.lpips.is_empty() {
        tracing::warn!("no --lpips weights given: LPIPS will be reported as absent");
        None
    } else {
        Some(gems_metrics::Lpips::load(&args.lpips)?)
    };
    let refine = PoseRefineConfig {
        steps: args.refine_steps,
        lr: args.refine_lr,
        ..Default::default()
    };
    tracing::info!(
        deblur = data.train_gt.iter().flatten().count(),
        held_out = data.held_out.len(),
        "evaluating"
    );
    let bar = gems_pipeline::progress::bar(
        true,
        gems_eval::evaluation_units(&data),
        "evaluating {wide_bar} {pos}/{len} views  {msg}  ETA {eta}",
    );
    let mut engine = super::open_engine(args.device)?;
    let eval = gems_eval::evaluate_output_on(
        &mut engine,
        &output,
        &data,
        &refine,
        lpips.as_ref(),
        &mut |name| {
            bar.set_message(name.to_owned());
            bar.inc(1);
        },
    )?;
    bar.finish_and_clear();
    let mut eval = eval;
    eval.metrics.eval_seconds = Some(started.elapsed().as_secs_f64());
    write_metrics_json(&args.output.join("metrics.json"), &eval.metrics)?;
    write_trajectories(&args.output, &output)?;
    gems_eval::write_renders_on(&mut engine, &args.output, &output, &data, &eval)?;
    let mut input = gems_eval::report_input(&output, &data, &eval, args.grid_rows);
    input.registration = gems_eval::report::read_registration(&args.output);
    let report = write_report(&args.output, &input)?;
    super::print_splits(&eval.metrics);
    println!("report: {}", report.display());
    Ok(())
}
