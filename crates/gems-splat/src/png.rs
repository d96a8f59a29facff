//! Writing a rendered view as PNG.

use std::path::Path;

use crate::{RenderOutput, SplatError};

/// Writes camera `camera` of `out` as an 8-bit RGB PNG (values clamped to [0, 1], rounded),
/// atomically (`gems_fs::write_atomic_with`: a temporary file in the same directory is renamed
/// over `path`).
pub fn write_png(
    path: impl AsRef<Path>,
    out: &RenderOutput,
    camera: usize,
) -> Result<(), SplatError> {
    let path = path.as_ref();
    let err = |reason: String| SplatError::Image {
        path: path.to_path_buf(),
        reason,
    };
    if camera >= out.num_cameras {
        return Err(err(format!(
            "camera {camera} requested but the render has {}",
            out.num_cameras
        )));
    }
    let (w, h) = (out.width as usize, out.height as usize);
    let px = &out.rgb[camera * w * h * 3..(camera + 1) * w * h * 3];
    let bytes: Vec<u8> = px
        .iter()
        .map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    let img = image::RgbImage::from_raw(out.width, out.height, bytes)
        .ok_or_else(|| err("image buffer has the wrong size".into()))?;
    gems_fs::write_atomic_with(path, |w| {
        img.write_to(w, image::ImageFormat::Png)
            .map_err(std::io::Error::other)
    })
    .map_err(|e| SplatError::Image {
        path: e.path,
        reason: e.source.to_string(),
    })
}
