//! Antialiased ray-cast rendering of the [`World`] and the sRGB transfer function.

use crate::camera::CameraPose;
use crate::world::{World, pixel_jitter};
use gems_math::Intrinsics;
use rayon::prelude::*;

/// An RGB image, row-major, interleaved, f32 per channel.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub data: Vec<f32>,
}

impl Image {
    pub fn zeros(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            data: vec![0.0; 3 * width as usize * height as usize],
        }
    }

    /// Rounds to 8-bit RGB (values clamped to [0, 1]).
    pub fn to_rgb8(&self) -> Vec<u8> {
        self.data
            .iter()
            .map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect()
    }
}

/// sRGB opto-electronic transfer function (IEC 61966-2-1) of a linear value, clamped to [0, 1].
pub fn linear_to_srgb(v: f32) -> f32 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Renders linear RGB radiance with `spp` stratified, jittered samples per pixel (box filter).
/// The jitter of sample k at pixel (x, y) depends only on (x, y, k, `jitter_seed`), never on
/// the thread, so renders are bit-identical for any thread count.
pub fn render_linear(
    world: &World,
    k: &Intrinsics,
    pose: &CameraPose,
    spp: u32,
    jitter_seed: u32,
) -> Image {
    let mut img = Image::zeros(k.width, k.height);
    let spp = spp.max(1);
    // Stratified: the samples fill a cols × rows grid of sub-cells, one jittered sample per cell.
    let cols = f64::from(spp).sqrt().ceil() as u32;
    let rows = spp.div_ceil(cols);
    let inv = 1.0 / spp as f32;
    img.data
        .par_chunks_mut(3 * k.width as usize)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, px) in row.chunks_exact_mut(3).enumerate() {
                let mut acc = [0.0f32; 3];
                for s in 0..spp {
                    let (jx, jy) = pixel_jitter(x as u32, y as u32, s, jitter_seed);
                    let sx = (f64::from(s % cols) + f64::from(jx)) / f64::from(cols);
                    let sy = (f64::from(s / cols) + f64::from(jy)) / f64::from(rows);
                    let (o, d) = pose.ray(k, x as f64 + sx, y as f64 + sy);
                    let c = world.radiance(o, d);
                    acc[0] += c.x;
                    acc[1] += c.y;
                    acc[2] += c.z;
                }
                for (p, a) in px.iter_mut().zip(acc) {
                    *p = a * inv;
                }
            }
        });
    img
}

/// sRGB-encodes a linear image (the display values that the blur average and the PNGs use).
pub fn encode_srgb(img: &Image) -> Image {
    Image {
        width: img.width,
        height: img.height,
        data: img.data.par_iter().map(|&v| linear_to_srgb(v)).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_curve_matches_the_standard() {
        assert_eq!(linear_to_srgb(0.0), 0.0);
        assert!((linear_to_srgb(1.0) - 1.0).abs() < 1e-6);
        // 18% grey encodes to ≈ 0.4614 (118/255).
        assert!((linear_to_srgb(0.18) - 0.4614).abs() < 1e-3);
        // Continuous at the knee.
        assert!((linear_to_srgb(0.003_130_8) - linear_to_srgb(0.003_130_9)).abs() < 3e-6);
        assert!(
            (linear_to_srgb(2.0) - 1.0).abs() < 1e-6,
            "saturates at white"
        );
    }
}
