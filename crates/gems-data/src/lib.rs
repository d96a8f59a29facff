//! The scene data layer of gems: views, splits, intrinsics, poses and sparse models read from the
//! layouts our users hold (GeMS/BAD-Gaussians/PRISM3D, COLMAP, LLFF, ExBluRF, nerfstudio).
//!
//! Conventions used everywhere: poses are **world-to-camera** ([`Pose`]), OpenCV camera axes
//! (x right, y down, z forward), f64.

pub mod colmap;
pub mod error;
mod fsutil;
pub mod image;
pub mod llff;
mod npy;
pub mod pose;

pub use error::{DataError, FormatError, Result};
pub use fsutil::write_atomic;
pub use image::{ImageCache, ImageRgb, load_image, save_png};
pub use pose::{Intrinsics, Pose};
