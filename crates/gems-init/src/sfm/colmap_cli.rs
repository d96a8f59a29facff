//! `--init colmap-cli`: run a user-installed COLMAP (feature extractor, exhaustive matcher,
//! mapper; CPU SIFT) as a subprocess and import the largest model it writes.

use super::SfmError;
use gems_data::colmap::{self, SparseModel};
use std::path::{Path, PathBuf};
use std::process::Command;

/// Settings of [`run_colmap_cli`].
#[derive(Clone, Debug)]
pub struct ColmapCliOptions {
    /// The `colmap` executable (looked up on PATH when not absolute).
    pub binary: PathBuf,
    /// Focal length in pixels when known; passed as a SIMPLE_PINHOLE prior.
    pub focal_px: Option<f64>,
    /// Use GPU SIFT (needs a CUDA build of COLMAP); the Debian package is CPU only.
    pub use_gpu: bool,
}

impl Default for ColmapCliOptions {
    fn default() -> Self {
        ColmapCliOptions {
            binary: PathBuf::from("colmap"),
            focal_px: None,
            use_gpu: false,
        }
    }
}

fn run_step(opts: &ColmapCliOptions, args: &[String], work_dir: &Path) -> Result<(), SfmError> {
    tracing::info!(step = %args[0], "running colmap");
    let out = Command::new(&opts.binary)
        .args(args)
        // COLMAP's Qt parts must not need a display.
        .env("QT_QPA_PLATFORM", "offscreen")
        .output()
        .map_err(|e| {
            SfmError::Colmap(format!(
                "could not start `{}` ({e}); install COLMAP (e.g. `apt-get install colmap`) or pass its path",
                opts.binary.display()
            ))
        })?;
    if !out.status.success() {
        let log = work_dir.join(format!("colmap_{}.log", args[0]));
        // Keeping the log is best effort; the error below carries its tail anyway.
        let _ = std::fs::write(&log, [&out.stdout[..], &out.stderr[..]].concat());
        let stderr = String::from_utf8_lossy(&out.stderr);
        let tail: String = stderr
            .lines()
            .rev()
            .take(5)
            .collect::<Vec<_>>()
            .into_iter()
            .rev()
            .collect::<Vec<_>>()
            .join("\n");
        return Err(SfmError::Colmap(format!(
            "`colmap {}` failed ({}): {tail}",
            args[0], out.status
        )));
    }
    Ok(())
}

/// Run COLMAP on the images in `image_dir`, working in `work_dir` (database and models are kept
/// there for inspection). Returns the model with the most registered images and its folder.
pub fn run_colmap_cli(
    image_dir: &Path,
    work_dir: &Path,
    opts: &ColmapCliOptions,
) -> Result<(SparseModel, PathBuf), SfmError> {
    std::fs::create_dir_all(work_dir).map_err(|e| SfmError::Write {
        path: work_dir.to_path_buf(),
        source: Box::new(e),
    })?;
    let db = work_dir.join("colmap.db");
    if db.exists() {
        std::fs::remove_file(&db).map_err(|e| SfmError::Write {
            path: db.clone(),
            source: Box::new(e),
        })?;
    }
    let sparse = work_dir.join("colmap_sparse");
    std::fs::create_dir_all(&sparse).map_err(|e| SfmError::Write {
        path: sparse.clone(),
        source: Box::new(e),
    })?;
    let s = |p: &Path| p.display().to_string();
    let gpu = if opts.use_gpu { "1" } else { "0" };
    let mut fe = vec![
        "feature_extractor".to_owned(),
        "--database_path".into(),
        s(&db),
        "--image_path".into(),
        s(image_dir),
        "--ImageReader.single_camera".into(),
        "1".into(),
        "--ImageReader.camera_model".into(),
        "SIMPLE_PINHOLE".into(),
        "--SiftExtraction.use_gpu".into(),
        gpu.into(),
    ];
    if let Some(f) = opts.focal_px {
        let first = first_image_size(image_dir)?;
        fe.push("--ImageReader.camera_params".into());
        fe.push(format!(
            "{f},{},{}",
            first.0 as f64 / 2.0,
            first.1 as f64 / 2.0
        ));
    }
    run_step(opts, &fe, work_dir)?;
    run_step(
        opts,
        &[
            "exhaustive_matcher".into(),
            "--database_path".into(),
            s(&db),
            "--SiftMatching.use_gpu".into(),
            gpu.into(),
        ],
        work_dir,
    )?;
    let mut mapper = vec![
        "mapper".to_owned(),
        "--database_path".into(),
        s(&db),
        "--image_path".into(),
        s(image_dir),
        "--output_path".into(),
        s(&sparse),
    ];
    if opts.focal_px.is_some() {
        mapper.extend(["--Mapper.ba_refine_focal_length".into(), "0".into()]);
    }
    run_step(opts, &mapper, work_dir)?;
    let mut best: Option<(SparseModel, PathBuf)> = None;
    let mut entries: Vec<PathBuf> = std::fs::read_dir(&sparse)
        .map_err(|e| SfmError::Colmap(format!("{}: {e}", sparse.display())))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir())
        .collect();
    entries.sort();
    for dir in entries {
        let m = colmap::read_model(&dir)?;
        if best
            .as_ref()
            .is_none_or(|b| m.images.len() > b.0.images.len())
        {
            best = Some((m, dir));
        }
    }
    best.ok_or_else(|| {
        SfmError::Colmap(format!(
            "COLMAP's mapper registered no model in {}",
            sparse.display()
        ))
    })
}

/// The size of the first image of `dir` (gems-fs's listing, in name order) whose header reads:
/// it sets the principal point given to COLMAP with a known focal.
fn first_image_size(dir: &Path) -> Result<(u32, u32), SfmError> {
    let files = gems_fs::list_images(dir).map_err(|e| SfmError::Colmap(e.to_string()))?;
    for f in files {
        if let Ok(d) = image::image_dimensions(&f) {
            return Ok(d);
        }
    }
    Err(SfmError::Colmap(format!(
        "no readable image in {}",
        dir.display()
    )))
}
