//! Images in memory: interleaved RGB `f32` in `[0, 1]` (sRGB values exactly as stored, no
//! linearisation), row-major `[height][width][3]`.
//!
//! [`load_image`] decodes PNG/JPEG (8 or 16 bit), [`save_png`] writes atomically,
//! [`downscale_area`] is an exact area (box) filter for any output size, and [`ImageCache`] loads
//! lazily and keeps recently used images up to a byte budget.

use std::collections::{HashMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use rayon::prelude::*;

use crate::error::{DataError, Result};

/// An RGB image, interleaved `f32` in `[0, 1]`; `data.len() == width * height * 3`.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageRgb {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Interleaved RGB, row-major.
    pub data: Vec<f32>,
}

impl ImageRgb {
    /// A black image.
    pub fn new(width: u32, height: u32) -> ImageRgb {
        ImageRgb {
            width,
            height,
            data: vec![0.0; width as usize * height as usize * 3],
        }
    }

    /// The RGB value at `(x, y)`.
    pub fn pixel(&self, x: u32, y: u32) -> [f32; 3] {
        let i = (y as usize * self.width as usize + x as usize) * 3;
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }

    /// Size of the pixel buffer in bytes.
    pub fn byte_size(&self) -> usize {
        self.data.len() * size_of::<f32>()
    }

    /// 8-bit copy, or `None` when `data` does not have `width * height * 3` values.
    fn to_rgb8(&self) -> Option<image::RgbImage> {
        let bytes = self
            .data
            .iter()
            .map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect();
        image::RgbImage::from_raw(self.width, self.height, bytes)
            .filter(|img| img.as_raw().len() == self.data.len())
    }
}

/// Width and height of an image file from its header (no pixel decoding).
pub fn image_dimensions(path: &Path) -> Result<(u32, u32)> {
    image::image_dimensions(path).map_err(|e| image_error(path, e))
}

fn image_error(path: &Path, e: image::ImageError) -> DataError {
    match e {
        image::ImageError::IoError(source) => DataError::io(path, source),
        source => DataError::Image {
            path: path.to_path_buf(),
            source,
        },
    }
}

/// Decodes a PNG or JPEG file into RGB `f32` in `[0, 1]` (grey and alpha are converted; values
/// are divided by the bit depth's maximum, no colour-space conversion).
pub fn load_image(path: &Path) -> Result<ImageRgb> {
    let img = image::ImageReader::open(path)
        .map_err(|e| DataError::io(path, e))?
        .with_guessed_format()
        .map_err(|e| DataError::io(path, e))?
        .decode()
        .map_err(|e| image_error(path, e))?;
    let rgb = img.into_rgb32f();
    Ok(ImageRgb {
        width: rgb.width(),
        height: rgb.height(),
        data: rgb.into_raw(),
    })
}

/// Writes an 8-bit PNG atomically (values clamped to `[0, 1]`, rounded to the nearest level).
pub fn save_png(path: &Path, img: &ImageRgb) -> Result<()> {
    save_image(path, img, image::ImageFormat::Png)
}

/// Writes an 8-bit image in `format` atomically (JPEG at quality 95).
fn save_image(path: &Path, img: &ImageRgb, format: image::ImageFormat) -> Result<()> {
    let rgb = img.to_rgb8().ok_or_else(|| {
        DataError::format(
            path,
            format!(
                "cannot write: image buffer holds {} values, {}x{}x3 expected",
                img.data.len(),
                img.width,
                img.height
            ),
        )
    })?;
    let mut buf = std::io::Cursor::new(Vec::new());
    match format {
        image::ImageFormat::Jpeg => {
            let enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut buf, 95);
            rgb.write_with_encoder(enc)
        }
        _ => rgb.write_to(&mut buf, format),
    }
    .map_err(|e| image_error(path, e))?;
    Ok(gems_fs::write_atomic(path, buf.get_ref())?)
}

/// Writes `img` in the format given by the extension of `path` (png, jpg/jpeg).
pub fn save_image_auto(path: &Path, img: &ImageRgb) -> Result<()> {
    let format = image::ImageFormat::from_path(path).map_err(|e| image_error(path, e))?;
    save_image(path, img, format)
}

/// Per output sample along one axis: the source range and the fraction of each source pixel
/// that falls inside the output pixel's footprint `[o·s/d, (o+1)·s/d)`.
struct AxisWeights {
    /// First source index of output sample `o`.
    first_src: Vec<usize>,
    /// `weights[offsets[o]..offsets[o + 1]]` are the weights of sources `first_src[o]..`.
    offsets: Vec<usize>,
    weights: Vec<f32>,
}

impl AxisWeights {
    fn new(src: usize, dst: usize) -> AxisWeights {
        let scale = src as f64 / dst as f64;
        let mut first_src = Vec::with_capacity(dst);
        let mut offsets = Vec::with_capacity(dst + 1);
        let mut weights = Vec::new();
        offsets.push(0);
        for o in 0..dst {
            let a = o as f64 * scale;
            let b = ((o + 1) as f64 * scale).min(src as f64);
            let i0 = a.floor() as usize;
            let i1 = (b.ceil() as usize).min(src);
            first_src.push(i0);
            for i in i0..i1 {
                let overlap = (b.min((i + 1) as f64) - a.max(i as f64)).max(0.0);
                weights.push((overlap / (b - a)) as f32);
            }
            offsets.push(weights.len());
        }
        AxisWeights {
            first_src,
            offsets,
            weights,
        }
    }

    fn taps(&self, o: usize) -> (usize, &[f32]) {
        (
            self.first_src[o],
            &self.weights[self.offsets[o]..self.offsets[o + 1]],
        )
    }
}

/// Area-filter resize to `width × height` (each output pixel is the exact average of the source
/// area it covers, so an integer factor is a plain box average). Rows are processed in parallel;
/// the result does not depend on the thread count.
pub fn downscale_area(img: &ImageRgb, width: u32, height: u32) -> ImageRgb {
    let (sw, sh) = (img.width as usize, img.height as usize);
    let (dw, dh) = (width as usize, height as usize);
    let wx = AxisWeights::new(sw, dw);
    let wy = AxisWeights::new(sh, dh);
    let mut out = ImageRgb::new(width, height);
    out.data.par_chunks_mut(dw * 3).enumerate().for_each_init(
        || vec![0f32; sw * 3],
        |row_acc, (oy, out_row)| {
            // Vertical pass into one accumulated source row, then horizontal pass.
            row_acc.fill(0.0);
            let (y0, ky) = wy.taps(oy);
            for (k, &w) in ky.iter().enumerate() {
                let src = &img.data[(y0 + k) * sw * 3..(y0 + k + 1) * sw * 3];
                for (a, &s) in row_acc.iter_mut().zip(src) {
                    *a += w * s;
                }
            }
            for (ox, px) in out_row.chunks_exact_mut(3).enumerate() {
                let (x0, kx) = wx.taps(ox);
                let mut acc = [0f32; 3];
                for (k, &w) in kx.iter().enumerate() {
                    let s = &row_acc[(x0 + k) * 3..(x0 + k) * 3 + 3];
                    acc[0] += w * s[0];
                    acc[1] += w * s[1];
                    acc[2] += w * s[2];
                }
                px.copy_from_slice(&acc);
            }
        },
    );
    out
}

/// The size of a copy downscaled by `factor`: `floor(size / factor)`, at least 1 (the rounding
/// used by the LLFF/nerfstudio tools that made `images_<f>` folders).
pub fn downscaled_size(width: u32, height: u32, factor: u32) -> (u32, u32) {
    let f = factor.max(1);
    ((width / f).max(1), (height / f).max(1))
}

/// A thread-safe lazy image loader that keeps decoded images up to `capacity_bytes`, evicting
/// the least recently inserted first. Clones of the returned `Arc` stay valid after eviction.
pub struct ImageCache {
    capacity_bytes: usize,
    inner: Mutex<CacheInner>,
}

#[derive(Default)]
struct CacheInner {
    map: HashMap<PathBuf, Arc<ImageRgb>>,
    order: VecDeque<PathBuf>,
    bytes: usize,
}

impl ImageCache {
    /// A cache holding at most `capacity_bytes` of decoded pixels (one image larger than the
    /// budget is still returned, just not kept).
    pub fn new(capacity_bytes: usize) -> ImageCache {
        ImageCache {
            capacity_bytes,
            inner: Mutex::new(CacheInner::default()),
        }
    }

    /// The decoded image at `path`, from the cache or loaded now.
    pub fn get(&self, path: &Path) -> Result<Arc<ImageRgb>> {
        if let Some(img) = self.lock().map.get(path) {
            return Ok(Arc::clone(img));
        }
        // Decode outside the lock so other threads can hit the cache meanwhile; two threads
        // racing on the same miss both decode, and the first insert wins.
        let img = Arc::new(load_image(path)?);
        let size = img.byte_size();
        let mut inner = self.lock();
        if let Some(existing) = inner.map.get(path) {
            return Ok(Arc::clone(existing));
        }
        if size <= self.capacity_bytes {
            while inner.bytes + size > self.capacity_bytes {
                let Some(old) = inner.order.pop_front() else {
                    break;
                };
                if let Some(o) = inner.map.remove(&old) {
                    inner.bytes -= o.byte_size();
                }
            }
            inner.map.insert(path.to_path_buf(), Arc::clone(&img));
            inner.order.push_back(path.to_path_buf());
            inner.bytes += size;
        }
        Ok(img)
    }

    /// Number of images currently cached.
    pub fn len(&self) -> usize {
        self.lock().map.len()
    }

    /// True when nothing is cached.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, CacheInner> {
        // A panic while holding the lock cannot leave the map inconsistent with `bytes` in a way
        // that matters for correctness of returned images, so recover from poisoning.
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn ramp(w: u32, h: u32) -> ImageRgb {
        let mut img = ImageRgb::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let i = ((y * w + x) * 3) as usize;
                img.data[i] = x as f32 / w as f32;
                img.data[i + 1] = y as f32 / h as f32;
                img.data[i + 2] = ((x * 7 + y * 13) % 17) as f32 / 16.0;
            }
        }
        img
    }

    #[test]
    fn integer_factor_is_box_average() {
        let img = ramp(6, 4);
        let d = downscale_area(&img, 3, 2);
        for oy in 0..2 {
            for ox in 0..3 {
                for c in 0..3 {
                    let mut s = 0.0;
                    for dy in 0..2 {
                        for dx in 0..2 {
                            s += img.pixel(ox * 2 + dx, oy * 2 + dy)[c];
                        }
                    }
                    assert!((d.pixel(ox, oy)[c] - s / 4.0).abs() < 1e-6);
                }
            }
        }
    }

    proptest! {
        /// Area filtering preserves the mean of the image for any (also fractional) ratio, and
        /// keeps values inside the input range.
        #[test]
        fn area_filter_preserves_mean(w in 1u32..20, h in 1u32..20, dw in 1u32..20, dh in 1u32..20) {
            let img = ramp(w, h);
            let d = downscale_area(&img, dw, dh);
            for c in 0..3 {
                let m0: f64 = img.data.iter().skip(c).step_by(3).map(|&v| v as f64).sum::<f64>() / (w * h) as f64;
                let m1: f64 = d.data.iter().skip(c).step_by(3).map(|&v| v as f64).sum::<f64>() / (dw * dh) as f64;
                prop_assert!((m0 - m1).abs() < 1e-5, "channel {c}: {m0} vs {m1}");
            }
            prop_assert!(d.data.iter().all(|&v| (-1e-6..=1.0 + 1e-6).contains(&v)));
        }
    }

    #[test]
    fn png_round_trip_and_cache() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.png");
        let mut img = ramp(5, 3);
        for v in &mut img.data {
            *v = (*v * 255.0).round() / 255.0;
        }
        save_png(&p, &img).unwrap();
        assert_eq!(image_dimensions(&p).unwrap(), (5, 3));
        let back = load_image(&p).unwrap();
        assert_eq!(back.width, 5);
        for (a, b) in back.data.iter().zip(&img.data) {
            assert!((a - b).abs() < 1e-6);
        }
        let cache = ImageCache::new(back.byte_size());
        let a = cache.get(&p).unwrap();
        let b = cache.get(&p).unwrap();
        assert!(Arc::ptr_eq(&a, &b), "second get must hit the cache");
        let q = dir.path().join("b.png");
        save_png(&q, &img).unwrap();
        cache.get(&q).unwrap();
        assert_eq!(cache.len(), 1, "budget of one image evicts the older one");
        let e = cache
            .get(&dir.path().join("missing.png"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing.png"), "{e}");
        let broken = ImageRgb {
            width: 4,
            height: 4,
            data: vec![0.0; 5],
        };
        let e = save_png(&dir.path().join("broken.png"), &broken)
            .unwrap_err()
            .to_string();
        assert!(e.contains("broken.png") && e.contains("5 values"), "{e}");
        assert!(!dir.path().join("broken.png").exists());
        std::fs::write(dir.path().join("bad.png"), b"\x89PNG\r\n\x1a\nnope").unwrap();
        let e = load_image(&dir.path().join("bad.png"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("bad.png"), "{e}");
    }
}
