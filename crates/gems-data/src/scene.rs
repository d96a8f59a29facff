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
//! 2. **Blender** — NeRF-synthetic and E2NeRF's synthetic scenes: `transforms_train.json` /
//!    `transforms_test.json` (E2NeRF: `transform_train.json` / `transform_test.json`) beside
//!    `train/` and `test/`. Train frames are training views, test frames sharp novel views, in
//!    file order. A frame without `file_path` is `<split>/r_<index>`; frames whose image is
//!    missing are skipped (E2NeRF lists 200 train frames but ships the 100 even ones) and `gems
//!    info` says so. E2NeRF's train frames hold a list of matrices along the exposure: they
//!    become [`View::gt_subframe_poses`], the middle one (index `len / 2`) the starting and
//!    ground-truth pose (the scenes are rendered, their poses exact); its sharp test
//!    images are taken at matrix 1 of their list (`iCVTEAM/E2NeRF:load_blender.py`). View names
//!    carry the split (`train_r_0.png`) because both splits reuse the same file names.
//! 3. **Nerfstudio** — `transforms.json`.
//! 4. **Llff** — Deblur-NeRF / ExBluRF / E2NeRF / EBAD-NeRF: `poses_bounds.npy` (EBAD-NeRF:
//!    `pose_bounds.npy`) + `images/` holding blurry training images and sharp test images
//!    interleaved: `i % llffhold == 0` is a sharp novel-view test image (hold from
//!    [`OpenOptions::hold`], else `hold=` marker, else 8). EBAD-NeRF keeps the sharp images apart
//!    instead: `images_gt_blur/` (training views) and `images_gt_novel/` (held-out views).
//!    E2NeRF's real scenes hold `k` poses per image (the middle one is used). Optional ExBluRF
//!    `poses_bounds_subframes.npy` gives ground-truth sub-frame poses. A `sparse/0/` beside the
//!    poses file (Deblur-NeRF real scenes as redistributed) gives poses, intrinsics and points;
//!    the poses file then gives only the poses of views the model does not register, carried
//!    into the model's frame by the similarity of the cameras both pose ([`Scene::uses`] says
//!    which it gave).
//! 5. **Folder** — a plain folder of photos or video frames: every image a training view, no
//!    poses (the SfM makes them).
//!
//! [`Scene::dataset`] names the dataset a folder looks like, from the files each one ships.
//!
//! # Poses
//! [`View::pose`] is the pose to start from (SfM model, else LLFF file, else transforms.json).
//! A COLMAP model's images are matched to the views by file name, else by stem (the model may
//! have been made on the PNG copies of JPG photos), else by sorted order when the counts agree
//! ([`colmap::SparseModel::key_by_view_names`]; [`Scene::sfm_match`] says which rule matched);
//! [`View::gt_pose`] is ground truth: from `poses_bounds.npy` only when the manifest declares
//! `poses: ground_truth`, or from PRISM3D's `sparse/0/images_gt.{bin,txt}` (matched by name).
//! [`View::gt_subframe_poses`] come from `poses_bounds_subframes.npy` (ground truth by
//! definition, as in ExBluRF). All are world-to-camera, OpenCV axes; ground truth may live in a
//! different world frame than the SfM poses (align before comparing, e.g. Umeyama).
//!
//! # Downscaling
//! With [`OpenOptions::downscale`] `= f > 1` images are read from the scene's `images_<f>/` (and
//! `images_test_<f>/`) when it exists. Its files may have other names or another extension than
//! `images/` (Deblur-NeRF real scenes: JPG `images/`, PNG `images_4/`): they are paired by file
//! stem, else by sorted order when the counts agree; views keep the `images/` name (the key into
//! SfM models). When the folder is missing, downscaled copies are made with an area filter into
//! the cache ([`OpenOptions::cache_dir`]), never into the scene; without a cache that is an error.
//! Intrinsics are rescaled to the actual image size of each view.
//!
//! # Nothing is written into the scene
//! Opening a scene only reads it. Every copy (downscaled, undistorted) goes to
//! `<cache_dir>/<scene name>-<hash of its path>/`, written atomically.
//!
//! # Distortion
//! SfM cameras with non-zero distortion are an error in [`open_scene`]; [`open_scene_undistorted`]
//! instead replaces each view's image and sharp ground truth by undistorted copies in the cache
//! (see [`crate::undistort`]).

use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::Serialize;

use crate::colmap::{self, SparseModel};
use crate::error::{DataError, Result};
use crate::events::{EventFiles, find_event_files};
use crate::fsutil::read_text;
use crate::image::{
    downscale_area, downscaled_size, image_dimensions, load_image, save_image_auto,
};
use crate::llff::{self, LlffRow};
use crate::manifest::{Manifest, ManifestPoses, read_hold_marker, read_manifest};
use crate::nerfstudio::{self, FrameSplit};
use gems_math::{Intrinsics, Pose};

/// Default hold-out interval (BAD-Gaussians / PRISM3D / LLFF).
pub const DEFAULT_HOLD: i64 = 8;

/// Folder layout of a scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Layout {
    /// GeMS / BAD-Gaussians / PRISM3D: `images/`, `images_test/`, `hold=`, `sparse/0/`.
    Gems,
    /// NeRF-synthetic / E2NeRF synthetic: `transforms_{train,test}.json`, `train/`, `test/`.
    Blender,
    /// Deblur-NeRF / ExBluRF: `poses_bounds.npy`, sharp test views interleaved in `images/`.
    Llff,
    /// nerfstudio `transforms.json`.
    Nerfstudio,
    /// A plain folder of photos or video frames (no poses: run SfM).
    Folder,
}

impl Layout {
    /// Human-readable name.
    pub fn describe(self) -> &'static str {
        match self {
            Layout::Gems => "GeMS/BAD-Gaussians/PRISM3D (images/, images_test/, hold=, sparse/0)",
            Layout::Llff => "LLFF/Deblur-NeRF/ExBluRF (poses_bounds.npy, interleaved test views)",
            Layout::Blender => {
                "NeRF-Blender/E2NeRF synthetic (transforms_train.json, train/, test/)"
            }
            Layout::Nerfstudio => "nerfstudio (transforms.json)",
            Layout::Folder => "a folder of photos or video frames (no poses)",
        }
    }
}

impl std::str::FromStr for Layout {
    type Err = String;
    /// Parses `gems`, `blender`, `llff`, `nerfstudio` or `folder` (as accepted by
    /// `gems info --layout`).
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "gems" | "bad" | "prism3d" => Ok(Layout::Gems),
            "llff" | "exblurf" | "deblurnerf" => Ok(Layout::Llff),
            "blender" | "nerf-synthetic" | "e2nerf" => Ok(Layout::Blender),
            "nerfstudio" => Ok(Layout::Nerfstudio),
            "folder" | "photos" | "frames" => Ok(Layout::Folder),
            other => Err(format!(
                "unknown layout {other:?} (expected gems, blender, llff, nerfstudio or folder)"
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
    /// `transforms.json`, or a NeRF-Blender scene's `transforms_<split>.json`.
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
    /// Image downscale factor (1 = full resolution): the scene's `images_<f>/` when it exists,
    /// else copies made in the cache.
    pub downscale: u32,
    /// Hold-out interval overriding the `hold=` marker (`< 1`: no hold-out).
    pub hold: Option<i64>,
    /// Force a layout instead of detecting it.
    pub layout: Option<Layout>,
    /// Folder for copies that must be made (downscaled or undistorted images); they go to a
    /// per-scene subfolder (see [`cache_folder`]). `None`: a needed copy is an error. Never
    /// inside the scene.
    pub cache_dir: Option<PathBuf>,
    /// Unit of the scene's time files (events, exposure windows) when their values leave it
    /// open (see [`crate::events`]); `None`: detected.
    pub time_unit: Option<gems_events::TimeUnit>,
}

impl Default for OpenOptions {
    fn default() -> Self {
        OpenOptions {
            downscale: 1,
            hold: None,
            layout: None,
            cache_dir: None,
            time_unit: None,
        }
    }
}

/// What one file of a scene is used for (reported by `gems info`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FileUse {
    /// The file or folder.
    pub path: PathBuf,
    /// What it is used for.
    pub role: String,
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
    /// How the scene's COLMAP model's images were matched to the views (`None`: no model).
    pub sfm_match: Option<colmap::NameMatch>,
    /// Each view's time in the clip, seconds, when the views are ordered frames of one video
    /// (a folder with [`crate::video::FRAMES_FILE`]); `None`: unordered photos.
    pub frame_times: Option<Vec<f64>>,
    /// Where `View::pose` comes from.
    pub pose_source: PoseSource,
    /// The manifest, if present.
    pub manifest: Option<Manifest>,
    /// Event files found.
    pub events: EventFiles,
    /// The dataset the folder looks like (e.g. "Deblur-NeRF / LLFF", "ExBluRF", "E2NeRF").
    pub dataset: String,
    /// Which file is used for what (when several could give the same thing).
    pub uses: Vec<FileUse>,
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

/// The LLFF poses file of `root`: `poses_bounds.npy`, or EBAD-NeRF's `pose_bounds.npy`.
pub fn poses_file(root: &Path) -> Option<PathBuf> {
    ["poses_bounds.npy", "pose_bounds.npy"]
        .into_iter()
        .map(|n| root.join(n))
        .find(|p| p.is_file())
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
    } else if blender_split_file(root, "train").is_some() {
        Layout::Blender
    } else if has("transforms.json") {
        Layout::Nerfstudio
    } else if poses_file(root).is_some() {
        Layout::Llff
    } else if root.join("images").is_dir() {
        Layout::Gems
    } else if !gems_fs::list_images(root)?.is_empty() {
        Layout::Folder
    } else {
        return Err(DataError::Missing {
            path: root.join("images"),
            what: "image folder (or images, or transforms.json): not a scene folder".into(),
        });
    };
    Ok(layout)
}

/// The dataset a folder of `layout` looks like, by the files each one ships (for `gems info`).
fn identify(root: &Path, layout: Layout, events: &EventFiles) -> String {
    let has = |n: &str| root.join(n).exists();
    match layout {
        Layout::Llff
            if has("images_gt_blur") || has("images_gt_novel") || has("pose_bounds.npy") =>
        {
            "EBAD-NeRF".into()
        }
        Layout::Llff if has("poses_bounds_subframes.npy") => "ExBluRF".into(),
        Layout::Llff if !events.is_empty() => "E2NeRF (LLFF with events)".into(),
        Layout::Llff => "Deblur-NeRF / LLFF".into(),
        Layout::Gems if has(crate::manifest::MANIFEST_FILE) => "GeMS (generated scene)".into(),
        Layout::Gems if events.bin_counts.is_some() => "PRISM3D-E".into(),
        Layout::Gems if has("images_test") => "BAD-Gaussians / PRISM3D".into(),
        Layout::Gems => "GeMS / BAD-Gaussians / PRISM3D (no sharp images)".into(),
        Layout::Blender if has("transform_train.json") => "E2NeRF synthetic".into(),
        Layout::Blender => "NeRF-Blender synthetic".into(),
        Layout::Nerfstudio => "nerfstudio".into(),
        Layout::Folder => "photos or video frames".into(),
    }
}

/// Opens the scene in `root` (see the module docs for layouts and rules). SfM cameras with
/// distortion are an error (see [`open_scene_undistorted`]).
pub fn open_scene(root: &Path, opts: &OpenOptions) -> Result<Scene> {
    open(root, opts, false)
}

/// Like [`open_scene`], but views whose SfM camera has distortion (SIMPLE_RADIAL, RADIAL,
/// OPENCV) get undistorted copies of their image and sharp ground truth in the cache
/// ([`OpenOptions::cache_dir`], required then; made when missing) and the pinhole intrinsics of
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
    let mut events = find_event_files(root);
    let cache = Cache::new(root, opts);
    let mut scene = match layout {
        Layout::Gems => open_gems(root, opts, &cache, hold, manifest.as_ref(), undistort)?,
        Layout::Llff => open_llff(root, opts, &cache, hold, undistort)?,
        Layout::Blender => open_blender(root, opts, &cache)?,
        Layout::Nerfstudio => open_nerfstudio(root, opts, &cache)?,
        Layout::Folder => open_folder(root, opts, &cache)?,
    };
    scene.manifest = manifest;
    scene.dataset = identify(root, layout, &events);
    let units = crate::events::resolve_time_units(&events, opts.time_unit)?;
    events.stream_unit = units.stream;
    if let (Some(dir), Some(unit)) = (&events.exposure_dir, units.exposure) {
        let windows = gems_events::read_exposure_windows(dir, unit).map_err(DataError::Events)?;
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
        scene.uses.push(FileUse {
            path: dir.join("exposure_start_ts.txt"),
            role: format!("exposure windows (times in {unit})"),
        });
    }
    if let (Some(p), Some(u)) = (&events.stream, units.stream) {
        scene.uses.push(FileUse {
            path: p.clone(),
            role: format!("event stream (times in {u})"),
        });
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

/// Where the copies of one scene go: `<cache_dir>/<scene name>-<hash of its absolute path>/`, so
/// one cache folder can serve several scenes without mixing them.
pub fn cache_folder(cache_dir: &Path, root: &Path) -> PathBuf {
    let abs = std::fs::canonicalize(root).unwrap_or_else(|_| root.to_path_buf());
    // FNV-1a: a stable hash (std's hasher may change between releases).
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in abs.as_os_str().as_encoded_bytes() {
        h = (h ^ u64::from(*b)).wrapping_mul(0x0100_0000_01b3);
    }
    let name = abs
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene".into());
    cache_dir.join(format!("{name}-{h:016x}"))
}

/// The cache of one scene (see [`cache_folder`]); `None` when the caller gave no cache folder.
struct Cache {
    dir: Option<PathBuf>,
    root: PathBuf,
}

impl Cache {
    fn new(root: &Path, opts: &OpenOptions) -> Cache {
        Cache {
            dir: opts.cache_dir.as_deref().map(|c| cache_folder(c, root)),
            root: root.to_path_buf(),
        }
    }

    /// `<cache>/<rel>`, or an error naming what needed a copy.
    fn path(&self, rel: &str, what: &str) -> Result<PathBuf> {
        let dir = self.dir.as_ref().ok_or_else(|| DataError::Missing {
            path: self.root.join(rel),
            what: format!(
                "{what}; gems never writes into a scene folder: give a cache folder \
                 (`gems train` makes one under its output, or pass --cache-dir) to have the \
                 copies made there"
            ),
        })?;
        let root_abs = std::fs::canonicalize(&self.root).unwrap_or_else(|_| self.root.clone());
        let dir_abs = std::path::absolute(dir).unwrap_or_else(|_| dir.clone());
        if dir_abs.starts_with(&root_abs) || dir.starts_with(&self.root) {
            return Err(DataError::Unsupported {
                path: dir.clone(),
                msg: "the cache folder must not be inside the scene folder".into(),
            });
        }
        Ok(dir.join(rel))
    }
}

/// Makes `dst` hold a copy of every image in `src` downscaled by `factor` with an area filter
/// (`floor(size / factor)`), same file names and formats, written atomically. Files already in
/// `dst` at the right size are kept. Returns the number of images written. `dst` must not be a
/// user's folder: [`open_scene`] passes a cache folder.
pub fn ensure_downscaled(src: &Path, dst: &Path, factor: u32) -> Result<usize> {
    let sources = gems_fs::list_images(src)?;
    std::fs::create_dir_all(dst).map_err(|e| DataError::io(dst, e))?;
    let todo: Vec<&PathBuf> = sources
        .iter()
        .filter(|p| {
            let Some(n) = p.file_name() else { return false };
            let want = image_dimensions(p).map(|(w, h)| downscaled_size(w, h, factor));
            match (image_dimensions(&dst.join(n)), want) {
                (Ok(have), Ok(want)) => have != want,
                _ => true,
            }
        })
        .collect();
    if !todo.is_empty() {
        tracing::info!(
            src = %src.display(),
            dst = %dst.display(),
            count = todo.len(),
            factor,
            "creating downscaled images in the cache"
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

fn stem(p: &Path) -> String {
    p.file_stem()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Pairs the files of an existing `images_<f>/` with those of `images/`: by file name, else by
/// stem (Deblur-NeRF real: `x.JPG` ↔ `x.png`), else by sorted order when the counts agree.
fn pair_scaled(full: &[PathBuf], scaled: &[PathBuf], dir: &Path) -> Result<Vec<PathBuf>> {
    let names = |v: &[PathBuf]| v.iter().map(|p| file_name(p)).collect::<Vec<_>>();
    if names(scaled) == names(full) {
        return Ok(scaled.to_vec());
    }
    let by_stem: std::collections::HashMap<String, &PathBuf> =
        scaled.iter().map(|p| (stem(p), p)).collect();
    if by_stem.len() == scaled.len()
        && scaled.len() == full.len()
        && let Some(paired) = full
            .iter()
            .map(|p| by_stem.get(&stem(p)).map(|q| (*q).clone()))
            .collect::<Option<Vec<_>>>()
    {
        return Ok(paired);
    }
    if scaled.len() == full.len() {
        tracing::warn!(
            dir = %dir.display(),
            "file names differ from images/: pairing the two folders by sorted order"
        );
        return Ok(scaled.to_vec());
    }
    Err(DataError::format(
        dir,
        format!(
            "holds {} images but the full-resolution folder holds {}: they cannot be paired (by \
             name, stem or order); fix or remove this folder (gems never writes into it)",
            scaled.len(),
            full.len()
        ),
    ))
}

/// The images of a view folder at the requested downscale, one per full-resolution image in
/// name order, paired as in [`pair_scaled`]: `(full-resolution names, files to read)`.
fn view_images(
    root: &Path,
    base: &str,
    opts: &OpenOptions,
    cache: &Cache,
) -> Result<(Vec<String>, Vec<PathBuf>)> {
    let full_dir = root.join(base);
    let f = opts.downscale.max(1);
    let scaled_dir = root.join(format!("{base}_{f}"));
    if !full_dir.is_dir() {
        // Some redistributions ship only the downscaled folder.
        if f > 1 && scaled_dir.is_dir() {
            let scaled = gems_fs::list_images(&scaled_dir)?;
            if !scaled.is_empty() {
                return Ok((scaled.iter().map(|p| file_name(p)).collect(), scaled));
            }
        }
        return Err(DataError::Missing {
            path: full_dir,
            what: "image folder".into(),
        });
    }
    let full = gems_fs::list_images(&full_dir)?;
    if full.is_empty() {
        return Err(DataError::Missing {
            path: full_dir,
            what: "images (.png/.jpg) in the image folder".into(),
        });
    }
    let names = full.iter().map(|p| file_name(p)).collect();
    if f == 1 {
        return Ok((names, full));
    }
    if scaled_dir.is_dir() {
        return Ok((
            names,
            pair_scaled(&full, &gems_fs::list_images(&scaled_dir)?, &scaled_dir)?,
        ));
    }
    let dst = cache.path(
        &format!("{base}_{f}"),
        &format!("{base}_{f}/ (images downscaled by {f})"),
    )?;
    ensure_downscaled(&full_dir, &dst, f)?;
    let scaled = full
        .iter()
        .map(|p| dst.join(p.file_name().expect("listed files have names")))
        .collect();
    Ok((names, scaled))
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
/// is replaced by an undistorted copy in the cache (`<folder>_undistorted/`, made when missing)
/// and gets the pinhole intrinsics of that copy.
fn attach_sfm(
    views: &mut [View],
    model: &SparseModel,
    dir: &Path,
    undistort: bool,
    cache: &Cache,
) -> Result<()> {
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
        undistort_views(views, model, &cams_file, cache)?;
    }
    Ok(())
}

/// `<folder>_undistorted/<file>` in the cache for an image path.
fn undistorted_path(p: &Path, cache: &Cache) -> Result<PathBuf> {
    let folder = p
        .parent()
        .and_then(|d| d.file_name())
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    cache.path(
        &format!("{folder}_undistorted/{}", file_name(p)),
        "undistorted copies of the images (the SfM camera has distortion)",
    )
}

fn undistort_views(
    views: &mut [View],
    model: &SparseModel,
    cams_file: &Path,
    cache: &Cache,
) -> Result<()> {
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
        "undistorting images into the cache (missing copies only)"
    );
    let maps = maps;
    let mut work: Vec<(PathBuf, PathBuf, &UndistortMap)> = Vec::new();
    for &(i, key) in &jobs {
        let v = &views[i];
        for p in std::iter::once(&v.image).chain(v.sharp_gt.as_ref()) {
            work.push((p.clone(), undistorted_path(p, cache)?, &maps[&key]));
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
        v.image = undistorted_path(&v.image, cache)?;
        v.sharp_gt = v
            .sharp_gt
            .as_deref()
            .map(|p| undistorted_path(p, cache))
            .transpose()?;
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
        colmap::parse_images_txt(&read_text(&txt)?).map_err(|e| DataError::from_format(&txt, e))?
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

/// A scene with the given parts and nothing else yet (manifest, events and dataset are filled in
/// by [`open`]).
fn new_scene(
    root: &Path,
    layout: Layout,
    opts: &OpenOptions,
    hold: Option<i64>,
    views: Vec<View>,
) -> Scene {
    Scene {
        root: root.to_path_buf(),
        layout,
        downscale: opts.downscale.max(1),
        hold,
        views,
        sfm: None,
        sfm_dir: None,
        sfm_match: None,
        frame_times: None,
        pose_source: PoseSource::None,
        manifest: None,
        events: EventFiles::default(),
        dataset: String::new(),
        uses: Vec::new(),
    }
}

/// Views of `names`/`images` (full-resolution names, files to read) with their header sizes.
fn make_views(names: Vec<String>, images: &[PathBuf], hold: Option<i64>) -> Result<Vec<View>> {
    let dims = sizes(images)?;
    Ok(names
        .into_iter()
        .zip(images)
        .zip(dims)
        .enumerate()
        .map(|(i, ((n, p), d))| new_view(n, p.clone(), d, split_of(i, hold)))
        .collect())
}

/// Attaches `sharp` (one per view, or one per training view) as sharp ground truth; `folder`
/// names the sharp folder in errors.
fn attach_sharp(
    views: &mut [View],
    sharp: Vec<PathBuf>,
    folder: &Path,
    hold: Option<i64>,
    only: Option<Split>,
) -> Result<()> {
    let n_train = views.iter().filter(|v| v.split == Split::Train).count();
    let n_novel = views.len() - n_train;
    let pick =
        |s: Split| -> Vec<usize> { (0..views.len()).filter(|&i| views[i].split == s).collect() };
    let targets: Vec<usize> = match only {
        Some(s) if sharp.len() == pick(s).len() => pick(s),
        None if sharp.len() == views.len() => (0..views.len()).collect(),
        Some(Split::Train) | None if sharp.len() == n_train => pick(Split::Train),
        _ => {
            return Err(DataError::format(
                folder,
                format!(
                    "{} sharp images, but the scene has {} views: {n_train} training and {n_novel} \
                     held out with hold={}; neither matches",
                    sharp.len(),
                    views.len(),
                    hold.unwrap_or(0)
                ),
            ));
        }
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
    Ok(())
}

/// Reads the scene's COLMAP model (if any) into `scene`: poses, intrinsics, points. The model's
/// images are matched to the views by name, stem or sorted order
/// ([`SparseModel::key_by_view_names`]) and renamed to them; a model that matches no view is not
/// used (and [`Scene::uses`] says so).
fn attach_scene_sfm(scene: &mut Scene, undistort: bool, cache: &Cache) -> Result<()> {
    let Some(dir) = find_sfm_dir(&scene.root) else {
        return Ok(());
    };
    let mut m = colmap::read_model(&dir)?;
    let names: Vec<String> = scene.views.iter().map(|v| v.name.clone()).collect();
    let matched = m.key_by_view_names(&names);
    scene.sfm_match = Some(matched);
    if matched.matched == 0 {
        tracing::warn!(
            dir = %dir.display(),
            images = m.images.len(),
            "the COLMAP model names none of the scene's views (by name, stem or sorted order): \
             not used"
        );
        scene.uses.push(FileUse {
            path: dir,
            role: format!(
                "not used: none of its {} images names one of the {} views (by file name, stem \
                 or sorted order)",
                m.images.len(),
                names.len()
            ),
        });
        return Ok(());
    }
    attach_sfm(&mut scene.views, &m, &dir, undistort, cache)?;
    scene.pose_source = PoseSource::Sfm;
    scene.uses.push(FileUse {
        path: dir.clone(),
        role: format!(
            "COLMAP model: starting poses of {} of {} views (images matched {}), intrinsics and \
             {} points (--init colmap)",
            matched.matched,
            matched.views,
            matched.rule.describe(),
            m.points.len()
        ),
    });
    scene.sfm = Some(m);
    scene.sfm_dir = Some(dir);
    Ok(())
}

/// Poses from the scene's LLFF poses file, for the views that have none yet: all of them (with
/// the file's intrinsics) when the scene has no usable COLMAP model, else only those the model
/// does not register ([`fill_missing_from_poses_file`]). Returns the role to report for the file.
fn poses_from_file(scene: &mut Scene, rows: &[LlffRow]) -> String {
    match &scene.sfm {
        Some(model) => fill_missing_from_poses_file(&mut scene.views, rows, model),
        None => {
            for (v, r) in scene.views.iter_mut().zip(rows) {
                v.pose = Some(r.pose());
                v.intrinsics = Some(r.intrinsics().resized(v.width, v.height));
            }
            scene.pose_source = PoseSource::Llff;
            "starting poses and intrinsics".into()
        }
    }
}

/// What the poses file gives a scene that also has a COLMAP model: the poses of the views the
/// model does not register, carried into the model's frame by the similarity between the two
/// sources' cameras of the views both pose ([`gems_math::camera_similarity`]); LLFF poses come
/// from the same kind of SfM run but are recentred and rescaled, so they are never mixed with
/// the model's unaligned. Returns the role to report for the poses file.
fn fill_missing_from_poses_file(
    views: &mut [View],
    rows: &[LlffRow],
    model: &SparseModel,
) -> String {
    let c2w = |p: &Pose| gems_math::Se3::from(p).inverse();
    let missing: Vec<usize> = (0..views.len())
        .filter(|&i| views[i].pose.is_none())
        .collect();
    if missing.is_empty() {
        return format!(
            "read and checked ({} rows for {} images, finite rotations); poses not used: the \
             COLMAP model gives them",
            rows.len(),
            views.len()
        );
    }
    let shared: Vec<_> = views
        .iter()
        .zip(rows)
        .filter_map(|(v, r)| Some((c2w(&r.pose()), c2w(v.pose.as_ref()?))))
        .collect();
    let Some(sim) = gems_math::camera_similarity(&shared) else {
        return format!(
            "not used: the COLMAP model leaves {} views without a pose, but shares too few \
             cameras with this file ({}) to carry its poses into the model's frame",
            missing.len(),
            shared.len()
        );
    };
    // One physical camera: the model's, when it has one; else the file's own.
    let model_k = match model.cameras.as_slice() {
        [cam] => cam.intrinsics().ok(),
        _ => None,
    };
    let mut names = Vec::with_capacity(missing.len());
    for i in missing {
        let v = &mut views[i];
        let placed = sim.act_c2w(&c2w(&rows[i].pose()));
        v.pose = Some(Pose::from(&placed.inverse()));
        let k = model_k.unwrap_or_else(|| rows[i].intrinsics());
        v.intrinsics = Some(k.resized(v.width, v.height));
        names.push(v.name.clone());
    }
    tracing::warn!(
        views = %names.join(", "),
        "not registered in the COLMAP model: posed from the poses file, aligned to the model's \
         frame"
    );
    format!(
        "poses of the {} views the COLMAP model does not register ({}), carried into the \
         model's frame by the similarity of the {} cameras both pose",
        names.len(),
        names.join(", "),
        shared.len()
    )
}

fn open_gems(
    root: &Path,
    opts: &OpenOptions,
    cache: &Cache,
    hold: Option<i64>,
    manifest: Option<&Manifest>,
    undistort: bool,
) -> Result<Scene> {
    let (names, images) = view_images(root, "images", opts, cache)?;
    let test_dir = root.join("images_test");
    let sharp = if test_dir.is_dir() {
        Some(view_images(root, "images_test", opts, cache)?.1)
    } else {
        None
    };
    // Without sharp images there is nothing to evaluate on, so no view is held out.
    let hold = if sharp.is_some() { hold } else { None };
    let views = make_views(names, &images, hold)?;
    let mut scene = new_scene(root, Layout::Gems, opts, hold, views);
    if let Some(sharp) = sharp {
        attach_sharp(&mut scene.views, sharp, &test_dir, hold, None)?;
    }
    attach_scene_sfm(&mut scene, undistort, cache)?;
    let ground_truth = manifest.is_some_and(|m| m.poses == ManifestPoses::GroundTruth);
    if let Some(pb) = poses_file(root) {
        let rows = llff_rows_for(&pb, scene.views.len())?;
        let role = if ground_truth {
            for (v, r) in scene.views.iter_mut().zip(&rows) {
                v.gt_pose = Some(r.pose());
                if v.intrinsics.is_none() {
                    v.intrinsics = Some(r.intrinsics().resized(v.width, v.height));
                }
            }
            "ground-truth mid-exposure poses (declared by gems_scene.json)".to_owned()
        } else {
            poses_from_file(&mut scene, &rows)
        };
        scene.uses.push(FileUse { path: pb, role });
    }
    if let Some(dir) = scene.sfm_dir.clone() {
        attach_prism3d_gt(&mut scene.views, &dir)?;
    }
    let sub = root.join("poses_bounds_subframes.npy");
    if sub.is_file() {
        attach_subframes(&mut scene.views, &sub)?;
    }
    Ok(scene)
}

/// LLFF / Deblur-NeRF / ExBluRF / E2NeRF / EBAD-NeRF. With a COLMAP model beside the poses file
/// (Deblur-NeRF real scenes as redistributed), the model gives poses, intrinsics and points and
/// the poses file is read and checked against the images; otherwise the poses file gives them.
fn open_llff(
    root: &Path,
    opts: &OpenOptions,
    cache: &Cache,
    hold: Option<i64>,
    undistort: bool,
) -> Result<Scene> {
    let (names, images) = view_images(root, "images", opts, cache)?;
    let pb = poses_file(root).ok_or_else(|| DataError::Missing {
        path: root.join("poses_bounds.npy"),
        what: "LLFF poses file".into(),
    })?;
    let rows = llff_rows_for(&pb, images.len())?;
    let mut views = make_views(names, &images, hold)?;
    // EBAD-NeRF keeps the sharp images apart; Deblur-NeRF/ExBluRF interleave the sharp test
    // images with the blurry ones.
    let gt_blur = root.join("images_gt_blur");
    let gt_novel = root.join("images_gt_novel");
    let separate = gt_blur.is_dir() || gt_novel.is_dir();
    for v in &mut views {
        if v.split == Split::NovelView && !separate {
            v.sharp_gt = Some(v.image.clone());
        }
    }
    let mut scene = new_scene(root, Layout::Llff, opts, hold, views);
    for (dir, only) in [(&gt_blur, Split::Train), (&gt_novel, Split::NovelView)] {
        if dir.is_dir() {
            let base = file_name(dir);
            let sharp = view_images(root, &base, opts, cache)?.1;
            attach_sharp(&mut scene.views, sharp, dir, hold, Some(only))?;
        }
    }
    attach_scene_sfm(&mut scene, undistort, cache)?;
    let role = poses_from_file(&mut scene, &rows);
    scene.uses.push(FileUse { path: pb, role });
    let sub = root.join("poses_bounds_subframes.npy");
    if sub.is_file() {
        attach_subframes(&mut scene.views, &sub)?;
        scene.uses.push(FileUse {
            path: sub,
            role: "ground-truth sub-frame poses".into(),
        });
    }
    Ok(scene)
}

/// A plain folder of photos or video frames: every image a training view, no poses.
fn open_folder(root: &Path, opts: &OpenOptions, cache: &Cache) -> Result<Scene> {
    let full = gems_fs::list_images(root)?;
    let f = opts.downscale.max(1);
    let images = if f == 1 {
        full.clone()
    } else {
        let dst = cache.path(&format!("images_{f}"), &format!("photos downscaled by {f}"))?;
        ensure_downscaled(root, &dst, f)?;
        full.iter()
            .map(|p| dst.join(p.file_name().expect("listed files have names")))
            .collect()
    };
    let names = full.iter().map(|p| file_name(p)).collect();
    let views = make_views(names, &images, None)?;
    let mut scene = new_scene(root, Layout::Folder, opts, None, views);
    // Frames of a clip keep their order and times (`gems train clip.mp4` writes them).
    if let Some(list) = crate::video::read_frame_list(root) {
        let times: Option<Vec<f64>> = scene
            .views
            .iter()
            .map(|v| {
                list.frames
                    .iter()
                    .find(|f| f.name == v.name)
                    .map(|f| f.time_s)
            })
            .collect();
        if let Some(times) = times {
            scene.uses.push(FileUse {
                path: root.join(crate::video::FRAMES_FILE),
                role: format!(
                    "ordered frames of {} ({:.2} per second, times kept)",
                    list.video.display(),
                    list.rate
                ),
            });
            scene.frame_times = Some(times);
        }
    }
    Ok(scene)
}

fn open_nerfstudio(root: &Path, opts: &OpenOptions, cache: &Cache) -> Result<Scene> {
    let tpath = root.join("transforms.json");
    let t = nerfstudio::read_transforms(&tpath)?;
    if t.frames.is_empty() {
        return Err(DataError::format(&tpath, "no frames"));
    }
    let mut frames = t.frames;
    frames.sort_by(|a, b| a.file_path.cmp(&b.file_path));
    let views = views_from_frames(root, opts, cache, frames, &|_, p| file_name(p))?;
    let mut scene = new_scene(root, Layout::Nerfstudio, opts, None, views);
    scene.pose_source = PoseSource::Nerfstudio;
    Ok(scene)
}

/// The split file of a NeRF-Blender scene: `transforms_<split>.json`, or E2NeRF's
/// `transform_<split>.json`.
fn blender_split_file(root: &Path, split: &str) -> Option<PathBuf> {
    [
        format!("transforms_{split}.json"),
        format!("transform_{split}.json"),
    ]
    .into_iter()
    .map(|n| root.join(n))
    .find(|p| p.is_file())
}

/// The image a transforms frame names (NeRF-Blender files omit the ".png").
fn frame_image(root: &Path, file_path: &str) -> PathBuf {
    let mut p = root.join(file_path);
    if !p.is_file() && p.extension().is_none() {
        p.set_extension("png");
    }
    p
}

fn open_blender(root: &Path, opts: &OpenOptions, cache: &Cache) -> Result<Scene> {
    let mut frames = Vec::new();
    let mut uses = Vec::new();
    for (split_name, split) in [("train", FrameSplit::Train), ("test", FrameSplit::Eval)] {
        let Some(path) = blender_split_file(root, split_name) else {
            continue;
        };
        let t = nerfstudio::parse_split_transforms(&read_text(&path)?, &|i| {
            format!("./{split_name}/r_{i}")
        })
        .map_err(|e| DataError::from_format(&path, e))?;
        let total = t.frames.len();
        let before = frames.len();
        for mut f in t.frames {
            if !frame_image(root, &f.file_path).is_file() {
                continue;
            }
            f.split = Some(split);
            if split == FrameSplit::Eval && !f.subframe_poses.is_empty() {
                // A sharp test image has one pose: E2NeRF's loader takes matrix 1 of the list
                // (iCVTEAM/E2NeRF:load_blender.py).
                f.pose = f.subframe_poses[1.min(f.subframe_poses.len() - 1)];
                f.subframe_poses.clear();
            }
            frames.push(f);
        }
        let kept = frames.len() - before;
        if kept == 0 {
            return Err(DataError::Missing {
                path: root.join(split_name),
                what: format!("images of the {total} frames in {}", path.display()),
            });
        }
        let role = if kept < total {
            format!(
                "{split_name} views: {kept} of {total} frames have an image (the others are skipped)"
            )
        } else {
            format!("{split_name} views ({kept} frames)")
        };
        uses.push(FileUse { path, role });
    }
    let mut views = views_from_frames(root, opts, cache, frames, &|f, p| {
        let split = if f.split == Some(FrameSplit::Eval) {
            "test"
        } else {
            "train"
        };
        format!("{split}_{}", file_name(p))
    })?;
    // Rendered scenes: their poses are exact, so they are also the ground truth (`--init gt`,
    // APE). A train frame with a list of matrices is compared at its middle one.
    for v in &mut views {
        v.gt_pose = v.pose;
    }
    let mut scene = new_scene(root, Layout::Blender, opts, None, views);
    scene.pose_source = PoseSource::Nerfstudio;
    scene.uses.extend(uses);
    Ok(scene)
}

/// Views of transforms frames in the given order; `name` names a view from its frame and image.
fn views_from_frames(
    root: &Path,
    opts: &OpenOptions,
    cache: &Cache,
    frames: Vec<nerfstudio::Frame>,
    name: &dyn Fn(&nerfstudio::Frame, &Path) -> String,
) -> Result<Vec<View>> {
    let mut views = Vec::with_capacity(frames.len());
    // Downscaled folder per source folder: nerfstudio's own `images_<f>/` beside it, else a copy
    // in the cache.
    let mut scaled_dirs: std::collections::HashMap<PathBuf, PathBuf> = Default::default();
    for f in frames {
        let mut p = frame_image(root, &f.file_path);
        if !p.is_file() {
            return Err(DataError::Missing {
                path: p,
                what: format!("image of frame {:?}", f.file_path),
            });
        }
        let file = file_name(&p);
        let view_name = name(&f, &p);
        if opts.downscale > 1 {
            let parent = p.parent().unwrap_or(root).to_path_buf();
            let dst = match scaled_dirs.get(&parent) {
                Some(d) => d.clone(),
                None => {
                    let base = file_name(&parent);
                    let sibling = parent.with_file_name(format!("{base}_{}", opts.downscale));
                    let d = if sibling.is_dir() {
                        sibling
                    } else {
                        let rel = parent.strip_prefix(root).unwrap_or(&parent);
                        let d = cache.path(
                            &format!("{}_{}", rel.display(), opts.downscale),
                            &format!(
                                "{base}_{} (images downscaled by {})",
                                opts.downscale, opts.downscale
                            ),
                        )?;
                        ensure_downscaled(&parent, &d, opts.downscale)?;
                        d
                    };
                    scaled_dirs.insert(parent.clone(), d.clone());
                    d
                }
            };
            let same = dst.join(&file);
            p = if same.is_file() {
                same
            } else {
                gems_fs::list_images(&dst)?
                    .into_iter()
                    .find(|q| stem(q) == stem(&p))
                    .ok_or_else(|| DataError::Missing {
                        path: same,
                        what: format!("downscaled copy of {file}"),
                    })?
            };
        }
        let (w, h) = image_dimensions(&p)?;
        let split = match f.split {
            Some(FrameSplit::Eval) => Split::NovelView,
            _ => Split::Train,
        };
        let mut v = new_view(view_name, p.clone(), (w, h), split);
        if split == Split::NovelView {
            v.sharp_gt = Some(p);
        }
        v.pose = Some(f.pose);
        v.intrinsics = Some(f.camera.resolve(w, h));
        if !f.subframe_poses.is_empty() {
            v.gt_subframe_poses = Some(f.subframe_poses);
        }
        views.push(v);
    }
    Ok(views)
}
