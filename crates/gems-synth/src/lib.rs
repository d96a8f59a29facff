//! `gems synth`: procedural extreme-blur scenes with perfect ground truth.
//!
//! The generator ray-casts (in f32) an analytic, procedurally textured world — a ground plane,
//! a back wall, boxes and spheres at several depths, with multi-scale solid textures (fBm value
//! noise, checkers, stripes, blobs), colour variation, sun + sky shading with hard shadows — from
//! `N` views on an arc facing the scene. Each view gets a smooth random camera motion inside its
//! exposure (a cubic Bézier curve in the camera's local (ω, t) tangent space, identity at
//! mid-exposure) whose size is calibrated so that scene points travel the requested number of
//! pixels. `S` sharp sub-frames along it are averaged into the blurry image, the mid-exposure
//! frame is the sharp ground truth, and gems-events' ESIM simulator turns the same (denser)
//! frames into events.
//!
//! # API
//! - [`generate`] / [`generate_with_progress`]`(config, out_dir)` write one scene folder in the
//!   GeMS layout (see [`generate`] for the files) atomically and return a [`SynthSummary`].
//! - [`generate_blur_levels`] writes the paper's blur-level study (`blur_01` … `blur_11`).
//! - [`SynthConfig::tiny`] / [`SynthConfig::small`] / [`SynthConfig::medium`] are the presets.
//! - [`SynthScene::new`] gives the in-memory ground truth without rendering anything: the
//!   [`World`] (ray-castable via [`World::intersect`] / [`World::radiance`]), [`gems_math::Intrinsics`],
//!   per-view [`ViewTruth`] (mid pose, exposure motion, depth bounds, blur), and renders of any view
//!   at any exposure fraction ([`SynthScene::render_sharp`], [`SynthScene::render_view`]).
//!
//! # Conventions
//! OpenCV cameras (x right, y down, z forward), world y up; pixel centres at (i + 0.5, j + 0.5).
//! The blurry image is the mean of **sRGB-encoded** sub-frames — exactly the GeMS/BAD-Gaussians
//! image-formation model — while events see linear luminance. Sub-frames sit at u = k/(S−1)
//! over the exposure, both ends included, like the trainer's virtual cameras. Everything is a pure
//! function of the config and its seed: files are byte-identical across runs and thread counts.

mod camera;
mod config;
mod generate;
mod geom;
mod render;
mod scene;
mod texture;
mod world;

use std::path::{Path, PathBuf};

pub use camera::{CameraPose, ExposureMotion, arc_path, mean_path_length_px};
pub use config::{EventOptions, Preset, SynthConfig};
pub use generate::{
    BLUR_LEVELS, SynthSummary, generate, generate_blur_levels, generate_with_progress, image_name,
};
pub use geom::V3;
pub use render::{Image, linear_to_srgb};
pub use scene::{SynthScene, ViewRender, ViewTruth, uniform_times};
pub use texture::Pattern;
pub use world::{Hit, Material, Object, Shape, World};

/// Everything that can go wrong generating a scene.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// A setting is out of range.
    #[error("invalid synth config: {0}")]
    Config(String),
    /// The output folder already holds files; the generator never overwrites a scene.
    #[error("{0}: output folder exists and is not empty")]
    OutputExists(PathBuf),
    /// A file-system operation failed.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// A PNG could not be written.
    #[error("{path}: {source}")]
    Image {
        path: PathBuf,
        source: image::ImageError,
    },
    /// A pose or model writer of gems-data failed.
    #[error(transparent)]
    Data(#[from] gems_data::DataError),
    /// The event simulator or writer failed.
    #[error(transparent)]
    Events(#[from] gems_events::EventError),
}

impl SynthError {
    fn io(path: &Path, source: std::io::Error) -> Self {
        SynthError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}
