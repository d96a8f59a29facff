//! Initial Gaussians: from SfM points (gsplat "sfm" init with the 3DGS-MCMC preset) or random
//! points inside the cameras' view frustums when no point cloud exists.
//!
//! SfM init (gsplat simple_trainer): scale = init_scale · sqrt(mean squared distance to the k = 3
//! nearest other points), isotropic; quaternion components uniform in [0, 1) (unnormalised, as
//! gsplat); opacity logit(init_opa); SH dc = (rgb − 0.5)/C0, higher bands zero.

use std::num::NonZeroUsize;

use gems_splat::sh::C0;
use gems_splat::{Camera, Gaussians, SH_COEFFS};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rand::{Rng, RngExt};
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;

use crate::TrainError;
use crate::config::InitConfig;

/// Smallest mean squared neighbour distance (keeps duplicate points from getting log(0)).
const MIN_SQ_DIST: f32 = 1e-7;

/// Per point: sqrt of the mean squared distance to its `k` nearest other points.
pub fn knn_rms_distance(points: &[[f32; 3]], k: usize) -> Result<Vec<f32>, TrainError> {
    if points.len() < 2 {
        return Err(TrainError::Input(format!(
            "need at least 2 points for nearest-neighbour scales, got {}",
            points.len()
        )));
    }
    let tree: ImmutableKdTree<f32, 3> = ImmutableKdTree::new_from_slice(points)
        .map_err(|e| TrainError::Input(format!("building the k-d tree: {e:?}")))?;
    let k = k.min(points.len() - 1);
    let want = NonZeroUsize::new(k + 1).expect("k + 1 > 0");
    Ok(points
        .par_iter()
        .map(|p| {
            let found = tree
                .query(p)
                .nearest_n::<SquaredEuclidean<f32>>(want)
                .execute();
            // The query point itself is among the results at distance 0: drop one zero.
            let mut d: Vec<f32> = found.iter().map(|r| r.distance).collect();
            d.sort_by(f32::total_cmp);
            let mean = d.iter().skip(1).take(k).sum::<f32>() / k as f32;
            mean.max(MIN_SQ_DIST).sqrt()
        })
        .collect())
}

/// Gaussians at `points` with colours `colors` (RGB in [0, 1]).
pub fn from_points<R: Rng + ?Sized>(
    points: &[[f32; 3]],
    colors: &[[f32; 3]],
    cfg: &InitConfig,
    sh_degree: u32,
    rng: &mut R,
) -> Result<Gaussians, TrainError> {
    if colors.len() != points.len() {
        return Err(TrainError::Input(format!(
            "{} points but {} colours",
            points.len(),
            colors.len()
        )));
    }
    let dist = knn_rms_distance(points, cfg.knn)?;
    let mut g = Gaussians::with_degree(sh_degree);
    let opacity = gems_splat::activation::logit(cfg.opacity);
    for ((p, c), d) in points.iter().zip(colors).zip(&dist) {
        let mut sh = [[0.0f32; 3]; SH_COEFFS];
        sh[0] = c.map(|v| (v - 0.5) / C0 as f32);
        let quat: [f32; 4] = std::array::from_fn(|_| rng.random::<f32>());
        g.push(*p, quat, [(cfg.scale_factor * d).ln(); 3], opacity, sh);
    }
    Ok(g)
}

/// Points and their RGB colours.
pub type PointCloud = (Vec<[f32; 3]>, Vec<[f32; 3]>);

/// `count` random points with random colours inside the cameras' frustums, at depths uniform in
/// [near, far] (in world units): a random camera, a random pixel, a random depth, unprojected.
pub fn random_in_frustums<R: Rng + ?Sized>(
    cams: &[Camera],
    count: usize,
    near: f32,
    far: f32,
    rng: &mut R,
) -> Result<PointCloud, TrainError> {
    if cams.is_empty() {
        return Err(TrainError::Input(
            "random initialisation needs at least one camera".into(),
        ));
    }
    if !(near > 0.0 && far > near) {
        return Err(TrainError::Input(format!(
            "random init depth range [{near}, {far}] is empty"
        )));
    }
    let mut points = Vec::with_capacity(count);
    let mut colors = Vec::with_capacity(count);
    for _ in 0..count {
        let cam = &cams[rng.random_range(0..cams.len())];
        let px = rng.random::<f32>() * cam.width as f32;
        let py = rng.random::<f32>() * cam.height as f32;
        let z = near + (far - near) * rng.random::<f32>();
        let xc = [(px - cam.cx) / cam.fx * z, (py - cam.cy) / cam.fy * z, z];
        // x_world = Rᵀ (x_cam − t).
        let d: [f32; 3] = std::array::from_fn(|i| xc[i] - cam.translation[i]);
        let r = &cam.rotation;
        points.push(std::array::from_fn(|j| {
            r[0][j] * d[0] + r[1][j] * d[1] + r[2][j] * d[2]
        }));
        colors.push(std::array::from_fn(|_| rng.random::<f32>()));
    }
    Ok((points, colors))
}

/// `count` points scattered around a sparse cloud: each copies a random source point's colour and
/// sits at a normal offset (σ = the source's RMS distance to its `knn` nearest neighbours) from it.
/// Sparse SfM clouds sample the surfaces; this fills the surfaces between their samples instead
/// of the empty space the frustums also contain.
pub fn near_points<R: Rng + ?Sized>(
    points: &[[f32; 3]],
    colors: &[[f32; 3]],
    knn: usize,
    count: usize,
    rng: &mut R,
) -> Result<PointCloud, TrainError> {
    let sigma = knn_rms_distance(points, knn)?;
    let mut out_p = Vec::with_capacity(count);
    let mut out_c = Vec::with_capacity(count);
    for _ in 0..count {
        let i = rng.random_range(0..points.len());
        let e: [f32; 3] = std::array::from_fn(|_| StandardNormal.sample(rng));
        out_p.push(std::array::from_fn(|a| points[i][a] + sigma[i] * e[a]));
        out_c.push(colors[i]);
    }
    Ok((out_p, out_c))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn knn_matches_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let pts: Vec<[f32; 3]> = (0..300)
            .map(|_| std::array::from_fn(|_| rng.random::<f32>()))
            .collect();
        let fast = knn_rms_distance(&pts, 3).unwrap();
        for (i, p) in pts.iter().enumerate().step_by(37) {
            let mut d: Vec<f32> = pts
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, q)| (0..3).map(|a| (p[a] - q[a]).powi(2)).sum())
                .collect();
            d.sort_by(f32::total_cmp);
            let want = (d[..3].iter().sum::<f32>() / 3.0).sqrt();
            assert!((fast[i] - want).abs() < 1e-5, "{} vs {want}", fast[i]);
        }
    }

    #[test]
    fn point_init_sets_scale_opacity_and_colour() {
        let pts = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 2.0, 0.0],
            [0.0, 0.0, 3.0],
        ];
        let cols = [[1.0, 0.5, 0.0]; 4];
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let g = from_points(&pts, &cols, &InitConfig::default(), 3, &mut rng).unwrap();
        g.validate().unwrap();
        // Point 0's neighbours are at distances 1, 2, 3: rms = sqrt(14/3).
        let want = (0.1f32 * (14.0f32 / 3.0).sqrt()).ln();
        assert!((g.log_scales[0][0] - want).abs() < 1e-5);
        assert!(g.opacity_logits[0].abs() < 1e-6, "logit(0.5) = 0");
        assert!((g.sh[0][0][0] * C0 as f32 + 0.5 - 1.0).abs() < 1e-5);
        assert_eq!(g.sh[0][1], [0.0; 3]);
        assert!(from_points(&pts, &cols[..2], &InitConfig::default(), 3, &mut rng).is_err());
        assert!(knn_rms_distance(&pts[..1], 3).is_err());
    }

    #[test]
    fn random_points_project_inside_some_camera_at_valid_depth() {
        let cam = Camera::look_at(
            &gems_math::Intrinsics {
                fx: 50.0,
                fy: 50.0,
                cx: 32.0,
                cy: 24.0,
                width: 64,
                height: 48,
            },
            [0.0, 0.0, -3.0],
            [0.0; 3],
            [0.0, 1.0, 0.0],
        )
        .unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let (pts, cols) = random_in_frustums(&[cam], 500, 0.5, 4.0, &mut rng).unwrap();
        assert_eq!(cols.len(), 500);
        for p in &pts {
            let r = &cam.rotation;
            let xc: [f32; 3] = std::array::from_fn(|i| {
                (0..3).map(|j| r[i][j] * p[j]).sum::<f32>() + cam.translation[i]
            });
            assert!(xc[2] >= 0.5 - 1e-4 && xc[2] <= 4.0 + 1e-4);
            let u = cam.fx * xc[0] / xc[2] + cam.cx;
            let v = cam.fy * xc[1] / xc[2] + cam.cy;
            assert!((-1e-3..=64.001).contains(&u) && (-1e-3..=48.001).contains(&v));
        }
        assert!(random_in_frustums(&[], 5, 0.5, 4.0, &mut rng).is_err());
    }

    #[test]
    fn near_points_scatter_at_the_neighbour_scale_with_source_colours() {
        // Two clusters of 50 points on a plane: one spaced 0.01 apart, one 0.1 apart.
        let mut pts = Vec::new();
        let mut cols = Vec::new();
        for (spacing, x0, colour) in [
            (0.01f32, 0.0f32, [1.0, 0.0, 0.0]),
            (0.1, 10.0, [0.0, 0.0, 1.0]),
        ] {
            for i in 0..50 {
                pts.push([
                    x0 + spacing * (i % 10) as f32,
                    spacing * (i / 10) as f32,
                    0.0,
                ]);
                cols.push(colour);
            }
        }
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let (new_p, new_c) = near_points(&pts, &cols, 3, 4000, &mut rng).unwrap();
        assert_eq!((new_p.len(), new_c.len()), (4000, 4000));
        let (mut red, mut blue) = (Vec::new(), Vec::new());
        for (p, c) in new_p.iter().zip(&new_c) {
            // Colour says which cluster the point came from; z is the pure offset.
            if c[0] == 1.0 {
                assert!(p[0] < 5.0);
                red.push(p[2].abs());
            } else {
                assert!(c[2] == 1.0 && p[0] > 5.0);
                blue.push(p[2].abs());
            }
        }
        // E|N(0, σ)| = σ·sqrt(2/π); σ ≈ the spacing (slightly more: diagonal neighbours).
        let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len() as f32;
        let (r, b) = (mean(&red), mean(&blue));
        assert!(red.len() > 1500 && blue.len() > 1500);
        assert!((0.007..0.012).contains(&r), "red offset {r}");
        assert!((0.07..0.12).contains(&b), "blue offset {b}");
        assert!(near_points(&pts[..1], &cols[..1], 3, 5, &mut rng).is_err());
    }
}
