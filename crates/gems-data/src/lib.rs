//! The scene data layer of gems: views, splits, intrinsics, poses and sparse models read from the
//! layouts our users hold (GeMS/BAD-Gaussians/PRISM3D, COLMAP, LLFF, ExBluRF, nerfstudio).
//!
//! # Conventions
//! Poses are **world-to-camera** ([`gems_math::Pose`]: `x_cam = R·x_world + t`), OpenCV camera axes (x right,
//! y down, z forward), f64. Images in memory are [`ImageRgb`]: interleaved RGB `f32` in `[0, 1]`
//! (sRGB values as stored), row-major. Every error names the file at fault ([`DataError`]);
//! every writer is atomic (temp file + rename).
//!
//! # Entry points
//! - [`open_scene`] (or [`open_scene_undistorted`]) → [`Scene`] (views with split, intrinsics, poses, ground truth, SfM model,
//!   events) for any supported layout; [`scene_info`] summarises it (serde, for `gems info`).
//! - [`colmap`]: `read_model` / `write_model` (binary byte-exact, text).
//! - [`llff`]: `read_poses_bounds` / `write_poses_bounds`, `read_subframes` / `write_subframes`.
//! - [`nerfstudio`]: `read_transforms` / `write_transforms`.
//! - [`manifest`]: `gems_scene.json` and the `hold=<n>` marker (for scene generators).
//! - [`image`]: `load_image`, `save_png`, `downscale_area`, [`ImageCache`].
//! - [`undistort`]: undistortion maps for SIMPLE_RADIAL / RADIAL / OPENCV cameras.
//! - [`check`]: full validation of an opened scene (`gems info --check`, and before training).
//! - [`exif`]: focal length in pixels from photos' EXIF tags.
//!
//! Nothing here writes into a scene folder: copies go to a cache folder the caller names.
//!
//! Fuzz targets for the binary parsers live in `fuzz/` (its own workspace; see `fuzz/README.md`:
//! `RUSTC_BOOTSTRAP=1 cargo fuzz run colmap_images_bin`).

pub mod check;
pub mod colmap;
pub mod error;
pub mod events;
pub mod exif;
mod fsutil;
pub mod image;
pub mod info;
pub mod llff;
pub mod manifest;
pub mod nerfstudio;
mod npy;
pub mod scene;
pub mod undistort;
pub mod video;

pub use error::{DataError, FormatError, Result};
pub use image::{ImageCache, ImageRgb, load_image, save_png};
pub use info::{SceneInfo, scene_info};
pub use manifest::{Manifest, ManifestPoses, write_hold_marker, write_manifest};
pub use scene::{
    FileUse, Layout, OpenOptions, PoseSource, Scene, Split, View, cache_folder, open_scene,
    open_scene_undistorted,
};
