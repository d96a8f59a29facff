//! Camera paths for a fly-through video of a trained result: the training path smoothed, or an
//! orbit around the scene. Poses are camera-to-world in the result's normalised frame (what the
//! renderer takes), OpenCV axes.

use gems_math::{Se3, Vector3, Vector6};
use gems_train::TrainOutput;

/// The trained mid-exposure cameras in the order of their photos' names (the capture order of
/// numbered photos and video frames), each replaced by the mean, in the tangent space around
/// it, of its neighbours within `window` on either side (a moving average that keeps the path's
/// ends), then `frames` poses interpolated along it at constant parameter speed (geodesics
/// between consecutive cameras). At least two views are needed.
pub fn training_path(output: &TrainOutput, frames: usize, window: usize) -> Option<Vec<Se3>> {
    let mut order: Vec<usize> = (0..output.views.len()).collect();
    order.sort_by(|&a, &b| output.views[a].name.cmp(&output.views[b].name));
    let poses: Vec<Se3> = order
        .iter()
        .map(|&i| Se3::from(&output.views[i].mid_c2w))
        .collect();
    if poses.len() < 2 || frames == 0 {
        return None;
    }
    let smoothed: Vec<Se3> = (0..poses.len())
        .map(|i| {
            let lo = i.saturating_sub(window);
            let hi = (i + window).min(poses.len() - 1);
            let inv = poses[i].inverse();
            let mean = (lo..=hi).fold(Vector6::zeros(), |acc, j| acc + (inv * poses[j]).log())
                / (hi - lo + 1) as f64;
            poses[i] * Se3::exp(&mean)
        })
        .collect();
    let last = (smoothed.len() - 1) as f64;
    Some(
        (0..frames)
            .map(|f| {
                let s = if frames == 1 {
                    0.0
                } else {
                    last * f as f64 / (frames - 1) as f64
                };
                let i = (s.floor() as usize).min(smoothed.len() - 2);
                let t = s - i as f64;
                let rel = (smoothed[i].inverse() * smoothed[i + 1]).log();
                smoothed[i] * Se3::exp(&(rel * t))
            })
            .collect(),
    )
}

/// `frames` cameras on a circle around the scene: centred above the median of the Gaussians'
/// centres along the cameras' mean up direction, at the cameras' mean distance from that axis
/// and their mean height, each looking at the centre. Starts at the first view's azimuth.
pub fn orbit_path(output: &TrainOutput, frames: usize) -> Option<Vec<Se3>> {
    let cams: Vec<Se3> = output.views.iter().map(|v| Se3::from(&v.mid_c2w)).collect();
    if cams.is_empty() || output.gaussians.is_empty() || frames == 0 {
        return None;
    }
    let median = |k: usize| {
        let mut v: Vec<f64> = output
            .gaussians
            .means
            .iter()
            .map(|m| f64::from(m[k]))
            .filter(|x| x.is_finite())
            .collect();
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    };
    let centre = Vector3::new(median(0), median(1), median(2));
    // OpenCV cameras: image up is −y.
    let up = cams
        .iter()
        .fold(Vector3::zeros(), |acc, c| acc - c.rot.column(1))
        .try_normalize(1e-12)?;
    let height = cams
        .iter()
        .map(|c| (c.trans - centre).dot(&up))
        .sum::<f64>()
        / cams.len() as f64;
    let radial = |c: &Se3| {
        let d = c.trans - centre;
        d - up * d.dot(&up)
    };
    let radius = cams.iter().map(|c| radial(c).norm()).sum::<f64>() / cams.len() as f64;
    let e0 = radial(&cams[0])
        .try_normalize(1e-12)
        .or_else(|| up.cross(&Vector3::x()).try_normalize(1e-12))?;
    let e1 = up.cross(&e0);
    Some(
        (0..frames)
            .map(|f| {
                let a = std::f64::consts::TAU * f as f64 / frames as f64;
                let pos = centre + up * height + (e0 * a.cos() + e1 * a.sin()) * radius.max(1e-6);
                look_at(&pos, &centre, &up)
            })
            .collect(),
    )
}

/// Camera-to-world pose at `pos` looking at `target` with `up` up in the image (OpenCV axes).
fn look_at(pos: &Vector3<f64>, target: &Vector3<f64>, up: &Vector3<f64>) -> Se3 {
    let z = (target - pos).normalize();
    let x = (z.cross(&-up)).try_normalize(1e-12).unwrap_or(Vector3::x());
    let y = z.cross(&x);
    let rot = gems_math::Matrix3::from_columns(&[x, y, z]);
    Se3::new(rot, *pos)
}
