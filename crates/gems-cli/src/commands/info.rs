//! `gems info`: describe what a scene folder holds (layout, views and split, resolution,
//! intrinsics, poses, ground truth, SfM model, events). Read-only: it never writes into the scene.

use std::path::PathBuf;

use anyhow::Context;
use gems_data::{Layout, OpenOptions, open_scene, scene_info};

/// Arguments of `gems info`.
#[derive(clap::Args)]
pub struct Args {
    /// Scene folder.
    pub scene: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Describe the `images_<f>/` copy at this downscale factor (it must already exist).
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
    /// Hold-out interval overriding the scene's `hold=<n>` marker (n < 1: no hold-out).
    #[arg(long)]
    pub hold: Option<i64>,
    /// Force the layout: gems, llff or nerfstudio (default: detect).
    #[arg(long)]
    pub layout: Option<Layout>,
    /// Do not read the event stream (only report which event files exist).
    #[arg(long)]
    pub no_events: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let opts = OpenOptions {
        downscale: args.downscale,
        hold: args.hold,
        layout: args.layout,
        create_downscaled: false,
    };
    let scene = open_scene(&args.scene, &opts)
        .with_context(|| format!("cannot open scene {}", args.scene.display()))?;
    let info = scene_info(&scene, !args.no_events)?;
    if args.json {
        println!("{}", info.to_json_pretty());
    } else {
        print!("{info}");
    }
    Ok(())
}
