//! Incremental reconstruction at the working level: tracks from verified pair matches, the
//! initial pair, PnP registration, triangulation and bundle adjustment.

use super::ba::{self, BaOptions, Focal, Observation, Pinhole};
use super::features::Features;
use super::geometry;
use super::{PairCorr, PairMatches, SfmOptions};
use gems_math::{Intrinsics, Se3, camera_center_from_w2c};
use nalgebra::{Vector2, Vector3};

/// One observation of a track: view, working-level pixel, and whether it is still trusted.
#[derive(Clone, Debug)]
pub(crate) struct TrackObs {
    pub view: usize,
    pub xy: Vector2<f64>,
    pub active: bool,
}

#[derive(Clone, Debug)]
pub(crate) struct Track {
    pub obs: Vec<TrackObs>,
    pub xyz: Option<Vector3<f64>>,
}

/// State of a reconstruction at the working level.
#[derive(Clone, Debug)]
pub(crate) struct Recon {
    pub k: Intrinsics,
    pub poses: Vec<Option<Se3>>,
    pub tracks: Vec<Track>,
    /// Smooth motion in capture order, in every bundle adjustment, when the images are ordered.
    pub path: Option<ba::PathPrior>,
}

impl Recon {
    pub fn registered(&self) -> usize {
        self.poses.iter().filter(|p| p.is_some()).count()
    }

    /// Observations that take part in the model: active, of a registered view, on a point.
    pub fn used_obs(&self) -> impl Iterator<Item = (&Track, &TrackObs)> {
        self.tracks
            .iter()
            .filter(|t| t.xyz.is_some())
            .flat_map(move |t| {
                t.obs
                    .iter()
                    .filter(move |o| o.active && self.poses[o.view].is_some())
                    .map(move |o| (t, o))
            })
    }

    /// Mean reprojection error (working-level px) over the used observations.
    pub fn mean_error(&self) -> f64 {
        let (mut s, mut n) = (0.0, 0usize);
        for (t, o) in self.used_obs() {
            if let (Some(x), Some(p)) = (t.xyz, self.poses[o.view]) {
                s += (self.k.project(&p.act(&x)) - o.xy).norm();
                n += 1;
            }
        }
        if n == 0 { f64::INFINITY } else { s / n as f64 }
    }
}

/// Chain pairwise matches into tracks with a union–find over (view, feature) nodes. A track keeps
/// at most one feature per view (the first met), so inconsistent chains cannot put two
/// observations of one point in the same image.
pub(crate) fn build_tracks(feats: &[Features], pairs: &[PairMatches]) -> Vec<Track> {
    let mut offset = vec![0usize; feats.len() + 1];
    for (i, f) in feats.iter().enumerate() {
        offset[i + 1] = offset[i] + f.xy.len();
    }
    let total = offset[feats.len()];
    let mut parent: Vec<usize> = (0..total).collect();
    fn find(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            p[x] = p[p[x]];
            x = p[x];
        }
        x
    }
    for pm in pairs {
        for &(a, b) in &pm.matches {
            let ra = find(&mut parent, offset[pm.i] + a as usize);
            let rb = find(&mut parent, offset[pm.j] + b as usize);
            if ra != rb {
                parent[ra.max(rb)] = ra.min(rb);
            }
        }
    }
    let mut root_track = vec![usize::MAX; total];
    let mut tracks: Vec<Track> = Vec::new();
    let mut linked = vec![false; total];
    for pm in pairs {
        for &(a, b) in &pm.matches {
            linked[offset[pm.i] + a as usize] = true;
            linked[offset[pm.j] + b as usize] = true;
        }
    }
    for (v, f) in feats.iter().enumerate() {
        for (k, xy) in f.xy.iter().enumerate() {
            let node = offset[v] + k;
            if !linked[node] {
                continue;
            }
            let r = find(&mut parent, node);
            if root_track[r] == usize::MAX {
                root_track[r] = tracks.len();
                tracks.push(Track {
                    obs: Vec::new(),
                    xyz: None,
                });
            }
            let t = &mut tracks[root_track[r]];
            if t.obs.iter().all(|o| o.view != v) {
                t.obs.push(TrackObs {
                    view: v,
                    xy: Vector2::new(xy[0] as f64, xy[1] as f64),
                    active: true,
                });
            }
        }
    }
    tracks.retain(|t| t.obs.len() >= 2);
    tracks
}

/// Triangulate a track from its active observations in registered views; drops the worst
/// observation while the fit is inconsistent. Returns whether a point was set.
fn triangulate_track(
    t: &mut Track,
    poses: &[Option<Se3>],
    k: &Intrinsics,
    opts: &SfmOptions,
) -> bool {
    let mut use_: Vec<usize> = (0..t.obs.len())
        .filter(|&i| t.obs[i].active && poses[t.obs[i].view].is_some())
        .collect();
    let min_angle = opts.min_tri_angle_deg.to_radians();
    while use_.len() >= 2 {
        let obs: Vec<(Se3, Vector2<f64>)> = use_
            .iter()
            .map(|&i| {
                (
                    poses[t.obs[i].view].expect("registered"),
                    k.normalise(&t.obs[i].xy),
                )
            })
            .collect();
        let Some(x) = geometry::triangulate(&obs) else {
            return false;
        };
        // Worst observation by reprojection error (behind the camera counts as infinite).
        let errs: Vec<f64> = use_
            .iter()
            .map(|&i| {
                let c = poses[t.obs[i].view].expect("registered").act(&x);
                if c.z <= 0.0 {
                    f64::INFINITY
                } else {
                    (k.project(&c) - t.obs[i].xy).norm()
                }
            })
            .collect();
        let (wi, we) = errs
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map(|(i, e)| (i, *e))
            .expect("non-empty");
        if we > opts.max_reproj_px {
            use_.remove(wi);
            continue;
        }
        let centres: Vec<Vector3<f64>> = use_
            .iter()
            .map(|&i| {
                poses[t.obs[i].view]
                    .map(|p| camera_center_from_w2c(&p))
                    .expect("registered")
            })
            .collect();
        let mut max_angle: f64 = 0.0;
        for a in 0..centres.len() {
            for b in a + 1..centres.len() {
                max_angle =
                    max_angle.max(geometry::triangulation_angle(&centres[a], &centres[b], &x));
            }
        }
        if max_angle < min_angle {
            return false;
        }
        for (i, o) in t.obs.iter_mut().enumerate() {
            if poses[o.view].is_some() && !use_.contains(&i) {
                o.active = false;
            }
        }
        t.xyz = Some(x);
        return true;
    }
    false
}

/// Bundle-adjust all points and registered poses (the `fixed` view is the gauge).
pub(crate) fn run_ba(
    r: &mut Recon,
    fixed_view: usize,
    focal: Focal,
    iters: usize,
    opts: &SfmOptions,
) {
    let fixed: Vec<bool> = (0..r.poses.len()).map(|v| v == fixed_view).collect();
    let all = vec![true; r.tracks.len()];
    adjust(r, &fixed, &all, focal, iters, opts);
}

/// Bundle-adjusts the points of the tracks with `include[track]` and the registered poses not
/// `fixed`; with every camera fixed only the points move (and the path prior is left out).
fn adjust(
    r: &mut Recon,
    fixed: &[bool],
    include: &[bool],
    focal: Focal,
    iters: usize,
    opts: &SfmOptions,
) {
    let mut point_of_track = vec![usize::MAX; r.tracks.len()];
    let mut points = Vec::new();
    let mut obs = Vec::new();
    for (ti, t) in r.tracks.iter().enumerate() {
        let Some(x) = t.xyz.filter(|_| include[ti]) else {
            continue;
        };
        point_of_track[ti] = points.len();
        for o in &t.obs {
            if o.active && r.poses[o.view].is_some() {
                obs.push(Observation {
                    cam: o.view,
                    point: points.len(),
                    xy: o.xy,
                });
            }
        }
        points.push(x);
    }
    if obs.is_empty() {
        return;
    }
    let mut poses: Vec<Se3> = r
        .poses
        .iter()
        .map(|p| p.unwrap_or(Se3::identity()))
        .collect();
    let path = r.path.clone().filter(|_| !fixed.iter().all(|&f| f));
    ba::bundle_adjust(
        &mut poses,
        fixed,
        &mut points,
        &obs,
        &mut r.k,
        &BaOptions {
            huber_px: opts.max_reproj_px * 0.5,
            max_iters: iters,
            focal,
            path: path.as_ref(),
        },
    );
    for (v, p) in r.poses.iter_mut().enumerate() {
        if p.is_some() {
            *p = Some(poses[v]);
        }
    }
    for (ti, t) in r.tracks.iter_mut().enumerate() {
        if point_of_track[ti] != usize::MAX {
            t.xyz = Some(points[point_of_track[ti]]);
        }
    }
}

/// A final bundle adjustment of the cameras on the best-measured points only, the focal held:
/// the `fraction` of points with the largest RMS reprojection error sit out while the cameras
/// move (the gauge view `fixed_view` held), then are re-fitted to the new cameras (the cameras
/// held) and filtered like every point.
///
/// On nearly sharp generated scenes the points a model fits worst are biased rather than noisy
/// (patches across depth edges): a bundle adjustment started from the true cameras ends as far
/// from them as the model, and adjusting without those points brings the cameras closer. The
/// focal is held because refining one under its prior here would weigh the prior more against
/// fewer points (on a generated scene with a focal given 4 % low it pulled the estimate back
/// toward the given value); crates/gems-init/BENCHMARKS.md, "Cameras adjusted on the
/// best-measured points".
pub(crate) fn trimmed_ba(r: &mut Recon, fixed_view: usize, fraction: f64, opts: &SfmOptions) {
    let k = r.k;
    let mut rms: Vec<(f64, usize)> = Vec::new();
    for (ti, t) in r.tracks.iter().enumerate() {
        let Some(x) = t.xyz else { continue };
        let (mut sum, mut n) = (0.0, 0usize);
        for o in t.obs.iter().filter(|o| o.active) {
            if let Some(p) = r.poses[o.view] {
                let c = p.act(&x);
                sum += if c.z > 0.0 {
                    (k.project(&c) - o.xy).norm_squared()
                } else {
                    f64::INFINITY
                };
                n += 1;
            }
        }
        if n > 0 {
            rms.push(((sum / n as f64).sqrt(), ti));
        }
    }
    let sit_out = (fraction * rms.len() as f64).floor() as usize;
    if sit_out == 0 || sit_out >= rms.len() {
        return;
    }
    rms.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    let mut best = vec![true; r.tracks.len()];
    for &(_, ti) in &rms[..sit_out] {
        best[ti] = false;
    }
    let fixed: Vec<bool> = (0..r.poses.len()).map(|v| v == fixed_view).collect();
    adjust(r, &fixed, &best, Focal::Fixed, 30, opts);
    let rest: Vec<bool> = best.iter().map(|b| !b).collect();
    adjust(r, &vec![true; r.poses.len()], &rest, Focal::Fixed, 10, opts);
    filter_outliers(r, opts);
}

/// Deactivate observations beyond the reprojection threshold; drop points left with < 2.
pub(crate) fn filter_outliers(r: &mut Recon, opts: &SfmOptions) {
    let k = r.k;
    for t in &mut r.tracks {
        let Some(x) = t.xyz else { continue };
        let mut n = 0;
        for o in &mut t.obs {
            let Some(p) = r.poses[o.view] else { continue };
            if !o.active {
                continue;
            }
            let c = p.act(&x);
            if c.z <= 0.0 || (k.project(&c) - o.xy).norm() > opts.max_reproj_px {
                o.active = false;
            } else {
                n += 1;
            }
        }
        if n < 2 {
            t.xyz = None;
        }
    }
}

fn triangulate_all(r: &mut Recon, opts: &SfmOptions) -> usize {
    let k = r.k;
    let mut added = 0;
    for t in &mut r.tracks {
        if t.xyz.is_none() && triangulate_track(t, &r.poses, &k, opts) {
            added += 1;
        }
    }
    added
}

/// Initial pair candidates, best first: essential matrices with many inliers and enough
/// parallax (score: inliers, discounted below a good triangulation angle).
fn initial_pairs(
    pairs: &[PairCorr],
    k: &Intrinsics,
    opts: &SfmOptions,
) -> Vec<(usize, usize, Se3)> {
    let mut order: Vec<&PairCorr> = pairs.iter().collect();
    order.sort_by(|a, b| {
        b.x1.len()
            .cmp(&a.x1.len())
            .then((a.i, a.j).cmp(&(b.i, b.j)))
    });
    let mut found: Vec<(f64, usize, usize, Se3)> = Vec::new();
    // A wide initial baseline: with a few degrees the rotation and the sideways translation of
    // the pair trade off against each other (bas-relief ambiguity) under blur noise, and the
    // error locks in as every later view is registered against it.
    let good_angle = (6.0f64).max(2.0 * opts.min_tri_angle_deg).to_radians();
    for pm in order.iter().take(30) {
        let x1: Vec<_> = pm.x1.iter().map(|p| k.normalise(p)).collect();
        let x2: Vec<_> = pm.x2.iter().map(|p| k.normalise(p)).collect();
        let seed = opts.seed.wrapping_add(0x1000 + (pm.i * 7919 + pm.j) as u64);
        let Some((e, mask)) =
            geometry::ransac_epipolar(&x1, &x2, true, opts.max_reproj_px / k.fx, 2000, seed)
        else {
            continue;
        };
        let (a, b): (Vec<_>, Vec<_>) = (0..x1.len())
            .filter(|&i| mask[i])
            .map(|i| (x1[i], x2[i]))
            .unzip();
        let Some((rel, front)) = geometry::decompose_essential(&e, &a, &b) else {
            continue;
        };
        let c2 = camera_center_from_w2c(&rel);
        let mut angles: Vec<f64> = a
            .iter()
            .zip(&b)
            .zip(&front)
            .filter(|(_, f)| **f)
            .filter_map(|((p, q), _)| geometry::triangulate(&[(Se3::identity(), *p), (rel, *q)]))
            .map(|x| geometry::triangulation_angle(&Vector3::zeros(), &c2, &x))
            .collect();
        if angles.len() < opts.min_pair_inliers {
            continue;
        }
        angles.sort_by(|x, y| x.total_cmp(y));
        let med = angles[angles.len() / 2];
        if med < opts.min_tri_angle_deg.to_radians() {
            continue;
        }
        let score = angles.len() as f64 * (med / good_angle).min(1.0);
        found.push((score, pm.i, pm.j, rel));
    }
    // Stable: equal scores keep the pairs' order (most matches first).
    found.sort_by(|a, b| b.0.total_cmp(&a.0));
    found.into_iter().map(|(_, i, j, p)| (i, j, p)).collect()
}

/// Full incremental reconstruction of `tracks` with intrinsics `k` (working level); `pairs`
/// are the two-view correspondences the initial pair is chosen from; the focal is held
/// fixed. None when no initial pair exists.
///
/// Under heavy blur a model grown from one pair can settle in a wrong basin of the bundle
/// adjustment (a generated 40° arc came out as 27°, its cameras turned up to 31° from the
/// truth, while bundle adjustment started from the true cameras converged within 5° at a lower
/// cost; crates/gems-init/BENCHMARKS.md, "Several initial pairs"). So the model is grown from
/// each of the best pairs, and the one that explains the tracks
/// clearly best ([`msac_cost`], by [`INITIAL_PAIR_MARGIN`]) is kept; `tries` is how many.
pub(crate) fn reconstruct(
    tracks: Vec<Track>,
    pairs: &[PairCorr],
    nviews: usize,
    k: Intrinsics,
    path: Option<&ba::PathPrior>,
    tries: usize,
    opts: &SfmOptions,
) -> Option<Recon> {
    let mut best: Option<(f64, Recon)> = None;
    for (i0, j0, rel) in initial_pairs(pairs, &k, opts).into_iter().take(tries) {
        let Some(r) = grow(tracks.clone(), (i0, j0, rel), nviews, k, path, opts) else {
            continue;
        };
        let cost = msac_cost(&r, opts.max_reproj_px);
        tracing::debug!(
            pair = ?(i0, j0),
            registered = r.registered(),
            cost,
            "model grown from an initial pair"
        );
        if best
            .as_ref()
            .is_none_or(|(c, _)| cost < (1.0 - INITIAL_PAIR_MARGIN) * *c)
        {
            best = Some((cost, r));
        }
    }
    best.map(|(_, r)| r)
}

/// Relative cost decrease by which a model from a later initial pair must beat the kept one
/// ([`reconstruct`]). On generated arcs the wrong basins cost 10–37 % more than the model
/// from another pair; smaller differences (0.6 and 3.4 % on two heavily blurred scenes) chose
/// the model farther from the truth (crates/gems-init/BENCHMARKS.md, "Several initial pairs").
const INITIAL_PAIR_MARGIN: f64 = 0.05;

/// How well a model explains all its tracks' observations, for comparing models made from the
/// same tracks: the sum over every observation of its squared reprojection error (working px),
/// truncated at `tau²` (MSAC, Torr & Zisserman 2000); an observation in a view without a pose,
/// of a track without a point, or behind its camera costs `tau²`.
fn msac_cost(r: &Recon, tau: f64) -> f64 {
    let cap = tau * tau;
    r.tracks
        .iter()
        .flat_map(|t| t.obs.iter().map(move |o| (t.xyz, o)))
        .map(|(x, o)| match (x, r.poses[o.view]) {
            (Some(x), Some(p)) => {
                let c = p.act(&x);
                if c.z <= 0.0 {
                    cap
                } else {
                    (r.k.project(&c) - o.xy).norm_squared().min(cap)
                }
            }
            _ => cap,
        })
        .sum()
}

/// The incremental reconstruction from one initial pair `(i0, j0, pose of j0)`.
fn grow(
    tracks: Vec<Track>,
    (i0, j0, rel): (usize, usize, Se3),
    nviews: usize,
    k: Intrinsics,
    path: Option<&ba::PathPrior>,
    opts: &SfmOptions,
) -> Option<Recon> {
    let mut r = Recon {
        k,
        poses: vec![None; nviews],
        tracks,
        path: path.cloned(),
    };
    r.poses[i0] = Some(Se3::identity());
    r.poses[j0] = Some(rel);
    triangulate_all(&mut r, opts);
    run_ba(&mut r, i0, Focal::Fixed, 30, opts);
    filter_outliers(&mut r, opts);
    if r.tracks.iter().filter(|t| t.xyz.is_some()).count() < opts.min_pair_inliers / 2 {
        return None;
    }
    // view → (track, obs index) for quick 2D–3D lookup.
    let mut view_obs: Vec<Vec<(usize, usize)>> = vec![Vec::new(); nviews];
    for (ti, t) in r.tracks.iter().enumerate() {
        for (oi, o) in t.obs.iter().enumerate() {
            view_obs[o.view].push((ti, oi));
        }
    }
    let mut tried: Vec<Option<usize>> = vec![None; nviews];
    const MIN_CORR: usize = 10;
    loop {
        let mut cands: Vec<(usize, usize)> = (0..nviews)
            .filter(|&v| r.poses[v].is_none())
            .map(|v| {
                let n = view_obs[v]
                    .iter()
                    .filter(|&&(ti, oi)| r.tracks[ti].xyz.is_some() && r.tracks[ti].obs[oi].active)
                    .count();
                (v, n)
            })
            .filter(|&(v, n)| n >= MIN_CORR && tried[v] != Some(n))
            .collect();
        cands.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
        let mut registered = None;
        for &(v, n) in &cands {
            tried[v] = Some(n);
            let corr: Vec<(usize, usize)> = view_obs[v]
                .iter()
                .copied()
                .filter(|&(ti, oi)| r.tracks[ti].xyz.is_some() && r.tracks[ti].obs[oi].active)
                .collect();
            let xw: Vec<Vector3<f64>> = corr
                .iter()
                .map(|&(ti, _)| r.tracks[ti].xyz.expect("point"))
                .collect();
            let xn: Vec<Vector2<f64>> = corr
                .iter()
                .map(|&(ti, oi)| r.k.normalise(&r.tracks[ti].obs[oi].xy))
                .collect();
            let seed = opts.seed.wrapping_add(0x2000 + v as u64 * 131 + n as u64);
            let Some((pose, mask)) =
                geometry::ransac_pnp(&xw, &xn, opts.max_reproj_px / r.k.fx, 1000, seed)
            else {
                continue;
            };
            let ninl = mask.iter().filter(|&&m| m).count();
            if ninl < MIN_CORR || (ninl as f64) < 0.25 * n as f64 {
                continue;
            }
            for (&(ti, oi), &m) in corr.iter().zip(&mask) {
                if !m {
                    r.tracks[ti].obs[oi].active = false;
                }
            }
            r.poses[v] = Some(pose);
            registered = Some(v);
            break;
        }
        let Some(v) = registered else { break };
        let added = triangulate_all(&mut r, opts);
        let nreg = r.registered();
        run_ba(&mut r, i0, Focal::Fixed, 15, opts);
        filter_outliers(&mut r, opts);
        tracing::debug!(
            view = v,
            registered = nreg,
            new_points = added,
            "registered view"
        );
    }
    triangulate_all(&mut r, opts);
    run_ba(&mut r, i0, Focal::Fixed, 50, opts);
    filter_outliers(&mut r, opts);
    triangulate_all(&mut r, opts);
    run_ba(&mut r, i0, Focal::Fixed, 30, opts);
    filter_outliers(&mut r, opts);
    Some(r)
}

/// Free the focal in a final bundle adjustment, keeping the result only when the focal stays in
/// `[lo, hi]` (the bracket of the focal search): outside it the focal is drifting along its weak
/// direction (blur biases the observations), not converging.
pub(crate) fn refine_focal_bounded(
    r: &Recon,
    lo: f64,
    hi: f64,
    opts: &SfmOptions,
) -> Option<Recon> {
    let out = refine_focal(r, Focal::Free, opts)?;
    (out.k.fx >= lo && out.k.fx <= hi).then_some(out)
}

/// A final bundle adjustment of `r` that refines the focal as `focal` says, then drops the
/// outliers; `None` when it loses a view.
pub(crate) fn refine_focal(r: &Recon, focal: Focal, opts: &SfmOptions) -> Option<Recon> {
    let fixed = r.poses.iter().position(|p| p.is_some())?;
    let mut out = r.clone();
    run_ba(&mut out, fixed, focal, 50, opts);
    filter_outliers(&mut out, opts);
    (out.registered() == r.registered()).then_some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tracks_keep_one_feature_per_view() {
        let f = |n: usize| Features {
            xy: (0..n).map(|i| [i as f32, 0.0]).collect(),
            desc: vec![],
        };
        let feats = vec![f(3), f(3), f(3)];
        let pairs = vec![
            PairMatches {
                i: 0,
                j: 1,
                matches: vec![(0, 0), (1, 1)],
            },
            PairMatches {
                i: 1,
                j: 2,
                matches: vec![(0, 0), (1, 2)],
            },
            // Inconsistent: links feature 0 of view 0 to feature 2 of view 2 as well as 0.
            PairMatches {
                i: 0,
                j: 2,
                matches: vec![(0, 2)],
            },
        ];
        let t = build_tracks(&feats, &pairs);
        for tr in &t {
            let mut views: Vec<_> = tr.obs.iter().map(|o| o.view).collect();
            views.sort();
            views.dedup();
            assert_eq!(views.len(), tr.obs.len());
        }
        assert!(!t.is_empty());
    }

    /// Six cameras on a 30° arc around a cloud of points at about 4 units, pixels moved by up to
    /// `noise` px (deterministically): the poses (world to camera), the points, and every
    /// observation as one track per point.
    fn arc_scene(noise: f64) -> (Intrinsics, Vec<Se3>, Vec<Vector3<f64>>, Vec<Track>) {
        let k = Intrinsics {
            fx: 200.0,
            fy: 200.0,
            cx: 120.0,
            cy: 80.0,
            width: 240,
            height: 160,
        };
        let poses: Vec<Se3> = (0..6)
            .map(|v| {
                let a = (v as f64 - 2.5) * 6f64.to_radians();
                let centre =
                    Vector3::new(4.0 * a.sin(), 0.3 * (v as f64 * 0.7).sin(), -4.0 * a.cos());
                let rot = nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), -a).into_inner();
                Se3::new(rot, -rot * centre)
            })
            .collect();
        // A deterministic cloud in a box around the origin.
        let points: Vec<Vector3<f64>> = (0..200)
            .map(|i| {
                let f = |m: f64| ((i as f64 * m).sin() * 43758.5453).fract();
                Vector3::new(
                    2.0 * f(12.9898) - 1.0,
                    1.4 * f(78.233) - 0.7,
                    2.0 * f(37.719) - 1.0,
                )
            })
            .collect();
        let tracks = points
            .iter()
            .enumerate()
            .map(|(i, x)| Track {
                obs: poses
                    .iter()
                    .enumerate()
                    .map(|(view, p)| {
                        let phase = (i * 6 + view) as f64;
                        TrackObs {
                            view,
                            xy: k.project(&p.act(x))
                                + noise * Vector2::new((phase * 1.7).sin(), (phase * 2.3).cos()),
                            active: true,
                        }
                    })
                    .collect(),
                xyz: None,
            })
            .collect();
        (k, poses, points, tracks)
    }

    #[test]
    fn msac_cost_counts_truncated_residuals_and_unexplained_observations() {
        let (k, poses, points, mut tracks) = arc_scene(0.0);
        for (t, x) in tracks.iter_mut().zip(&points) {
            t.xyz = Some(*x);
        }
        let mut r = Recon {
            k,
            poses: poses.iter().copied().map(Some).collect(),
            tracks,
            path: None,
        };
        assert!(msac_cost(&r, 2.0) < 1e-12);
        // One pixel off in x for one observation: cost 1.
        r.tracks[0].obs[0].xy.x += 1.0;
        assert!((msac_cost(&r, 2.0) - 1.0).abs() < 1e-9);
        // Ten pixels off: truncated at tau² = 4.
        r.tracks[0].obs[0].xy.x += 9.0;
        assert!((msac_cost(&r, 2.0) - 4.0).abs() < 1e-9);
        // A view without a pose: each of its 200 observations costs tau² (the moved one was
        // in view 0 as well).
        r.poses[0] = None;
        assert!((msac_cost(&r, 2.0) - 800.0).abs() < 1e-9);
        // A track without a point: its other five observations cost tau² too.
        r.tracks[1].xyz = None;
        assert!((msac_cost(&r, 2.0) - 820.0).abs() < 1e-9);
    }

    /// All-pairs correspondences of the scene's tracks, as the initial pair is chosen from.
    fn pair_correspondences(tracks: &[Track], views: usize) -> Vec<PairCorr> {
        let mut out = Vec::new();
        for i in 0..views {
            for j in i + 1..views {
                out.push(PairCorr {
                    i,
                    j,
                    x1: tracks.iter().map(|t| t.obs[i].xy).collect(),
                    x2: tracks.iter().map(|t| t.obs[j].xy).collect(),
                });
            }
        }
        out
    }

    #[test]
    fn several_initial_pairs_keep_the_model_that_explains_the_tracks_best() {
        let (k, _, _, tracks) = arc_scene(0.5);
        let pairs = pair_correspondences(&tracks, 6);
        let opts = |n: usize| SfmOptions {
            initial_pairs: n,
            ..SfmOptions::default()
        };
        let one = reconstruct(tracks.clone(), &pairs, 6, k, None, 1, &opts(1)).expect("model");
        let three = reconstruct(tracks.clone(), &pairs, 6, k, None, 3, &opts(3)).expect("model");
        assert_eq!(three.registered(), 6);
        // The three candidates start with the one pair's model, which only a cheaper one
        // replaces.
        let (c1, c3) = (msac_cost(&one, 2.0), msac_cost(&three, 2.0));
        assert!(c3 <= c1, "{c3} > {c1}");
        // And no candidate on its own beats the kept one by the margin.
        for (i0, j0, rel) in initial_pairs(&pairs, &k, &opts(3)).into_iter().take(3) {
            let r = grow(tracks.clone(), (i0, j0, rel), 6, k, None, &opts(3)).expect("model");
            assert!((1.0 - INITIAL_PAIR_MARGIN) * c3 <= msac_cost(&r, 2.0));
        }
        // It reprojects the pixels to about their noise.
        assert!(three.mean_error() < 0.6, "{}", three.mean_error());
    }
    /// Mean angle, degrees, between the model's and the truth's relative rotations over every
    /// pair of cameras (free of the gauge).
    fn relative_rotation_error(r: &Recon, truth: &[Se3]) -> f64 {
        let mut sum = 0.0;
        let mut n = 0;
        for a in 0..truth.len() {
            for b in a + 1..truth.len() {
                let (pa, pb) = (r.poses[a].unwrap(), r.poses[b].unwrap());
                let model = pb.rot * pa.rot.transpose();
                let real = truth[b].rot * truth[a].rot.transpose();
                let d = model * real.transpose();
                sum += ((d.trace() - 1.0) / 2.0)
                    .clamp(-1.0, 1.0)
                    .acos()
                    .to_degrees();
                n += 1;
            }
        }
        sum / n as f64
    }

    #[test]
    fn the_trimmed_adjustment_leaves_biased_points_out_and_keeps_them() {
        let opts = SfmOptions::default();
        let adjusted = |bias: f64| {
            let (k, poses, points, mut tracks) = arc_scene(0.05);
            // Every fifth point is measured with a vertical drift from view to view (a patch
            // across a depth edge), inside every outlier threshold; the cameras move
            // sideways, so no depth of the point explains it.
            for (i, (t, x)) in tracks.iter_mut().zip(&points).enumerate() {
                t.xyz = Some(*x);
                if i % 5 == 0 {
                    for o in &mut t.obs {
                        o.xy.y += bias * (o.view as f64 - 2.5);
                    }
                }
            }
            let mut r = Recon {
                k,
                poses: poses.iter().copied().map(Some).collect(),
                tracks,
                path: None,
            };
            run_ba(&mut r, 0, Focal::Fixed, 50, &opts);
            (r, poses)
        };
        let (clean, _) = adjusted(0.0);
        let (plain, poses) = adjusted(0.36);
        let mut trimmed = plain.clone();
        trimmed_ba(&mut trimmed, 0, 0.3, &opts);
        let [e_clean, e_plain, e_trimmed] =
            [&clean, &plain, &trimmed].map(|r| relative_rotation_error(r, &poses));
        // The biased points pull the plain adjustment off; left out, the cameras come back to
        // where the unbiased points alone put them.
        assert!(
            e_trimmed - e_clean < 0.25 * (e_plain - e_clean),
            "trimmed {e_trimmed}°, plain {e_plain}°, without bias {e_clean}°"
        );
        // The points that sat out are fitted to the new cameras and kept.
        assert_eq!(
            trimmed.tracks.iter().filter(|t| t.xyz.is_some()).count(),
            200
        );
        // Nothing to trim: unchanged.
        let mut untouched = plain.clone();
        trimmed_ba(&mut untouched, 0, 0.0, &opts);
        assert_eq!(untouched.poses, plain.poses);
    }
}
