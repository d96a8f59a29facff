//! The focal length in pixels from a photo's EXIF tags, for the SfM (which otherwise estimates it
//! from blurry images, a few percent off).
//!
//! Two ways, in this order (EXIF 2.32, CIPA DC-008):
//! 1. `FocalLength` (mm) × `FocalPlaneXResolution` (pixels per `FocalPlaneResolutionUnit`: 2 inch,
//!    the default, 3 cm; 4 mm and 5 µm as TIFF/EP and exiftool read them) — the physical focal on
//!    the sensor, exact when the camera writes it. The
//!    resolution refers to the original pixel grid (`PixelXDimension`), so the result is scaled
//!    to the file's actual width when it was resized.
//! 2. `FocalLengthIn35mmFilm`: the focal of a 36 × 24 mm frame with the same field of view, so
//!    `f_px = f35 / 36 · long side` (phones write only this one).

use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::scene::Scene;

/// A focal length and where it came from (shown by `gems info`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FocalSource {
    /// Focal in pixels at the image's size.
    pub focal_px: f64,
    /// The image whose EXIF gave it.
    pub image: PathBuf,
    /// Which tags, e.g. "EXIF FocalLength 4.2 mm × FocalPlaneXResolution".
    pub source: String,
}

fn rational(exif: &exif::Exif, tag: exif::Tag) -> Option<f64> {
    match &exif.get_field(tag, exif::In::PRIMARY)?.value {
        exif::Value::Rational(v) => v.first().map(exif::Rational::to_f64),
        exif::Value::SRational(v) => v.first().map(exif::SRational::to_f64),
        other => other.get_uint(0).map(f64::from),
    }
    .filter(|v| v.is_finite() && *v > 0.0)
}

fn uint(exif: &exif::Exif, tag: exif::Tag) -> Option<u32> {
    exif.get_field(tag, exif::In::PRIMARY)?.value.get_uint(0)
}

/// The focal in pixels of the photo at `path` (whose pixel size is `width × height`), or `None`
/// when it carries no usable EXIF focal.
pub fn focal_from_exif(path: &Path, width: u32, height: u32) -> Option<FocalSource> {
    let file = std::fs::File::open(path).ok()?;
    let exif = exif::Reader::new()
        .read_from_container(&mut std::io::BufReader::new(file))
        .ok()?;
    let long = f64::from(width.max(height));
    if let (Some(f_mm), Some(res)) = (
        rational(&exif, exif::Tag::FocalLength),
        rational(&exif, exif::Tag::FocalPlaneXResolution),
    ) {
        let mm_per_unit = match uint(&exif, exif::Tag::FocalPlaneResolutionUnit).unwrap_or(2) {
            3 => Some(10.0),
            4 => Some(1.0),
            5 => Some(1e-3),
            2 => Some(25.4),
            _ => None,
        };
        if let Some(mm) = mm_per_unit {
            let at_original = f_mm * res / mm;
            let scale = uint(&exif, exif::Tag::PixelXDimension)
                .filter(|&w| w > 0)
                .map_or(1.0, |w| f64::from(width) / f64::from(w));
            return Some(FocalSource {
                focal_px: at_original * scale,
                image: path.to_path_buf(),
                source: format!(
                    "EXIF FocalLength {f_mm} mm × FocalPlaneXResolution {res} px per {mm} mm"
                ),
            });
        }
    }
    let f35 = uint(&exif, exif::Tag::FocalLengthIn35mmFilm).filter(|&f| f > 0)?;
    Some(FocalSource {
        focal_px: f64::from(f35) / 36.0 * long,
        image: path.to_path_buf(),
        source: format!("EXIF FocalLengthIn35mmFilm {f35} mm (36 mm frame width)"),
    })
}

/// The EXIF focal of the first photo in `dir` (a scene folder with `images/`, or a folder of
/// photos) that has one, at that photo's full size: what the SfM on that folder should use.
pub fn folder_focal(dir: &Path) -> Option<FocalSource> {
    let img_dir = gems_fs::image_folder(dir);
    gems_fs::list_images(&img_dir).ok()?.iter().find_map(|p| {
        let (w, h) = crate::image::image_dimensions(p).ok()?;
        focal_from_exif(p, w, h)
    })
}

/// The EXIF focal for the SfM on `scene`'s full-resolution images (see [`folder_focal`]).
pub fn scene_focal(scene: &Scene) -> Option<FocalSource> {
    folder_focal(&scene.root)
}
