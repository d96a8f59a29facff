//! Opening a scene folder: layout detection, views, splits, poses, SfM model, events.
//!
//! # Layouts ([`Layout`])
//! Detected in this order (override with [`OpenOptions::layout`]):
//! 1. **Gems** — GeMS / BAD-Gaussians / PRISM3D: `images/` (blurry), optional `images_test/`
//!    (sharp), optional `hold=<n>` marker (default 8; `n < 1`: no hold-out), optional
//!    `sparse/0/` COLMAP model, optional `gems_scene.json` manifest. Chosen when the manifest or
//!    `images_test/` exists, or when there is `sparse/` and no `poses_bounds.npy`, or when only
//!    `images/` exists.
//!    Split: views sorted by file name; `i % hold == 0` → novel-view eval, else training.
//!    `images_test/` holds either one sharp image per image in `images/` (GeMS/PRISM3D: training
//!    views get theirs as deblur ground truth, held-out views are evaluated on theirs) or one per
//!    *training* image (BAD-Gaussians: held-out views then have no sharp image) — told apart by
//!    count. Without `images_test/` every view is a training view (nothing to evaluate on).
//! 2. **Nerfstudio** — `transforms.json`.
//! 3. **Llff** — Deblur-NeRF / ExBluRF: `poses_bounds.npy` + `images/` holding blurry training
//!    images and sharp test images interleaved: `i % llffhold == 0` is a sharp novel-view test
//!    image (hold from [`OpenOptions::hold`], else `hold=` marker, else 8). Optional ExBluRF
//!    `poses_bounds_subframes.npy` gives ground-truth sub-frame poses.
//!
//! # Poses
//! [`View::pose`] is the pose to start from (SfM model, else LLFF file, else transforms.json);
//! [`View::gt_pose`] is ground truth: from `poses_bounds.npy` only when the manifest declares
//! `poses: ground_truth`, or from PRISM3D's `sparse/0/images_gt.{bin,txt}` (matched by name).
//! [`View::gt_subframe_poses`] come from `poses_bounds_subframes.npy` (ground truth by
//! definition, as in ExBluRF). All are world-to-camera, OpenCV axes; ground truth may live in a
//! different world frame than the SfM poses (align before comparing, e.g. Umeyama).
//!
//! # Downscaling
//! With [`OpenOptions::downscale`] `= f > 1` images are read from `images_<f>/` (and
//! `images_test_<f>/`), which are created with an area filter when missing; existing files are
//! never overwritten. Intrinsics are rescaled to the actual image size of each view.
//!
//! # Distortion
//! SfM cameras with non-zero distortion are an error in [`open_scene`]; [`open_scene_undistorted`]
//! instead replaces each view's image and sharp ground truth by undistorted copies in
//! `<folder>_undistorted/` (made when missing, never overwritten; see [`crate::undistort`]).

use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::Serialize;

use crate::colmap::{self, SparseModel};
use crate::error::{DataError, Result};
use crate::events::{EventFiles, find_event_files};
use crate::fsutil::list_images;
use crate::image::{
    downscale_area, downscaled_size, image_dimensions, load_image, save_image_auto,
};
use crate::llff::{self, LlffRow};
use crate::manifest::{Manifest, ManifestPoses, read_hold_marker, read_manifest};
use crate::nerfstudio::{self, FrameSplit};
use crate::pose::{Intrinsics, Pose};

/// Default hold-out interval (BAD-Gaussians / PRISM3D / LLFF).
pub const DEFAULT_HOLD: i64 = 8;

/// Folder layout of a scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Layout {
    /// GeMS / BAD-Gaussians / PRISM3D: `images/`, `images_test/`, `hold=`, `sparse/0/`.
    Gems,
    /// Deblur-NeRF / ExBluRF: `poses_bounds.npy`, sharp test views interleaved in `images/`.
    Llff,
    /// nerfstudio `transforms.json`.
    Nerfstudio,
}

impl Layout {
    /// Human-readable name.
    pub fn describe(self) -> &'static str {
        match self {
            Layout::Gems => "GeMS/BAD-Gaussians/PRISM3D (images/, images_test/, hold=, sparse/0)",
            Layout::Llff => "LLFF/Deblur-NeRF/ExBluRF (poses_bounds.npy, interleaved test views)",
            Layout::Nerfstudio => "nerfstudio (transforms.json)",
        }
    }
}

impl std::str::FromStr for Layout {
    type Err = String;
    /// Parses `gems`, `llff` or `nerfstudio` (as accepted by `gems info --layout`).
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "gems" | "bad" | "prism3d" => Ok(Layout::Gems),
            "llff" | "exblurf" | "deblurnerf" => Ok(Layout::Llff),
            "nerfstudio" => Ok(Layout::Nerfstudio),
            other => Err(format!(
                "unknown layout {other:?} (expected gems, llff or nerfstudio)"
            )),
        }
    }
}

/// Which split a view belongs to. Deblur evaluation uses the training views that have a sharp
/// ground truth ([`View::sharp_gt`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Split {
    /// A (blurry) training view.
    Train,
    /// A held-out view for novel-view-synthesis evaluation.
    NovelView,
}

/// Where [`View::pose`] comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PoseSource {
    /// No poses: run SfM first.
    None,
    /// The COLMAP model in `sparse/`.
    Sfm,
    /// `poses_bounds.npy` (estimated poses).
    Llff,
    /// `transforms.json`.
    Nerfstudio,
}

/// One view of a scene.
#[derive(Debug, Clone, PartialEq)]
pub struct View {
    /// File name in the image folder (the key into SfM models).
    pub name: String,
    /// The image to use: blurry for training views; for novel views the image at the eval
    /// position (sharp in the Llff/nerfstudio layouts, the blurry frame in the Gems layout).
    pub image: PathBuf,
    /// Width of `image` in pixels.
    pub width: u32,
    /// Height of `image` in pixels.
    pub height: u32,
    /// Pinhole intrinsics at `width × height`, if known (no SfM yet: `None`).
    pub intrinsics: Option<Intrinsics>,
    /// Training or novel-view evaluation.
    pub split: Split,
    /// Sharp mid-exposure ground truth, same size as `image`.
    pub sharp_gt: Option<PathBuf>,
    /// Starting pose (world-to-camera), from [`Scene::pose_source`].
    pub pose: Option<Pose>,
    /// Ground-truth mid-exposure pose.
    pub gt_pose: Option<Pose>,
    /// Ground-truth poses of the sharp sub-frames inside the exposure, in time order.
    pub gt_subframe_poses: Option<Vec<Pose>>,
    /// Exposure window in µs (from `exposure_start_ts.txt` / `exposure_end_ts.txt`).
    pub exposure: Option<gems_events::ExposureWindow>,
}

/// Options of [`open_scene`].
#[derive(Debug, Clone, PartialEq)]
pub struct OpenOptions {
    /// Image downscale factor (1 = full resolution). `images_<f>/` is created when missing.
    pub downscale: u32,
    /// Hold-out interval overriding the `hold=` marker (`< 1`: no hold-out).
    pub hold: Option<i64>,
    /// Force a layout instead of detecting it.
    pub layout: Option<Layout>,
    /// Create missing `images_<f>/` copies (else a missing folder is an error).
    pub create_downscaled: bool,
}

impl Default for OpenOptions {
    fn default() -> Self {
        OpenOptions {
            downscale: 1,
            hold: None,
            layout: None,
            create_downscaled: true,
        }
    }
}

/// A scene folder, opened.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The scene folder.
    pub root: PathBuf,
    /// Its layout.
    pub layout: Layout,
    /// Downscale factor the views refer to.
    pub downscale: u32,
    /// Hold-out interval used for the split (`None`: no hold-out).
    pub hold: Option<i64>,
    /// Views sorted by file name.
    pub views: Vec<View>,
    /// The COLMAP model, if the scene has one (coordinates as in the file).
    pub sfm: Option<SparseModel>,
    /// Folder of the SfM model.
    pub sfm_dir: Option<PathBuf>,
    /// Where `View::pose` comes from.
    pub pose_source: PoseSource,
    /// The manifest, if present.
    pub manifest: Option<Manifest>,
    /// Event files found.
    pub events: EventFiles,
}

impl Scene {
    /// Training views.
    pub fn train_views(&self) -> impl Iterator<Item = &View> {
        self.views.iter().filter(|v| v.split == Split::Train)
    }
    /// Training views with a sharp ground truth (deblurring evaluation).
    pub fn deblur_eval_views(&self) -> impl Iterator<Item = &View> {
        self.train_views().filter(|v| v.sharp_gt.is_some())
    }
    /// Held-out views with a sharp ground truth (novel-view evaluation).
    pub fn nvs_eval_views(&self) -> impl Iterator<Item = &View> {
        self.views
            .iter()
            .filter(|v| v.split == Split::NovelView && v.sharp_gt.is_some())
    }
}

/// Detects the layout of `root`.
pub fn detect_layout(root: &Path) -> Result<Layout> {
    if !root.is_dir() {
        return Err(DataError::Missing {
            path: root.to_path_buf(),
            what: "scene folder".into(),
        });
    }
    let has = |n: &str| root.join(n).exists();
    let layout = if has(crate::manifest::MANIFEST_FILE) || root.join("images_test").is_dir() {
        Layout::Gems
    } else if has("transforms.json") {
        Layout::Nerfstudio
    } else if has("poses_bounds.npy") {
        Layout::Llff
    } else if root.join("images").is_dir() {
        Layout::Gems
    } else {
        return Err(DataError::Missing {
            path: root.join("images"),
            what: "image folder (or transforms.json): not a scene folder".into(),
        });
    };
    Ok(layout)
}

/// Opens the scene in `root` (see the module docs for layouts and rules). SfM cameras with
/// distortion are an error (see [`open_scene_undistorted`]).
pub fn open_scene(root: &Path, opts: &OpenOptions) -> Result<Scene> {
    open(root, opts, false)
}

/// Like [`open_scene`], but views whose SfM camera has distortion (SIMPLE_RADIAL, RADIAL,
/// OPENCV) get undistorted copies of their image and sharp ground truth in
/// `<folder>_undistorted/` (made when missing, never overwritten) and the pinhole intrinsics of
/// those copies.
pub fn open_scene_undistorted(root: &Path, opts: &OpenOptions) -> Result<Scene> {
    open(root, opts, true)
}

fn open(root: &Path, opts: &OpenOptions, undistort: bool) -> Result<Scene> {
    let layout = match opts.layout {
        Some(l) => l,
        None => detect_layout(root)?,
    };
    let manifest = read_manifest(root)?;
    let hold = match opts.hold {
        Some(h) => h,
        None => read_hold_marker(root)?.unwrap_or(DEFAULT_HOLD),
    };
    let hold = (hold >= 1).then_some(hold);
    let events = find_event_files(root);
    let mut scene = match layout {
        Layout::Gems => open_gems(root, opts, hold, manifest.as_ref(), undistort)?,
        Layout::Llff => open_llff(root, opts, hold)?,
        Layout::Nerfstudio => open_nerfstudio(root, opts)?,
    };
    scene.manifest = manifest;
    if let Some(dir) = &events.exposure_dir {
        let windows = gems_events::read_exposure_windows(dir, gems_events::TimeUnit::Microseconds)
            .map_err(DataError::Events)?;
        if windows.len() != scene.views.len() {
            return Err(DataError::format(
                dir.join("exposure_start_ts.txt"),
                format!(
                    "{} exposure windows but the scene has {} views",
                    windows.len(),
                    scene.views.len()
                ),
            ));
        }
        for (v, w) in scene.views.iter_mut().zip(windows) {
            v.exposure = Some(w);
        }
    }
    scene.events = events;
    tracing::debug!(
        root = %root.display(),
        layout = ?scene.layout,
        views = scene.views.len(),
        "opened scene"
    );
    Ok(scene)
}

/// The image folder for a downscale factor: `base` for 1, else `base_<f>` (created from `base`
/// when missing and allowed).
fn image_dir(root: &Path, base: &str, opts: &OpenOptions) -> Result<PathBuf> {
    let src = root.join(base);
    if opts.downscale <= 1 {
        return Ok(src);
    }
    let dst = root.join(format!("{base}_{}", opts.downscale));
    if !dst.is_dir() && !opts.create_downscaled {
        return Err(DataError::Missing {
            path: dst,
            what: "downscaled image folder".into(),
        });
    }
    ensure_downscaled(&src, &dst, opts.downscale)?;
    Ok(dst)
}

/// Makes `dst` hold a copy of every image in `src` downscaled by `factor` with an area filter
/// (`floor(size / factor)`), same file names and formats. Files already in `dst` are kept as they
/// are (never overwritten). Returns the number of images written.
pub fn ensure_downscaled(src: &Path, dst: &Path, factor: u32) -> Result<usize> {
    let sources = list_images(src)?;
    std::fs::create_dir_all(dst).map_err(|e| DataError::io(dst, e))?;
    let todo: Vec<&PathBuf> = sources
        .iter()
        .filter(|p| p.file_name().is_some_and(|n| !dst.join(n).exists()))
        .collect();
    if !todo.is_empty() {
        tracing::info!(
            src = %src.display(),
            dst = %dst.display(),
            count = todo.len(),
            factor,
            "creating downscaled images"
        );
    }
    todo.par_iter()
        .map(|p| {
            let img = load_image(p)?;
            let (w, h) = downscaled_size(img.width, img.height, factor);
            let small = downscale_area(&img, w, h);
            let name = p.file_name().expect("listed files have names");
            save_image_auto(&dst.join(name), &small)
        })
        .collect::<Result<Vec<()>>>()?;
    Ok(todo.len())
}

fn file_name(p: &Path) -> String {
    p.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Image list of a folder at the requested downscale, checked against the full-res names.
fn view_images(root: &Path, base: &str, opts: &OpenOptions) -> Result<Vec<PathBuf>> {
    let full_dir = root.join(base);
    if !full_dir.is_dir() {
        return Err(DataError::Missing {
            path: full_dir,
            what: "image folder".into(),
        });
    }
    let full = list_images(&full_dir)?;
    if full.is_empty() {
        return Err(DataError::Missing {
            path: full_dir,
            what: "images (.png/.jpg) in the image folder".into(),
        });
    }
    let dir = image_dir(root, base, opts)?;
    if dir == full_dir {
        return Ok(full);
    }
    let scaled = list_images(&dir)?;
    let names = |v: &[PathBuf]| v.iter().map(|p| file_name(p)).collect::<Vec<_>>();
    if names(&scaled) != names(&full) {
        return Err(DataError::format(
            &dir,
            format!(
                "holds {} images whose names differ from the {} in {}; remove the folder to \
                 regenerate it",
                scaled.len(),
                full.len(),
                full_dir.display()
            ),
        ));
    }
    Ok(scaled)
}

/// Reads image sizes (headers only), in parallel.
fn sizes(paths: &[PathBuf]) -> Result<Vec<(u32, u32)>> {
    paths.par_iter().map(|p| image_dimensions(p)).collect()
}

fn new_view(name: String, image: PathBuf, (width, height): (u32, u32), split: Split) -> View {
    View {
        name,
        image,
        width,
        height,
        intrinsics: None,
        split,
        sharp_gt: None,
        pose: None,
        gt_pose: None,
        gt_subframe_poses: None,
        exposure: None,
    }
}

fn split_of(i: usize, hold: Option<i64>) -> Split {
    match hold {
        Some(h) if (i as i64) % h == 0 => Split::NovelView,
        _ => Split::Train,
    }
}

/// Locates the COLMAP model: `sparse/0/`, else `sparse/` itself.
fn find_sfm_dir(root: &Path) -> Option<PathBuf> {
    [root.join("sparse").join("0"), root.join("sparse")]
        .into_iter()
        .find(|d| colmap::detect_format(d).is_some())
}

/// Attaches SfM poses and intrinsics to views by file name. Cameras with non-zero distortion
/// are an error unless `undistort`, in which case every view's image (and sharp ground truth)
/// is replaced by an undistorted copy in a sibling `<folder>_undistorted/` (made when missing,
/// never overwritten) and gets the pinhole intrinsics of that copy.
fn attach_sfm(views: &mut [View], model: &SparseModel, dir: &Path, undistort: bool) -> Result<()> {
    let cams_file = dir.join(format!(
        "cameras.{}",
        match colmap::detect_format(dir) {
            Some(colmap::ModelFormat::Text) => "txt",
            _ => "bin",
        }
    ));
    let mut registered = 0;
    let mut needs_undistort = false;
    for v in views.iter_mut() {
        let Some(img) = model.image_by_name(&v.name) else {
            continue;
        };
        registered += 1;
        let cam = model
            .camera(img.camera_id)
            .expect("read_model checked camera references");
        v.pose = Some(img.pose());
        match cam.intrinsics() {
            // The model may have been computed on a resized copy (e.g. the Deblur-NeRF "ball"
            // scene): rescale to this view's actual size.
            Ok(k) => v.intrinsics = Some(k.resized(v.width, v.height)),
            Err(msg) if !undistort || crate::undistort::UndistortMap::new(cam, 1, 1).is_err() => {
                return Err(DataError::Unsupported {
                    path: cams_file,
                    msg: format!(
                        "{msg}; or open the scene with undistortion (open_scene_undistorted)"
                    ),
                });
            }
            Err(_) => needs_undistort = true,
        }
    }
    if registered < views.len() {
        tracing::warn!(
            dir = %dir.display(),
            registered,
            views = views.len(),
            "some views are not registered in the SfM model and have no pose"
        );
    }
    if needs_undistort {
        undistort_views(views, model, &cams_file)?;
    }
    Ok(())
}

/// `<parent>/<folder>_undistorted/<file>` for an image path.
fn undistorted_path(p: &Path) -> PathBuf {
    let dir = p.parent().unwrap_or(Path::new("."));
    let folder = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    dir.with_file_name(format!("{folder}_undistorted"))
        .join(p.file_name().unwrap_or_default())
}

fn undistort_views(views: &mut [View], model: &SparseModel, cams_file: &Path) -> Result<()> {
    use crate::undistort::UndistortMap;
    use std::collections::HashMap;
    // One map per (camera, image size), shared by every view that uses it.
    let mut maps: HashMap<(u32, u32, u32), UndistortMap> = HashMap::new();
    let mut jobs: Vec<(usize, (u32, u32, u32))> = Vec::new();
    for (i, v) in views.iter().enumerate() {
        let Some(img) = model.image_by_name(&v.name) else {
            continue;
        };
        let cam = model.camera(img.camera_id).expect("checked by read_model");
        let key = (cam.id, v.width, v.height);
        if let std::collections::hash_map::Entry::Vacant(e) = maps.entry(key) {
            let map = UndistortMap::new(cam, v.width, v.height).map_err(|msg| {
                DataError::Unsupported {
                    path: cams_file.to_path_buf(),
                    msg,
                }
            })?;
            e.insert(map);
        }
        jobs.push((i, key));
    }
    tracing::info!(
        views = jobs.len(),
        "undistorting images (missing copies only)"
    );
    let maps = maps;
    let mut work: Vec<(PathBuf, PathBuf, &UndistortMap)> = Vec::new();
    for &(i, key) in &jobs {
        let v = &views[i];
        for p in std::iter::once(&v.image).chain(v.sharp_gt.as_ref()) {
            work.push((p.clone(), undistorted_path(p), &maps[&key]));
        }
    }
    work.par_iter()
        .filter(|(_, dst, _)| !dst.exists())
        .map(|(src, dst, map)| {
            let img = load_image(src)?;
            let out = map.apply(&img).map_err(|msg| DataError::format(src, msg))?;
            save_image_auto(dst, &out)
        })
        .collect::<Result<Vec<()>>>()?;
    for &(i, key) in &jobs {
        let v = &mut views[i];
        v.image = undistorted_path(&v.image);
        v.sharp_gt = v.sharp_gt.as_deref().map(undistorted_path);
        v.intrinsics = Some(maps[&key].intrinsics());
    }
    Ok(())
}

/// Rows of an LLFF file, one per view. E2NeRF's real scenes store `k` poses per image (from
/// SfM on `k` EDI-deblurred frames of each exposure, `k·N` rows); the middle one of each group
/// is the mid-exposure pose.
fn llff_rows_for(path: &Path, n: usize) -> Result<Vec<LlffRow>> {
    let rows = llff::read_poses_bounds(path)?;
    if rows.len() == n {
        return Ok(rows);
    }
    if n > 0 && rows.len() > n && rows.len().is_multiple_of(n) {
        let k = rows.len() / n;
        tracing::info!(
            path = %path.display(),
            per_image = k,
            "poses file holds {k} poses per image (E2NeRF); using the middle one of each group"
        );
        return Ok(rows.chunks_exact(k).map(|g| g[k / 2]).collect());
    }
    Err(DataError::format(
        path,
        format!(
            "{} poses but the image folder has {n} images (rows must be one per image, sorted \
             by name, or k per image as in E2NeRF)",
            rows.len()
        ),
    ))
}

/// Sub-frame rows, one entry per view of `targets` (indices into the views).
fn attach_subframes(views: &mut [View], path: &Path) -> Result<()> {
    let sub = llff::read_subframes(path)?;
    let train: Vec<usize> = (0..views.len())
        .filter(|&i| views[i].split == Split::Train)
        .collect();
    let targets: Vec<usize> = if sub.len() == views.len() {
        (0..views.len()).collect()
    } else if sub.len() == train.len() {
        train
    } else {
        return Err(DataError::format(
            path,
            format!(
                "{} images of sub-frames, but the scene has {} views ({} training)",
                sub.len(),
                views.len(),
                train.len()
            ),
        ));
    };
    for (i, rows) in targets.into_iter().zip(sub) {
        views[i].gt_subframe_poses = Some(rows.iter().map(LlffRow::pose).collect());
    }
    Ok(())
}

/// PRISM3D keeps ground-truth poses as a second COLMAP image list, `sparse/0/images_gt.bin`
/// (or `.txt`); they are matched to views by file name.
fn attach_prism3d_gt(views: &mut [View], sfm_dir: &Path) -> Result<()> {
    let bin = sfm_dir.join("images_gt.bin");
    let txt = sfm_dir.join("images_gt.txt");
    let images = if bin.is_file() {
        colmap::parse_images_bin(&crate::fsutil::read_bytes(&bin)?)
            .map_err(|e| DataError::from_format(&bin, e))?
    } else if txt.is_file() {
        colmap::parse_images_txt(&crate::fsutil::read_text(&txt)?)
            .map_err(|e| DataError::from_format(&txt, e))?
    } else {
        return Ok(());
    };
    let path = if bin.is_file() { bin } else { txt };
    for img in &images {
        let pose = img.pose();
        if !pose.is_finite() {
            return Err(DataError::format(
                &path,
                format!("image {} ({}) has a non-finite pose", img.id, img.name),
            ));
        }
        if let Some(v) = views.iter_mut().find(|v| v.name == img.name) {
            v.gt_pose = Some(pose);
        }
    }
    Ok(())
}

fn open_gems(
    root: &Path,
    opts: &OpenOptions,
    hold: Option<i64>,
    manifest: Option<&Manifest>,
    undistort: bool,
) -> Result<Scene> {
    let images = view_images(root, "images", opts)?;
    let dims = sizes(&images)?;
    let test_dir = root.join("images_test");
    let sharp = if test_dir.is_dir() {
        Some(view_images(root, "images_test", opts)?)
    } else {
        None
    };
    // Without sharp images there is nothing to evaluate on, so no view is held out.
    let hold = if sharp.is_some() { hold } else { None };
    let mut views: Vec<View> = images
        .iter()
        .zip(&dims)
        .enumerate()
        .map(|(i, (p, &d))| new_view(file_name(p), p.clone(), d, split_of(i, hold)))
        .collect();
    if let Some(sharp) = sharp {
        let n_train = views.iter().filter(|v| v.split == Split::Train).count();
        let targets: Vec<usize> = if sharp.len() == views.len() {
            (0..views.len()).collect()
        } else if sharp.len() == n_train {
            (0..views.len())
                .filter(|&i| views[i].split == Split::Train)
                .collect()
        } else {
            return Err(DataError::format(
                &test_dir,
                format!(
                    "{} sharp images, but images/ has {} (one per image) and {n_train} training \
                     views with hold={} (one per training image); neither matches",
                    sharp.len(),
                    views.len(),
                    hold.unwrap_or(0)
                ),
            ));
        };
        let sharp_dims = sizes(&sharp)?;
        for (i, (p, d)) in targets.into_iter().zip(sharp.into_iter().zip(sharp_dims)) {
            if d != (views[i].width, views[i].height) {
                return Err(DataError::format(
                    &p,
                    format!(
                        "sharp image is {}x{} but its blurry twin {} is {}x{}",
                        d.0, d.1, views[i].name, views[i].width, views[i].height
                    ),
                ));
            }
            views[i].sharp_gt = Some(p);
        }
    }
    let mut pose_source = PoseSource::None;
    let sfm_dir = find_sfm_dir(root);
    let sfm = match &sfm_dir {
        Some(dir) => {
            let m = colmap::read_model(dir)?;
            attach_sfm(&mut views, &m, dir, undistort)?;
            pose_source = PoseSource::Sfm;
            Some(m)
        }
        None => None,
    };
    let pb = root.join("poses_bounds.npy");
    let ground_truth = manifest.is_some_and(|m| m.poses == ManifestPoses::GroundTruth);
    if pb.is_file() {
        let rows = llff_rows_for(&pb, views.len())?;
        for (v, r) in views.iter_mut().zip(&rows) {
            if ground_truth {
                v.gt_pose = Some(r.pose());
            } else if sfm.is_none() {
                v.pose = Some(r.pose());
            }
            if v.intrinsics.is_none() {
                v.intrinsics = Some(r.intrinsics().resized(v.width, v.height));
            }
        }
        if !ground_truth && sfm.is_none() {
            pose_source = PoseSource::Llff;
        }
    }
    if let Some(dir) = &sfm_dir {
        attach_prism3d_gt(&mut views, dir)?;
    }
    let sub = root.join("poses_bounds_subframes.npy");
    if sub.is_file() {
        attach_subframes(&mut views, &sub)?;
    }
    Ok(Scene {
        root: root.to_path_buf(),
        layout: Layout::Gems,
        downscale: opts.downscale.max(1),
        hold,
        views,
        sfm,
        sfm_dir,
        pose_source,
        manifest: None,
        events: EventFiles::default(),
    })
}

fn open_llff(root: &Path, opts: &OpenOptions, hold: Option<i64>) -> Result<Scene> {
    let images = view_images(root, "images", opts)?;
    let dims = sizes(&images)?;
    let pb = root.join("poses_bounds.npy");
    let rows = llff_rows_for(&pb, images.len())?;
    let mut views: Vec<View> = Vec::with_capacity(images.len());
    for (i, ((p, d), r)) in images.iter().zip(dims).zip(&rows).enumerate() {
        let split = split_of(i, hold);
        let mut v = new_view(file_name(p), p.clone(), d, split);
        if split == Split::NovelView {
            // Deblur-NeRF/ExBluRF interleave the sharp test images with the blurry ones.
            v.sharp_gt = Some(p.clone());
        }
        v.pose = Some(r.pose());
        v.intrinsics = Some(r.intrinsics().resized(d.0, d.1));
        views.push(v);
    }
    let sub = root.join("poses_bounds_subframes.npy");
    if sub.is_file() {
        attach_subframes(&mut views, &sub)?;
    }
    Ok(Scene {
        root: root.to_path_buf(),
        layout: Layout::Llff,
        downscale: opts.downscale.max(1),
        hold,
        views,
        sfm: None,
        sfm_dir: None,
        pose_source: PoseSource::Llff,
        manifest: None,
        events: EventFiles::default(),
    })
}

fn open_nerfstudio(root: &Path, opts: &OpenOptions) -> Result<Scene> {
    let tpath = root.join("transforms.json");
    let t = nerfstudio::read_transforms(&tpath)?;
    if t.frames.is_empty() {
        return Err(DataError::format(&tpath, "no frames"));
    }
    let mut frames = t.frames;
    frames.sort_by(|a, b| a.file_path.cmp(&b.file_path));
    let mut views = Vec::with_capacity(frames.len());
    for f in frames {
        let mut p = root.join(&f.file_path);
        if !p.is_file() && p.extension().is_none() {
            // NeRF-Blender files omit the ".png".
            p.set_extension("png");
        }
        if !p.is_file() {
            return Err(DataError::Missing {
                path: p,
                what: format!("image of frame {:?} in {}", f.file_path, tpath.display()),
            });
        }
        if opts.downscale > 1 {
            let parent = p.parent().unwrap_or(root).to_path_buf();
            let base = parent
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let dst = parent.with_file_name(format!("{base}_{}", opts.downscale));
            if !dst.is_dir() && !opts.create_downscaled {
                return Err(DataError::Missing {
                    path: dst,
                    what: "downscaled image folder".into(),
                });
            }
            ensure_downscaled(&parent, &dst, opts.downscale)?;
            p = dst.join(p.file_name().expect("checked is_file"));
        }
        let (w, h) = image_dimensions(&p)?;
        let split = match f.split {
            Some(FrameSplit::Eval) => Split::NovelView,
            _ => Split::Train,
        };
        let mut v = new_view(file_name(&p), p.clone(), (w, h), split);
        if split == Split::NovelView {
            v.sharp_gt = Some(p);
        }
        v.pose = Some(f.pose);
        v.intrinsics = Some(f.camera.resolve(w, h));
        views.push(v);
    }
    Ok(Scene {
        root: root.to_path_buf(),
        layout: Layout::Nerfstudio,
        downscale: opts.downscale.max(1),
        hold: None,
        views,
        sfm: None,
        sfm_dir: None,
        pose_source: PoseSource::Nerfstudio,
        manifest: None,
        events: EventFiles::default(),
    })
}
