//! Coarse-to-fine: the reconstruction made at a coarse working level, re-measured at a finer
//! one. The coarse level is where the blur is short enough to match patches without bias, but
//! its pixels are few: even sharp photos reconstructed at 64–96 px are 1–2 % off and turn the
//! camera path by ±8° too much or too little (crates/gems-init/BENCHMARKS.md, "Where the error
//! under heavy blur comes from"). At the finer level every observation is tracked again from
//! its track's first view, searching only around where the coarse model projects the point
//! (so the longer smear cannot send it elsewhere), then the model is bundle-adjusted there.
//!
//! The model also says how each patch looks in the other view: its template is resampled
//! through the local affine map of the surface between the two views ([`surface_warp`]), since
//! a translation-only match of a patch seen 20–40° apart is off by up to a pixel, and always the
//! same way along a camera arc (a path that turns 3 % too far at no blur at all). And patches are
//! sized to the blur at that level ([`SfmOptions::refine_patch_blur_ratio`]): a sharp photo is
//! re-measured with small patches, which straddle fewer depth edges. Where the blur there is
//! short ([`SfmOptions::refine_affine_max_blur_px`]) each match also corrects that warp by an
//! affine map of its window, since the predicted one assumes a surface facing both views.

use super::ba::{Focal, Pinhole};
use super::features::Gray;
use super::incremental::{self, Recon, TrackObs};
use super::tracking::{self, Prepared, Scratch, TrackParams, Warp};
use super::{SfmOptions, TRACKING_SMOOTH_SIGMA};
use gems_math::Intrinsics;
use gems_math::Se3;
use nalgebra::{Vector2, Vector3};
use rayon::prelude::*;

/// A registered view needs this many observations at the finer level, or the refinement is
/// not kept (its pose would rest on too little).
const MIN_VIEW_OBSERVATIONS: usize = 12;

/// `rec`, made on `grays` resized by `from`, re-measured and bundle-adjusted on them resized by
/// `to` (≥ `from`; `blur` is the photos' estimated blur at full size). `None` when a registered
/// view keeps fewer than [`MIN_VIEW_OBSERVATIONS`] observations there.
pub(crate) fn remeasure(
    rec: &Recon,
    grays: &[Gray],
    from: f64,
    to: f64,
    blur: f64,
    opts: &SfmOptions,
) -> Option<Recon> {
    let r = to / from;
    let fine: Vec<Prepared> = grays
        .par_iter()
        .map(|g| Prepared::new(g.resized(to as f32).gaussian(TRACKING_SMOOTH_SIGMA)))
        .collect();
    let (w, h) = (fine[0].img.w, fine[0].img.h);
    let k = Intrinsics {
        fx: rec.k.fx * r,
        fy: rec.k.fy * r,
        cx: rec.k.cx * r,
        cy: rec.k.cy * r,
        width: w as u32,
        height: h as u32,
    };
    let long = w.max(h) as f32;
    let params = TrackParams {
        half: if opts.refine_patch_blur_ratio > 0.0 {
            (opts.refine_patch_blur_ratio * blur * to).round() as i32
        } else {
            // As for the coarse tracks (`all_tracks`), at this level's size.
            (long * 0.09).round() as i32
        }
        .clamp(4, 10),
        // The coarse model predicts each point to about its reprojection error times `r`.
        radius: ((2.0 * r).ceil() as i32).max(3),
        neighbours: 0,
        min_ncc: 0.75,
        min_margin: 0.01,
        fb_tol: 1.0,
        // The smear at this level, as the patch size above.
        affine: opts.refine_affine_max_blur_px > 0.0 && blur * to <= opts.refine_affine_max_blur_px,
    };
    let scale = |xy: &Vector2<f64>| xy * r;
    let tracks: Vec<incremental::Track> = rec
        .tracks
        .par_iter()
        .map_init(Scratch::default, |s, t| {
            let used: Vec<&TrackObs> = t
                .obs
                .iter()
                .filter(|o| o.active && rec.poses[o.view].is_some())
                .collect();
            let (Some(x), Some(root)) = (t.xyz, used.first()) else {
                // Not in the model: carried over at the new scale for later triangulation.
                let mut t = t.clone();
                t.obs.iter_mut().for_each(|o| o.xy = scale(&o.xy));
                return t;
            };
            let project = |v: usize| k.project(&rec.poses[v].expect("registered").act(&x));
            let root_xy = scale(&root.xy);
            let offset = root_xy - project(root.view);
            let as_f32 = |v: Vector2<f64>| [v.x as f32, v.y as f32];
            let mut obs = vec![TrackObs {
                view: root.view,
                xy: root_xy,
                active: true,
            }];
            let root_pose = rec.poses[root.view].expect("registered");
            for o in &used[1..] {
                let predicted = project(o.view) + offset;
                let pose = rec.poses[o.view].expect("registered");
                let warp = surface_warp(&k, &root_pose, &pose, &x, &project(root.view));
                if let Some(q) = tracking::track_point(
                    &fine[root.view],
                    &fine[o.view],
                    as_f32(root_xy),
                    as_f32(predicted),
                    &warp,
                    &params,
                    s,
                ) {
                    obs.push(TrackObs {
                        view: o.view,
                        xy: Vector2::new(q[0] as f64, q[1] as f64),
                        active: true,
                    });
                }
            }
            incremental::Track {
                xyz: (obs.len() >= 2).then_some(x),
                obs,
            }
        })
        .collect();
    let mut out = Recon {
        k,
        poses: rec.poses.clone(),
        tracks,
        path: rec.path.clone(),
    };
    let gauge = out.poses.iter().position(Option::is_some)?;
    incremental::run_ba(&mut out, gauge, Focal::Fixed, 30, opts);
    incremental::filter_outliers(&mut out, opts);
    incremental::run_ba(&mut out, gauge, Focal::Fixed, 20, opts);
    let mut per_view = vec![0usize; out.poses.len()];
    for (_, o) in out.used_obs() {
        per_view[o.view] += 1;
    }
    let thin = out
        .poses
        .iter()
        .zip(&per_view)
        .any(|(p, &n)| p.is_some() && n < MIN_VIEW_OBSERVATIONS);
    (!thin).then_some(out)
}

/// The local affine map, at `at` (the projection of `x` into `src`), from pixel offsets in `src`
/// to pixel offsets in `dst` for the surface through `x`, taken as the plane facing the bisector
/// of the two viewing directions (the multi-view-stereo convention when the normal is unknown,
/// e.g. PMVS, Furukawa & Ponce 2010). Central differences of one pixel; the identity when the
/// plane is seen edge-on from `src`.
fn surface_warp(k: &Intrinsics, src: &Se3, dst: &Se3, x: &Vector3<f64>, at: &Vector2<f64>) -> Warp {
    let centre = |p: &Se3| -(p.rot.transpose() * p.trans);
    let (cs, cd) = (centre(src), centre(dst));
    let normal = ((cs - x).normalize() + (cd - x).normalize()).normalize();
    let map = |u: Vector2<f64>| -> Option<Vector2<f64>> {
        let ray = src.rot.transpose() * Vector3::new((u.x - k.cx) / k.fx, (u.y - k.cy) / k.fy, 1.0);
        let along = normal.dot(&ray);
        if along.abs() < 1e-9 {
            return None;
        }
        let hit = cs + ray * (normal.dot(&(x - cs)) / along);
        Some(k.project(&dst.act(&hit)))
    };
    let column = |d: Vector2<f64>| Some((map(at + d)? - map(at - d)?) * 0.5);
    match (column(Vector2::x()), column(Vector2::y())) {
        (Some(a), Some(b)) if a.iter().chain(b.iter()).all(|v| v.is_finite()) => {
            Warp::new(a.x as f32, b.x as f32, a.y as f32, b.y as f32)
        }
        _ => Warp::identity(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix3;

    fn close(w: &Warp, m: Warp) -> bool {
        (w - m).abs().max() < 1e-4
    }

    #[test]
    fn surface_warp_scales_with_depth_and_is_the_identity_between_equal_views() {
        let k = Intrinsics {
            fx: 100.0,
            fy: 100.0,
            cx: 50.0,
            cy: 40.0,
            width: 100,
            height: 80,
        };
        let x = Vector3::new(0.3, -0.2, 5.0);
        let src = Se3::new(Matrix3::identity(), Vector3::zeros());
        let at = k.project(&src.act(&x));
        let same = surface_warp(&k, &src, &src, &x, &at);
        assert!(close(&same, Warp::identity()), "{same:?}");
        // The same orientation from −x, on the same ray and twice as far: every offset halves.
        let far = Se3::new(Matrix3::identity(), x);
        let half = surface_warp(&k, &src, &far, &x, &at);
        assert!(close(&half, Warp::identity() * 0.5), "{half:?}");
    }
}
