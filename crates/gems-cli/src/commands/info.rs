//! `gems info`: describe what a scene folder holds (layout, views and split, resolution,
//! intrinsics, poses, ground truth, SfM model, events, where the SfM focal comes from). Read-only:
//! it never writes into the scene. `--check` validates everything in full (every image decoded,
//! every file read) and prints one line per problem; the exit status is non-zero if there is any.

use std::path::PathBuf;

use anyhow::Context;
use gems_data::{Layout, OpenOptions, open_scene, scene_info};

/// Arguments of `gems info`.
#[derive(clap::Args)]
pub struct Args {
    /// Scene folder.
    pub scene: PathBuf,
    #[command(flatten)]
    pub video: super::VideoArgs,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Describe the scene at this downscale factor: its `images_<f>/`, or copies in --cache-dir.
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
    /// Folder for downscaled copies the scene lacks (none by default: a missing `images_<f>/`
    /// is then an error; nothing is ever written into the scene).
    #[arg(long)]
    pub cache_dir: Option<PathBuf>,
    /// Unit of the scene's event and exposure times (s, ms, us, ns) when their values leave it
    /// open; detected otherwise.
    #[arg(long)]
    pub time_unit: Option<gems_events::TimeUnit>,
    /// Decode every image and read every file in full; print one line per problem and exit
    /// non-zero if there is any.
    #[arg(long)]
    pub check: bool,
    /// Hold-out interval overriding the scene's `hold=<n>` marker (n < 1: no hold-out).
    #[arg(long)]
    pub hold: Option<i64>,
    /// Force the layout: gems, blender, llff, nerfstudio or folder (default: detect).
    #[arg(long)]
    pub layout: Option<Layout>,
    /// Do not read the event stream (only report which event files exist).
    #[arg(long)]
    pub no_events: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if gems_data::video::is_video(&args.scene) {
        // A video is described, not decoded: nothing is written anywhere.
        let info = args.video.ffmpeg().probe(&args.scene)?;
        let rate = args
            .video
            .fps
            .unwrap_or_else(|| gems_data::video::default_rate(&info));
        println!("video      {}", args.scene.display());
        println!(
            "stream     {}x{}, {:.2} fps, {:.2} s",
            info.width, info.height, info.fps, info.duration_s
        );
        println!(
            "frames     about {} at {rate:.2} per second (ordered; `gems train` extracts them \
             into <output>/frames)",
            (info.duration_s * rate).round() as u64
        );
        return Ok(());
    }
    let opts = OpenOptions {
        downscale: args.downscale,
        hold: args.hold,
        layout: args.layout,
        cache_dir: args.cache_dir.clone(),
        time_unit: args.time_unit,
    };
    let scene = open_scene(&args.scene, &opts)
        .with_context(|| format!("cannot open scene {}", args.scene.display()))?;
    let info = scene_info(&scene, !args.no_events)?;
    if args.json {
        println!("{}", info.to_json_pretty());
    } else {
        print!("{info}");
    }
    if args.check {
        let problems = gems_data::check::check_scene(&scene);
        for p in &problems {
            println!("problem    {p}");
        }
        if !problems.is_empty() {
            anyhow::bail!(
                "{} problem(s) found in {}",
                problems.len(),
                args.scene.display()
            );
        }
        println!("check      ok: every image decoded, every file read in full");
    }
    Ok(())
}
