//! `gems render`: render a Gaussian-splat PLY to PNG from a camera given on the command line,
//! or, from a trained output folder, every training photo's exposure as a burst of sharp frames
//! (`--bursts`: PNG frames, an animated GIF and the mid-exposure image per photo).
//!
//! The camera is one image of a COLMAP model (`--colmap <sparse dir> --image <name>`: its
//! intrinsics and pose), or given on the command line: intrinsics from `--width/--height` and
//! `--fx/--fy/--cx/--cy` or `--fov`, pose as a position and a look-at target (`--cam-pos`,
//! `--look-at`, optional `--up`) or an explicit OpenCV world-to-camera rotation and translation
//! (`--rotation`, `--translation`).

use std::path::PathBuf;

use anyhow::{Context, bail};
use gems_math::{Intrinsics, Se3};
use gems_splat::{Camera, RenderSettings, ply, write_png};

/// Camera path of a fly-through.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum PathKind {
    /// The training photos' mid-exposure cameras, smoothed.
    Train,
    /// A circle around the scene, looking at its centre.
    Orbit,
}

/// Arguments of `gems render`.
#[derive(clap::Args)]
pub struct Args {
    /// Inria-layout Gaussian-splat PLY file, or (with --bursts) an output folder of `gems train`.
    pub input: PathBuf,
    /// Output PNG (a folder with --bursts; default `<input>/bursts`).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// For every training photo of the trained output folder, its n sharp frames along the
    /// exposure (`<stem>/00.png`…, start to end), an animated preview (`<stem>.gif`) and the
    /// mid-exposure image (`<stem>_mid.png`); their mean is the re-blurred photo.
    #[arg(long)]
    pub bursts: bool,
    /// A fly-through video of a trained output folder: along the training path (smoothed, in
    /// the photos' name order) or an orbit around the scene, encoded with the user's ffmpeg as
    /// `--output` (default `<input>/flythrough.mp4`); PNG frames when ffmpeg is absent.
    #[arg(long, value_enum, conflicts_with = "bursts")]
    pub path: Option<PathKind>,
    /// Frames of the fly-through.
    #[arg(long, default_value_t = 120)]
    pub frames: usize,
    /// Frames per second of the fly-through video.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// The ffmpeg executable for the fly-through video.
    #[arg(long, default_value = "ffmpeg")]
    pub ffmpeg: PathBuf,
    /// Image width in pixels.
    #[arg(long, default_value_t = 800)]
    pub width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 600)]
    pub height: u32,
    /// Focal length in pixels along x (default: from --fov).
    #[arg(long)]
    pub fx: Option<f32>,
    /// Focal length in pixels along y (default: fx).
    #[arg(long)]
    pub fy: Option<f32>,
    /// Principal point x (default: width / 2).
    #[arg(long)]
    pub cx: Option<f32>,
    /// Principal point y (default: height / 2).
    #[arg(long)]
    pub cy: Option<f32>,
    /// Horizontal field of view in degrees, used when --fx is not given.
    #[arg(long, default_value_t = 60.0)]
    pub fov: f32,
    /// Camera position in world coordinates: x,y,z.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub cam_pos: Option<[f32; 3]>,
    /// Point the camera looks at: x,y,z.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub look_at: Option<[f32; 3]>,
    /// World direction that appears up in the image: x,y,z (OpenCV/COLMAP scenes: 0,-1,0).
    #[arg(long, value_parser = parse_vec3, default_value = "0,-1,0", allow_hyphen_values = true)]
    pub up: [f32; 3],
    /// World-to-camera rotation, 9 numbers row-major (OpenCV: x right, y down, z forward).
    #[arg(long, value_parser = parse_mat3, allow_hyphen_values = true)]
    pub rotation: Option<[[f32; 3]; 3]>,
    /// World-to-camera translation: x,y,z (x_cam = R x_world + t).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub translation: Option<[f32; 3]>,
    /// COLMAP sparse model folder (cameras/images .bin or .txt) to take the camera from.
    #[arg(long, requires = "image")]
    pub colmap: Option<PathBuf>,
    /// Image name in the COLMAP model whose camera to render.
    #[arg(long, requires = "colmap")]
    pub image: Option<String>,
    /// Background colour r,g,b in [0, 1].
    #[arg(long, value_parser = parse_vec3, default_value = "0,0,0")]
    pub background: [f32; 3],
    /// Mip-Splatting antialiased rasterisation (for scenes trained that way).
    #[arg(long)]
    pub antialiased: bool,
    /// Where the splatting runs: `auto` takes a hardware GPU when there is one and the CPU
    /// otherwise; `gpu` any GPU adapter (software ones such as Mesa lavapipe included), an error
    /// when there is none; `cpu` the CPU.
    #[arg(long, default_value = "auto")]
    pub device: gems_gpu::DeviceChoice,
}

fn parse_floats<const K: usize>(s: &str) -> Result<[f32; K], String> {
    let vals: Vec<f32> = s
        .split(',')
        .map(|v| v.trim().parse::<f32>().map_err(|e| format!("`{v}`: {e}")))
        .collect::<Result<_, _>>()?;
    if !vals.iter().all(|v| v.is_finite()) {
        return Err(format!("`{s}` has a non-finite value"));
    }
    vals.try_into()
        .map_err(|v: Vec<f32>| format!("expected {K} comma-separated numbers, got {}", v.len()))
}

fn parse_vec3(s: &str) -> Result<[f32; 3], String> {
    parse_floats::<3>(s)
}

fn parse_mat3(s: &str) -> Result<[[f32; 3]; 3], String> {
    let v = parse_floats::<9>(s)?;
    Ok([[v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]])
}

/// The camera of image `name` in the COLMAP model at `dir`.
fn colmap_camera(dir: &std::path::Path, name: &str) -> anyhow::Result<Camera> {
    let model = gems_data::colmap::read_model(dir)
        .with_context(|| format!("reading the COLMAP model in {}", dir.display()))?;
    let image = model.image_by_name(name).with_context(|| {
        format!(
            "no image named `{name}` in the COLMAP model {}",
            dir.display()
        )
    })?;
    let cam = model
        .camera(image.camera_id)
        .with_context(|| format!("camera {} of image `{name}` is missing", image.camera_id))?;
    let k = cam.intrinsics().map_err(anyhow::Error::msg)?;
    Ok(Camera::new(&k, &Se3::from(image.pose())))
}

/// Builds the camera from the arguments, rejecting contradictory or incomplete poses.
pub fn camera(args: &Args) -> anyhow::Result<Camera> {
    if let (Some(dir), Some(name)) = (&args.colmap, &args.image) {
        let given = [
            args.cam_pos.is_some(),
            args.look_at.is_some(),
            args.rotation.is_some(),
            args.translation.is_some(),
        ];
        if given.iter().any(|&g| g) {
            bail!(
                "--colmap/--image already give the pose; drop --cam-pos/--look-at/--rotation/--translation"
            );
        }
        return colmap_camera(dir, name);
    }
    if args.width == 0 || args.height == 0 {
        bail!("--width and --height must be positive");
    }
    if !(args.fov > 0.0 && args.fov < 180.0) {
        bail!("--fov must be in (0, 180) degrees");
    }
    let fx = args
        .fx
        .unwrap_or_else(|| 0.5 * args.width as f32 / (0.5 * args.fov.to_radians()).tan());
    let fy = args.fy.unwrap_or(fx);
    let cx = args.cx.unwrap_or(0.5 * args.width as f32);
    let cy = args.cy.unwrap_or(0.5 * args.height as f32);
    if !(fx > 0.0 && fy > 0.0 && fx.is_finite() && fy.is_finite()) {
        bail!("focal lengths must be positive");
    }
    // The arguments are f32; widening them is exact, so the renderer sees them unchanged.
    let k = Intrinsics {
        fx: f64::from(fx),
        fy: f64::from(fy),
        cx: f64::from(cx),
        cy: f64::from(cy),
        width: args.width,
        height: args.height,
    };
    let look = (args.cam_pos, args.look_at);
    let explicit = (args.rotation, args.translation);
    match (look, explicit) {
        ((Some(pos), Some(target)), (None, None)) => Camera::look_at(&k, pos, target, args.up)
            .context("--cam-pos equals --look-at, or the view direction is parallel to --up"),
        ((None, None), (Some(rotation), Some(translation))) => {
            let r = rotation;
            // R must be a rotation: RᵀR = I within f32 tolerance.
            for i in 0..3 {
                for j in 0..3 {
                    let d: f32 = (0..3).map(|k| r[k][i] * r[k][j]).sum();
                    let want = if i == j { 1.0 } else { 0.0 };
                    if (d - want).abs() > 1e-3 {
                        bail!("--rotation is not a rotation matrix (RᵀR ≠ I)");
                    }
                }
            }
            // Widened exactly (no re-orthonormalisation): the renderer gets the given matrix.
            let w2c = Se3::from_arrays(
                &rotation.map(|row| row.map(f64::from)),
                &translation.map(f64::from),
            );
            Ok(Camera::new(&k, &w2c))
        }
        _ => bail!(
            "give the pose as --cam-pos and --look-at, or as --rotation and --translation (not both)"
        ),
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if args.bursts {
        return bursts(&args);
    }
    if let Some(kind) = args.path {
        return flythrough(&args, kind);
    }
    if args.input.is_dir() {
        bail!(
            "{} is a folder: give a PLY file, or --bursts or --path to render a trained output \
             folder",
            args.input.display()
        );
    }
    let Some(output) = &args.output else {
        bail!("give the PNG to write with --output");
    };
    let cam = camera(&args)?;
    let g = ply::read_ply(&args.input)?;
    tracing::info!(
        gaussians = g.len(),
        sh_degree = g.sh_degree,
        "loaded {}",
        args.input.display()
    );
    let settings = RenderSettings {
        antialiased: args.antialiased,
        ..Default::default()
    };
    let mut renderer = super::open_engine(args.device)?;
    let out = renderer.forward(&g, &[cam], &[args.background], &settings)?;
    write_png(output, &out, 0)?;
    let covered = out.alpha.iter().filter(|&&a| a > 0.5).count();
    tracing::info!(
        "wrote {} ({}x{}, {:.1}% of pixels covered)",
        output.display(),
        out.width,
        out.height,
        100.0 * covered as f64 / out.alpha.len() as f64
    );
    Ok(())
}

/// `--bursts`: every training photo's exposure of the trained output folder `args.input`.
fn bursts(args: &Args) -> anyhow::Result<()> {
    let output = gems_train::TrainOutput::load(&args.input).with_context(|| {
        format!(
            "--bursts needs an output folder of `gems train`; cannot read one in {}",
            args.input.display()
        )
    })?;
    let dir = args
        .output
        .clone()
        .unwrap_or_else(|| args.input.join("bursts"));
    let mut engine = super::open_engine(args.device)?;
    let bar = gems_pipeline::progress::bar(
        true,
        output.views.len(),
        "bursts {wide_bar} {pos}/{len} photos  {msg}",
    );
    let n = gems_eval::export::write_bursts(&dir, &mut engine, &output, &mut |name| {
        bar.set_message(name.to_owned());
        bar.inc(1);
    })?;
    bar.finish_and_clear();
    println!(
        "bursts: {n} photos × {} sharp frames in {}",
        output.config.num_virtual_views,
        dir.display()
    );
    Ok(())
}

/// `--path`: a fly-through video of the trained output folder `args.input`.
fn flythrough(args: &Args, kind: PathKind) -> anyhow::Result<()> {
    let output = gems_train::TrainOutput::load(&args.input).with_context(|| {
        format!(
            "--path needs an output folder of `gems train`; cannot read one in {}",
            args.input.display()
        )
    })?;
    if args.frames < 2 || !(args.fps.is_finite() && args.fps > 0.0) {
        bail!("--frames must be at least 2 and --fps positive");
    }
    let poses = match kind {
        PathKind::Train => gems_eval::flythrough::training_path(&output, args.frames, 2),
        PathKind::Orbit => gems_eval::flythrough::orbit_path(&output, args.frames),
    }
    .context("the result has too few cameras (or no Gaussians) for that path")?;
    let video = args
        .output
        .clone()
        .unwrap_or_else(|| args.input.join("flythrough.mp4"));
    let frames_dir = video.with_extension("frames");
    std::fs::create_dir_all(&frames_dir)
        .with_context(|| format!("creating {}", frames_dir.display()))?;
    let k = output.views[0].intrinsics;
    let mut engine = super::open_engine(args.device)?;
    let settings = RenderSettings {
        antialiased: args.antialiased,
        ..Default::default()
    };
    let bar = gems_pipeline::progress::bar(
        true,
        poses.len(),
        "fly-through {wide_bar} {pos}/{len} frames  ETA {eta}",
    );
    for (i, c2w) in poses.iter().enumerate() {
        let cam = Camera::from_c2w(&k, c2w);
        let out = engine.forward(&output.gaussians, &[cam], &[args.background], &settings)?;
        write_png(frames_dir.join(format!("{i:04}.png")), &out, 0)?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    let ffmpeg = gems_data::video::Ffmpeg {
        binary: args.ffmpeg.clone(),
    };
    match ffmpeg.encode(&frames_dir, args.fps, &video) {
        Ok(()) => {
            std::fs::remove_dir_all(&frames_dir)
                .with_context(|| format!("removing {}", frames_dir.display()))?;
            println!(
                "fly-through: {} ({} frames, {} fps)",
                video.display(),
                poses.len(),
                args.fps
            );
        }
        Err(e @ gems_data::video::VideoError::Missing { .. }) => {
            tracing::warn!("{e}");
            println!(
                "fly-through: {} PNG frames in {} (no video: ffmpeg is not available)",
                poses.len(),
                frames_dir.display()
            );
        }
        Err(e) => return Err(e.into()),
    }
    Ok(())
}
