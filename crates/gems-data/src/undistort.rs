//! Undistortion of images taken with COLMAP's distorted pinhole models (SIMPLE_RADIAL, RADIAL,
//! OPENCV) into the pinhole camera with the same focal lengths and principal point.
//!
//! For every output pixel centre the normalised ray `(x, y)` is distorted with the model's
//! forward equations and the input image is sampled bilinearly there (clamped at the borders).
//! The lookup map is built once per camera and image size ([`UndistortMap`]) and applied to any
//! number of images in parallel rows, so results do not depend on the thread count.

use rayon::prelude::*;

use crate::colmap::{Camera, CameraModel};
use crate::image::ImageRgb;
use gems_math::Intrinsics;

/// Applies the model's distortion to a normalised image point `(x, y)` (`z = 1`).
///
/// - SIMPLE_RADIAL `k`: `(x, y)·(1 + k r²)`
/// - RADIAL `k1, k2`: `(x, y)·(1 + k1 r² + k2 r⁴)`
/// - OPENCV `k1, k2, p1, p2`: radial as RADIAL plus tangential
///   `(2 p1 x y + p2 (r² + 2x²), p1 (r² + 2y²) + 2 p2 x y)`
///
/// Returns `None` for models without these equations or a parameter list of the wrong length.
pub fn distort_normalized(
    model: CameraModel,
    params: &[f64],
    x: f64,
    y: f64,
) -> Option<(f64, f64)> {
    if params.len() != model.num_params() {
        return None;
    }
    let r2 = x * x + y * y;
    let (radial, p1, p2) = match model {
        CameraModel::SimplePinhole | CameraModel::Pinhole => (0.0, 0.0, 0.0),
        CameraModel::SimpleRadial => (params[3] * r2, 0.0, 0.0),
        CameraModel::Radial => (params[3] * r2 + params[4] * r2 * r2, 0.0, 0.0),
        CameraModel::Opencv => (params[4] * r2 + params[5] * r2 * r2, params[6], params[7]),
        _ => return None,
    };
    Some((
        x * (1.0 + radial) + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
        y * (1.0 + radial) + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
    ))
}

/// Pinhole part `(fx, fy, cx, cy)` of a camera's parameters.
fn pinhole_params(cam: &Camera) -> Option<[f64; 4]> {
    let p = &cam.params;
    if p.len() != cam.model.num_params() {
        return None;
    }
    match cam.model {
        CameraModel::SimplePinhole | CameraModel::SimpleRadial | CameraModel::Radial => {
            Some([p[0], p[0], p[1], p[2]])
        }
        CameraModel::Pinhole | CameraModel::Opencv => Some([p[0], p[1], p[2], p[3]]),
        _ => None,
    }
}

/// A precomputed undistortion lookup for one camera at one image size.
#[derive(Debug)]
pub struct UndistortMap {
    width: u32,
    height: u32,
    /// Source pixel coordinates (pixel-index space, centre of pixel `i` at `i`) per output pixel.
    src: Vec<[f32; 2]>,
    intrinsics: Intrinsics,
}

impl UndistortMap {
    /// Builds the map for images of `width × height` taken with `cam` (its calibration is
    /// rescaled if the images are a resized copy). Errors for models other than
    /// SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL and OPENCV, or invalid parameters.
    pub fn new(cam: &Camera, width: u32, height: u32) -> Result<UndistortMap, String> {
        let [fx, fy, cx, cy] = pinhole_params(cam).ok_or_else(|| {
            format!(
                "camera {}: cannot undistort model {} with {} parameters (supported: \
                 SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV)",
                cam.id,
                cam.model.name(),
                cam.params.len()
            )
        })?;
        if cam.width == 0 || cam.height == 0 {
            return Err(format!("camera {} has size 0", cam.id));
        }
        let sx = f64::from(width) / cam.width as f64;
        let sy = f64::from(height) / cam.height as f64;
        let k = Intrinsics {
            fx: fx * sx,
            fy: fy * sy,
            cx: cx * sx,
            cy: cy * sy,
            width,
            height,
        };
        if ![k.fx, k.fy, k.cx, k.cy].iter().all(|v| v.is_finite()) || k.fx <= 0.0 || k.fy <= 0.0 {
            return Err(format!(
                "camera {} has invalid parameters {:?}",
                cam.id, cam.params
            ));
        }
        if !cam.params.iter().all(|v| v.is_finite()) {
            return Err(format!("camera {} has non-finite parameters", cam.id));
        }
        let mut src = vec![[0f32; 2]; width as usize * height as usize];
        src.par_chunks_mut(width as usize)
            .enumerate()
            .for_each(|(v, row)| {
                for (u, s) in row.iter_mut().enumerate() {
                    // COLMAP convention: pixel centres at +0.5.
                    let x = (u as f64 + 0.5 - k.cx) / k.fx;
                    let y = (v as f64 + 0.5 - k.cy) / k.fy;
                    let (xd, yd) = distort_normalized(cam.model, &cam.params, x, y)
                        .expect("model checked above");
                    *s = [
                        (k.fx * xd + k.cx - 0.5) as f32,
                        (k.fy * yd + k.cy - 0.5) as f32,
                    ];
                }
            });
        Ok(UndistortMap {
            width,
            height,
            src,
            intrinsics: k,
        })
    }

    /// The pinhole intrinsics of the undistorted images.
    pub fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    /// Undistorts one image (it must have the map's size).
    pub fn apply(&self, img: &ImageRgb) -> Result<ImageRgb, String> {
        if (img.width, img.height) != (self.width, self.height) {
            return Err(format!(
                "image is {}x{} but the undistortion map is for {}x{}",
                img.width, img.height, self.width, self.height
            ));
        }
        let (w, h) = (self.width as usize, self.height as usize);
        let mut out = ImageRgb::new(self.width, self.height);
        out.data
            .par_chunks_mut(w * 3)
            .zip(self.src.par_chunks(w))
            .for_each(|(row, srcs)| {
                for (px, &[sx, sy]) in row.chunks_exact_mut(3).zip(srcs) {
                    px.copy_from_slice(&bilinear_clamped(img, w, h, sx, sy));
                }
            });
        Ok(out)
    }
}

fn bilinear_clamped(img: &ImageRgb, w: usize, h: usize, x: f32, y: f32) -> [f32; 3] {
    let x = x.clamp(0.0, (w - 1) as f32);
    let y = y.clamp(0.0, (h - 1) as f32);
    let x0 = (x.floor() as usize).min(w - 1);
    let y0 = (y.floor() as usize).min(h - 1);
    let x1 = (x0 + 1).min(w - 1);
    let y1 = (y0 + 1).min(h - 1);
    let (ax, ay) = (x - x0 as f32, y - y0 as f32);
    let at = |xx: usize, yy: usize, c: usize| img.data[(yy * w + xx) * 3 + c];
    let mut out = [0f32; 3];
    for (c, o) in out.iter_mut().enumerate() {
        let top = at(x0, y0, c) * (1.0 - ax) + at(x1, y0, c) * ax;
        let bottom = at(x0, y1, c) * (1.0 - ax) + at(x1, y1, c) * ax;
        *o = top * (1.0 - ay) + bottom * ay;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth scene as a function of the normalised ray.
    fn scene(x: f64, y: f64) -> [f32; 3] {
        [
            (0.5 + 0.4 * (6.0 * x).sin()) as f32,
            (0.5 + 0.4 * (5.0 * y).cos()) as f32,
            (0.5 + 0.3 * (4.0 * (x + y)).sin()) as f32,
        ]
    }

    /// Inverts the distortion by fixed-point iteration (test-only oracle).
    fn undistort_point(cam: &Camera, xd: f64, yd: f64) -> (f64, f64) {
        let (mut x, mut y) = (xd, yd);
        for _ in 0..100 {
            let (dx, dy) = distort_normalized(cam.model, &cam.params, x, y).unwrap();
            x += xd - dx;
            y += yd - dy;
        }
        (x, y)
    }

    /// Renders what a distorted camera sees of `scene`.
    fn render_distorted(cam: &Camera) -> ImageRgb {
        let [fx, fy, cx, cy] = pinhole_params(cam).unwrap();
        let mut img = ImageRgb::new(cam.width as u32, cam.height as u32);
        for v in 0..cam.height as usize {
            for u in 0..cam.width as usize {
                let xd = (u as f64 + 0.5 - cx) / fx;
                let yd = (v as f64 + 0.5 - cy) / fy;
                let (x, y) = undistort_point(cam, xd, yd);
                let i = (v * cam.width as usize + u) * 3;
                img.data[i..i + 3].copy_from_slice(&scene(x, y));
            }
        }
        img
    }

    #[test]
    fn undistortion_recovers_the_pinhole_image() {
        for (model, params) in [
            (CameraModel::SimpleRadial, vec![80.0, 40.0, 30.0, -0.25]),
            (CameraModel::Radial, vec![80.0, 40.0, 30.0, 0.15, -0.05]),
            (
                CameraModel::Opencv,
                vec![80.0, 78.0, 41.0, 29.0, -0.2, 0.05, 0.01, -0.008],
            ),
        ] {
            let cam = Camera {
                id: 1,
                model,
                width: 80,
                height: 60,
                params,
            };
            let map = UndistortMap::new(&cam, 80, 60).unwrap();
            let out = map.apply(&render_distorted(&cam)).unwrap();
            let k = map.intrinsics();
            let mut max_err = 0f32;
            // Interior pixels (borders may sample outside the distorted image).
            for v in 6..54 {
                for u in 6..74 {
                    let x = (u as f64 + 0.5 - k.cx) / k.fx;
                    let y = (v as f64 + 0.5 - k.cy) / k.fy;
                    let want = scene(x, y);
                    let got = out.pixel(u, v);
                    for c in 0..3 {
                        max_err = max_err.max((want[c] - got[c]).abs());
                    }
                }
            }
            // Bilinear interpolation of a smooth signal sampled at ~1/13 of its period.
            assert!(max_err < 0.02, "{model:?}: max error {max_err}");
            // Without undistortion the error is much larger (the test can fail).
            let raw = render_distorted(&cam);
            let mut raw_err = 0f32;
            for v in 6..54 {
                for u in 6..74 {
                    let x = (u as f64 + 0.5 - k.cx) / k.fx;
                    let y = (v as f64 + 0.5 - k.cy) / k.fy;
                    raw_err = raw_err.max((scene(x, y)[0] - raw.pixel(u, v)[0]).abs());
                }
            }
            assert!(
                raw_err > 5.0 * max_err,
                "{model:?}: raw {raw_err} vs {max_err}"
            );
        }
    }

    #[test]
    fn zero_distortion_is_identity_and_resized_maps_scale() {
        let cam = Camera {
            id: 1,
            model: CameraModel::Opencv,
            width: 20,
            height: 10,
            params: vec![30.0, 30.0, 10.0, 5.0, 0.0, 0.0, 0.0, 0.0],
        };
        let mut img = ImageRgb::new(20, 10);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = (i % 7) as f32 / 7.0;
        }
        let map = UndistortMap::new(&cam, 20, 10).unwrap();
        assert_eq!(map.apply(&img).unwrap(), img);
        let half = UndistortMap::new(&cam, 10, 5).unwrap();
        assert_eq!(half.intrinsics().fx, 15.0);
        assert!(half.apply(&img).is_err());
        let fisheye = Camera {
            model: CameraModel::OpencvFisheye,
            ..cam
        };
        assert!(
            UndistortMap::new(&fisheye, 20, 10)
                .unwrap_err()
                .contains("OPENCV_FISHEYE")
        );
    }
}
