//! Coarse-to-fine: the reconstruction made at a coarse working level, re-measured at a finer
//! one. The coarse level is where the blur is short enough to match patches without bias, but
//! its pixels are few: even sharp photos reconstructed at 64–96 px are 1–2 % off and turn the
//! camera path by ±8° too much or too little (crates/gems-init/BENCHMARKS.md, "Where the error
//! under heavy blur comes from"). At the finer level every observation is tracked again from
//! its track's first view, searching only around where the coarse model projects the point
//! (so the longer smear cannot send it elsewhere), then the model is bundle-adjusted there.

use super::ba::{Focal, Pinhole};
use super::features::Gray;
use super::incremental::{self, Recon, TrackObs};
use super::tracking::{self, Prepared, Scratch, TrackParams};
use super::{SfmOptions, TRACKING_SMOOTH_SIGMA};
use gems_math::Intrinsics;
use nalgebra::Vector2;
use rayon::prelude::*;

/// A registered view needs this many observations at the finer level, or the refinement is
/// not kept (its pose would rest on too little).
const MIN_VIEW_OBSERVATIONS: usize = 12;

/// `rec`, made on `grays` resized by `from`, re-measured and bundle-adjusted on them resized by
/// `to` (> `from`). `None` when a registered view keeps fewer than
/// [`MIN_VIEW_OBSERVATIONS`] observations there.
pub(crate) fn refine_finer(
    rec: &Recon,
    grays: &[Gray],
    from: f64,
    to: f64,
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
        // As for the coarse tracks (`all_tracks`), at this level's size.
        half: ((long * 0.09).round() as i32).clamp(4, 10),
        // The coarse model predicts each point to about its reprojection error times `r`.
        radius: ((2.0 * r).ceil() as i32).max(3),
        neighbours: 0,
        min_ncc: 0.75,
        min_margin: 0.01,
        fb_tol: 1.0,
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
            for o in &used[1..] {
                let predicted = project(o.view) + offset;
                if let Some(q) = tracking::track_point(
                    &fine[root.view],
                    &fine[o.view],
                    as_f32(root_xy),
                    as_f32(predicted),
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
