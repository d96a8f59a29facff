//! From the working-level reconstruction to full-resolution results, and the files written for
//! users: COLMAP `sparse/0`, `sfm_report.json` and `sfm_topview.png`.

use super::ba::Pinhole;
use super::incremental::Recon;
use super::{SfmCamera, SfmError, SfmImage, SfmPoint, SfmResult, SfmStats, SfmView};
use gems_data::colmap::{
    self, Camera, CameraModel, Image, ModelFormat, Point2D, Point3D, SparseModel,
};
use gems_math::camera_center_from_w2c;
use nalgebra::{Vector2, Vector3};
use std::path::Path;

/// Bilinear RGB sample at continuous full-resolution coordinates.
fn sample_rgb(img: &image::RgbImage, x: f64, y: f64) -> [f64; 3] {
    let (w, h) = (img.width() as f64, img.height() as f64);
    let fx = (x - 0.5).clamp(0.0, w - 1.0);
    let fy = (y - 0.5).clamp(0.0, h - 1.0);
    let (x0, y0) = (fx.floor() as u32, fy.floor() as u32);
    let (x1, y1) = (
        (x0 + 1).min(img.width() - 1),
        (y0 + 1).min(img.height() - 1),
    );
    let (ax, ay) = (fx - x0 as f64, fy - y0 as f64);
    let mut out = [0.0; 3];
    for (c, o) in out.iter_mut().enumerate() {
        let p = |x: u32, y: u32| img.get_pixel(x, y)[c] as f64;
        *o = (p(x0, y0) * (1.0 - ax) + p(x1, y0) * ax) * (1.0 - ay)
            + (p(x0, y1) * (1.0 - ax) + p(x1, y1) * ax) * ay;
    }
    out
}

/// Scale the working-level reconstruction up to full resolution and collect the diagnostics.
pub(crate) fn assemble(
    images: &[SfmImage],
    rec: &Recon,
    scale: f64,
    focal_from_metadata: bool,
    working_size: u32,
) -> SfmResult {
    let (w, h) = images[0].image.dimensions();
    let camera = SfmCamera {
        width: w,
        height: h,
        focal: rec.k.fx / scale,
        cx: rec.k.cx / scale,
        cy: rec.k.cy / scale,
    };
    let mut views: Vec<SfmView> = images
        .iter()
        .zip(&rec.poses)
        .map(|(im, p)| SfmView {
            name: im.name.clone(),
            pose: *p,
            observations: Vec::new(),
        })
        .collect();
    let mut points = Vec::new();
    let (mut err_sum, mut err_n) = (0.0, 0usize);
    // Per view: the sum and count of its observations' reprojection errors.
    let mut per_view = vec![(0.0f64, 0usize); views.len()];
    for t in &rec.tracks {
        let Some(x) = t.xyz else { continue };
        let used: Vec<_> = t
            .obs
            .iter()
            .filter(|o| o.active && rec.poses[o.view].is_some())
            .collect();
        if used.len() < 2 {
            continue;
        }
        let pid = points.len();
        let mut track = Vec::with_capacity(used.len());
        let mut rgb = [0.0; 3];
        let mut perr = 0.0;
        for o in &used {
            let full = o.xy / scale;
            let pose = rec.poses[o.view].expect("registered");
            let e = (rec.k.project(&pose.act(&x)) - o.xy).norm() / scale;
            perr += e;
            per_view[o.view].0 += e;
            per_view[o.view].1 += 1;
            let c = sample_rgb(&images[o.view].image, full.x, full.y);
            for k in 0..3 {
                rgb[k] += c[k];
            }
            track.push((o.view, views[o.view].observations.len()));
            views[o.view].observations.push(([full.x, full.y], pid));
        }
        err_sum += perr;
        err_n += used.len();
        let n = used.len() as f64;
        points.push(SfmPoint {
            xyz: [x.x, x.y, x.z],
            rgb: rgb.map(|c| (c / n).round().clamp(0.0, 255.0) as u8),
            error: perr / n,
            track,
        });
    }
    let registered = views.iter().filter(|v| v.pose.is_some()).count();
    let unregistered = views
        .iter()
        .filter(|v| v.pose.is_none())
        .map(|v| v.name.clone())
        .collect();
    let stats = SfmStats {
        registered,
        total: views.len(),
        points: points.len(),
        mean_reprojection_error: if err_n > 0 {
            err_sum / err_n as f64
        } else {
            0.0
        },
        mean_track_length: if points.is_empty() {
            0.0
        } else {
            err_n as f64 / points.len() as f64
        },
        seconds: 0.0,
        unregistered,
        working_size,
        final_size: working_size,
        focal: camera.focal,
        focal_from_metadata,
        // Set by `run_sfm`, which knows the blur.
        focal_barely_determined: false,
        seconds_features: 0.0,
        seconds_reconstruction: 0.0,
        blur_px_estimate: 0.0,
        capture_order: false,
        views: views
            .iter()
            .zip(&per_view)
            .map(|(v, &(sum, n))| super::ViewReport {
                name: v.name.clone(),
                registered: v.pose.is_some(),
                blur_px: 0.0,
                points: n,
                reprojection_error_px: (n > 0).then(|| sum / n as f64),
                why_not: None,
            })
            .collect(),
        advice: Vec::new(),
    };
    SfmResult {
        camera,
        views,
        points,
        stats,
    }
}

/// The result as a COLMAP model: one SIMPLE_PINHOLE camera (id 1), registered images with id =
/// input index + 1, points with ids from 1.
pub fn to_colmap_model(r: &SfmResult) -> SparseModel {
    let cameras = vec![Camera {
        id: 1,
        model: CameraModel::SimplePinhole,
        width: r.camera.width as u64,
        height: r.camera.height as u64,
        params: vec![r.camera.focal, r.camera.cx, r.camera.cy],
    }];
    let images = r
        .views
        .iter()
        .enumerate()
        .filter_map(|(i, v)| {
            let p = v.pose?;
            let pose = gems_math::Pose::from(&p);
            let mut im = Image::from_pose(i as u32 + 1, 1, &v.name, &pose);
            im.points2d = v
                .observations
                .iter()
                .map(|&(xy, pid)| Point2D {
                    x: xy[0],
                    y: xy[1],
                    point3d_id: pid as u64 + 1,
                })
                .collect();
            Some(im)
        })
        .collect();
    let points = r
        .points
        .iter()
        .enumerate()
        .map(|(i, p)| Point3D {
            id: i as u64 + 1,
            xyz: p.xyz,
            rgb: p.rgb,
            error: p.error,
            track: p
                .track
                .iter()
                .map(|&(v, o)| (v as u32 + 1, o as u32))
                .collect(),
        })
        .collect();
    SparseModel {
        cameras,
        images,
        points,
    }
}

/// Top view of cameras (red, with a viewing-direction tick) and points (their colour): the
/// points and centres are projected onto the plane orthogonal to the cameras' mean "up" axis.
pub fn draw_top_view(r: &SfmResult, size: u32) -> image::RgbImage {
    let mut img = image::RgbImage::from_pixel(size, size, image::Rgb([255, 255, 255]));
    let poses: Vec<_> = r.views.iter().filter_map(|v| v.pose).collect();
    if poses.is_empty() {
        return img;
    }
    // Up = mean of −y camera axes in the world; two in-plane axes from the mean viewing direction.
    let mut up = Vector3::zeros();
    let mut fwd = Vector3::zeros();
    for p in &poses {
        let rt = p.rot.transpose();
        up -= rt * Vector3::y();
        fwd += rt * Vector3::z();
    }
    let up = up.try_normalize(1e-12).unwrap_or(Vector3::y());
    let mut ax2 = fwd - up * fwd.dot(&up);
    ax2 = ax2
        .try_normalize(1e-12)
        .unwrap_or_else(|| up.cross(&Vector3::x()).normalize());
    let ax1 = ax2.cross(&up);
    let proj = |x: &Vector3<f64>| Vector2::new(x.dot(&ax1), -x.dot(&ax2));
    let centres: Vec<Vector2<f64>> = poses
        .iter()
        .map(|p| proj(&camera_center_from_w2c(p)))
        .collect();
    let pts: Vec<(Vector2<f64>, [u8; 3])> = r
        .points
        .iter()
        .map(|p| (proj(&Vector3::new(p.xyz[0], p.xyz[1], p.xyz[2])), p.rgb))
        .collect();
    // Extent: all camera centres plus the 2nd–98th percentile of the points, so that stray
    // points do not shrink the plot and the cameras are always inside it.
    let mut xs: Vec<f64> = pts.iter().map(|p| p.0.x).collect();
    let mut ys: Vec<f64> = pts.iter().map(|p| p.0.y).collect();
    xs.sort_by(|a, b| a.total_cmp(b));
    ys.sort_by(|a, b| a.total_cmp(b));
    let q = |v: &[f64], f: f64| {
        v.get(((v.len().max(1) - 1) as f64 * f).round() as usize)
            .copied()
    };
    let fold = |init: Option<f64>, f: fn(f64, f64) -> f64, vals: &mut dyn Iterator<Item = f64>| {
        vals.fold(init, |acc, v| Some(acc.map_or(v, |a| f(a, v))))
    };
    let x0 = fold(q(&xs, 0.02), f64::min, &mut centres.iter().map(|c| c.x)).unwrap_or(0.0);
    let x1 = fold(q(&xs, 0.98), f64::max, &mut centres.iter().map(|c| c.x)).unwrap_or(0.0);
    let y0 = fold(q(&ys, 0.02), f64::min, &mut centres.iter().map(|c| c.y)).unwrap_or(0.0);
    let y1 = fold(q(&ys, 0.98), f64::max, &mut centres.iter().map(|c| c.y)).unwrap_or(0.0);
    let cx = 0.5 * (x0 + x1);
    let cy = 0.5 * (y0 + y1);
    let span = (x1 - x0).max(y1 - y0).max(1e-9) * 1.1;
    let s = size as f64;
    let to_px = |p: &Vector2<f64>| {
        (
            (p.x - cx) / span * s + 0.5 * s,
            (p.y - cy) / span * s + 0.5 * s,
        )
    };
    let put = |x: f64, y: f64, c: [u8; 3], img: &mut image::RgbImage| {
        if x >= 0.0 && y >= 0.0 && x < s && y < s {
            img.put_pixel(x as u32, y as u32, image::Rgb(c));
        }
    };
    for (p, c) in &pts {
        let (x, y) = to_px(p);
        for (dx, dy) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
            put(x + dx, y + dy, *c, &mut img);
        }
    }
    for (p, c) in poses.iter().zip(&centres) {
        let (x, y) = to_px(c);
        let dir = proj(&(camera_center_from_w2c(p) + p.rot.transpose() * Vector3::z())) - c;
        let dir = dir.try_normalize(1e-12).unwrap_or(Vector2::zeros());
        for k in 0..14 {
            put(
                x + dir.x * k as f64,
                y + dir.y * k as f64,
                [0, 0, 200],
                &mut img,
            );
        }
        for dy in -3..=3 {
            for dx in -3..=3 {
                put(x + dx as f64, y + dy as f64, [220, 0, 0], &mut img);
            }
        }
    }
    img
}

/// The per-photo registration report [`write_outputs`] puts beside `sparse/`.
pub const REPORT_FILE: &str = "sfm_report.json";

/// Whether the COLMAP model folder `model` is one [`write_outputs`] wrote: `<out>/sparse/0` with
/// `<out>/sfm_report.json` beside it.
pub fn is_builtin_model(model: &Path) -> bool {
    model.ends_with(Path::new("sparse").join("0"))
        && model
            .parent()
            .and_then(Path::parent)
            .is_some_and(|out| out.join(REPORT_FILE).is_file())
}

/// Write `out_dir/sparse/0` (COLMAP binary), `out_dir/sfm_report.json` and
/// `out_dir/sfm_topview.png`. Every file is written atomically.
pub fn write_outputs(r: &SfmResult, out_dir: &Path) -> Result<(), SfmError> {
    let sparse = out_dir.join("sparse").join("0");
    colmap::write_model(&sparse, &to_colmap_model(r), ModelFormat::Binary)?;
    let report = out_dir.join(REPORT_FILE);
    let json = serde_json::to_vec_pretty(&r.stats).map_err(|e| SfmError::Write {
        path: report.clone(),
        source: Box::new(e),
    })?;
    gems_fs::write_atomic(&report, &json).map_err(SfmError::write)?;
    let png_path = out_dir.join("sfm_topview.png");
    let img = draw_top_view(r, 800);
    let mut bytes = Vec::new();
    img.write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )
    .map_err(|e| SfmError::Write {
        path: png_path.clone(),
        source: Box::new(e),
    })?;
    gems_fs::write_atomic(&png_path, &bytes).map_err(SfmError::write)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_model_is_the_built_in_sfms_when_its_report_is_beside_it() {
        let dir = tempfile::tempdir().unwrap();
        let model = dir.path().join("sfm").join("sparse").join("0");
        std::fs::create_dir_all(&model).unwrap();
        assert!(!is_builtin_model(&model), "no report yet");
        std::fs::write(dir.path().join("sfm").join(REPORT_FILE), "{}").unwrap();
        assert!(is_builtin_model(&model));
        assert!(!is_builtin_model(&dir.path().join("sfm").join("sparse")));
    }
}
