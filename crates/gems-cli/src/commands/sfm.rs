//! `gems sfm`: blur-robust structure from motion on a scene's images (gems-init does the work).

use anyhow::Context;
use gems_init::sfm::{self, CaptureOrder, ColmapCliOptions, SfmOptions};
use std::path::PathBuf;

/// `gems sfm --capture-order`.
#[derive(Clone, Copy, clap::ValueEnum)]
pub enum CaptureOrderArg {
    /// Decide from the images.
    Detect,
    /// The images are in capture order.
    Ordered,
    /// No order.
    Unordered,
}

/// Arguments of `gems sfm`.
#[derive(clap::Args)]
pub struct Args {
    /// Scene folder (with an `images/` folder), a folder of images, or a video (its frames go
    /// to `<output>/frames`).
    pub scene: PathBuf,
    #[command(flatten)]
    pub video: super::VideoArgs,
    /// Output folder: `sparse/0` (COLMAP binary), `sfm_report.json`, `sfm_topview.png`.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Focal length in pixels when known (held fixed). Default: from the photos' EXIF when they
    /// carry it, else estimated.
    #[arg(long)]
    pub focal: Option<f64>,
    /// Refine the given or EXIF focal in the final bundle adjustment under a Gaussian prior of
    /// this relative width instead of holding it fixed. Default: 0.02 for a focal read from EXIF
    /// (`gems_init::sfm::EXIF_FOCAL_PRIOR`), held for one given with `--focal` (0 holds either).
    #[arg(long)]
    pub focal_prior: Option<f64>,
    /// The photos' motion blur in pixels when it is known (0: sharp), in place of the estimate
    /// from their edges, which soft but unblurred images (renders, out-of-focus shots) read as
    /// blur: it sets the working level, coarse to fine and the matching patches.
    #[arg(long)]
    pub blur_px: Option<f64>,
    /// Long side (px) of the pyramid levels to try (default: 384,256,192,128,96,64), nearest first to
    /// the level where the estimated motion blur is about 10 px.
    #[arg(long, value_delimiter = ',')]
    pub working_size: Option<Vec<u32>>,
    /// Keypoints per image.
    #[arg(long)]
    pub max_features: Option<usize>,
    /// Points per view tracked into its neighbours (its keypoints first, then grid points);
    /// each becomes at most one sparse point, and tracking time grows with it (default: 300).
    #[arg(long)]
    pub max_query_points: Option<usize>,
    /// Spacing of the grid of extra tracking points, as a fraction of the working level's long
    /// side (default: 0.04; 0 tracks keypoints only).
    #[arg(long)]
    pub grid_spacing: Option<f32>,
    /// Whether the images' order (file names, or a video's frames) is their capture order. In
    /// capture order the bundle adjustment holds the camera path smooth (a weak, robust prior
    /// on consecutive cameras). `detect` decides from the images: ordered when almost every
    /// image looks most like the next. Off by default: on generated scenes it did not help on
    /// average (crates/gems-init/BENCHMARKS.md).
    #[arg(long, value_enum, default_value_t = CaptureOrderArg::Unordered)]
    pub capture_order: CaptureOrderArg,
    /// Coarse to fine: re-measure the model at the finest level where the estimated blur is at
    /// most this many pixels (default: 12; 0 keeps the working level's model).
    #[arg(long)]
    pub refine_max_blur: Option<f64>,
    /// With the focal known (--focal or EXIF): grow a model from each of this many initial
    /// pairs (the best by matches and parallax) and keep the best pair's unless another
    /// explains the tracks clearly better (default: 3; 1 grows one model). Under heavy blur the
    /// best pair alone can lock the model into a wrong solution.
    #[arg(long)]
    pub initial_pairs: Option<usize>,
    /// Leave this fraction of the points, those the model fits worst, out of a last bundle
    /// adjustment of the cameras, then fit them to the new cameras (default: 0.4; 0 turns it
    /// off). Only photos whose estimated blur is at most 10 % of their long side: on nearly
    /// sharp photos the worst-fitting points are biased, not noisy; under heavier blur every
    /// track is.
    #[arg(long)]
    pub trim_fraction: Option<f64>,
    /// Re-measure each match with an affine map of its window, correcting the foreshortening
    /// that the model's predicted surface warp gets wrong, where the estimated blur at the
    /// measuring level is at most this many pixels (default: 10; 0 turns it off). On nearly
    /// sharp photos the cameras come out about 40 % more precise and an estimated focal about
    /// twice as close; under more smear the map also fits the smear.
    #[arg(long)]
    pub affine_max_blur: Option<f64>,
    /// RANSAC seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Run a user-installed COLMAP (feature extractor, exhaustive matcher, mapper) instead and
    /// import its largest model into `<out>/sparse/0`.
    #[arg(long)]
    pub colmap_cli: bool,
    /// The COLMAP executable for --colmap-cli.
    #[arg(long, default_value = "colmap")]
    pub colmap_binary: PathBuf,
}

pub fn run(mut args: Args) -> anyhow::Result<()> {
    crate::console::log_to(&args.output)?;
    args.scene = args.video.scene(&args.scene, &args.output)?;
    let from_exif = args.focal.is_none();
    let focal = args.focal.or_else(|| {
        gems_data::exif::folder_focal(&args.scene).map(|f| {
            println!(
                "focal {:.1} px from {} ({})",
                f.focal_px,
                f.source,
                f.image.display()
            );
            f.focal_px
        })
    });
    if args.colmap_cli {
        let img_dir = gems_fs::image_folder(&args.scene);
        let opts = ColmapCliOptions {
            binary: args.colmap_binary.clone(),
            focal_px: focal,
            use_gpu: false,
        };
        let (model, dir) = sfm::run_colmap_cli(&img_dir, &args.output.join("colmap_work"), &opts)?;
        gems_data::colmap::write_model(
            &args.output.join("sparse/0"),
            &model,
            gems_data::colmap::ModelFormat::Binary,
        )
        .context("writing the imported COLMAP model")?;
        println!(
            "COLMAP registered {} images, {} points (model {}); written to {}",
            model.images.len(),
            model.points.len(),
            dir.display(),
            args.output.join("sparse/0").display()
        );
        return Ok(());
    }
    let images = sfm::load_images(&args.scene)?;
    let mut opts = SfmOptions {
        focal_px: focal,
        focal_prior: args
            .focal_prior
            .or((from_exif && focal.is_some()).then_some(sfm::EXIF_FOCAL_PRIOR))
            .filter(|&w| w != 0.0),
        capture_order: match args.capture_order {
            CaptureOrderArg::Detect => CaptureOrder::Detect,
            CaptureOrderArg::Ordered => CaptureOrder::Ordered,
            CaptureOrderArg::Unordered => CaptureOrder::Unordered,
        },
        blur_px: args.blur_px,
        seed: args.seed,
        ..SfmOptions::default()
    };
    if let Some(ws) = args.working_size {
        opts.working_sizes = ws;
    }
    if let Some(m) = args.max_features {
        opts.max_features = m;
    }
    if let Some(q) = args.max_query_points {
        opts.max_query_points = q;
    }
    if let Some(g) = args.grid_spacing {
        opts.grid_spacing_frac = g;
    }
    if let Some(n) = args.initial_pairs {
        opts.initial_pairs = n;
    }
    if let Some(f) = args.trim_fraction {
        opts.trim_fraction = f;
    }
    if let Some(b) = args.refine_max_blur {
        opts.refine_max_blur_px = b;
    }
    if let Some(b) = args.affine_max_blur {
        opts.refine_affine_max_blur_px = b;
    }
    tracing::info!(images = images.len(), "running structure from motion");
    let result = sfm::run_sfm(&images, &opts)?;
    sfm::write_outputs(&result, &args.output)?;
    let s = &result.stats;
    println!(
        "registered {}/{} views, {} points, mean track length {:.2}, reprojection error {:.2} px, focal {:.1} px, estimated blur {:.0} px (working size {}, refined at {}), {}, {:.1} s",
        s.registered,
        s.total,
        s.points,
        s.mean_track_length,
        s.mean_reprojection_error,
        s.focal,
        s.blur_px_estimate,
        s.working_size,
        s.final_size,
        if s.capture_order {
            "in capture order (smooth path prior)"
        } else {
            "no capture order"
        },
        s.seconds
    );
    println!("photo                        registered  blur px  points  error px");
    for v in &s.views {
        println!(
            "{:<28} {:<11} {:>7.1} {:>7} {:>9}",
            v.name,
            if v.registered { "yes" } else { "no" },
            v.blur_px,
            v.points,
            v.reprojection_error_px
                .map_or("—".to_owned(), |e| format!("{e:.2}"))
        );
    }
    for line in &s.advice {
        println!("{line}");
    }
    println!("written to {}", args.output.display());
    Ok(())
}
