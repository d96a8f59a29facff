//! Dense initial points for the run proper from a confirmed first model
//! (`init.confirmed_dense_points`), or from the renders' model (`init.renders_dense_points`,
//! whose maps are attached to that model's own cameras: [`ModelCameras`]).
//!
//! Once the SfM on the first pass's renders has confirmed the first model's cameras, those
//! cameras are accurate, but the run proper still starts from the model's sparse points, which
//! lie only where the photos have texture, topped up with points scattered around them. With
//! exact surface points the
//! same cameras train 1.7 dB better (BENCHMARKS.md, "Is depth the missing part? An oracle"),
//! and denser SfM tracks do not give that. The first pass's Gaussians render a depth for every
//! pixel: each view's surface-depth map (`gems_splat::Renderer::surface_depth`: where the
//! pixel's ray meets the Gaussian that halves its transmittance), rendered at its trained
//! midpoint, is aligned to the first model's sparse depths in that view (one scale per view,
//! the median ratio: the first pass's scene is its own, and depth is useful only in the
//! cameras' frame, as the oracle showed), back-projected from the model's camera, and a
//! pixel's point is kept only where the aligned depths of at least [`MIN_AGREEING_VIEWS`]
//! other views agree with it (a floater or a depth averaged across an edge is seen by no other
//! view at that depth).
//!
//! Why surface depth: expected depth, the opacity-weighted mean of the Gaussians' centre
//! depths composited front to back, lies up to 3 % in front of a slanted surface (the test
//! below); surface depth lies within 0.2 %. Depths are read between pixel centres
//! bilinearly, for the same reason: on a slanted surface the depth changes across a pixel by
//! more than the agreement's tolerance.

use gems_data::colmap::{Point3D, SparseModel};
use gems_math::{Intrinsics, Se3, Vector3};
use gems_splat::{Camera, Gaussians, RenderSettings, Renderer};
use gems_train::TrainOutput;

use crate::PipelineError;

/// Opacity a rendered pixel needs for its depth to be used (`1 − T`).
pub const MIN_ALPHA: f32 = 0.95;
/// Relative depth difference within which another view agrees with a point.
pub const DEPTH_TOLERANCE: f64 = 0.01;
/// Other views that must agree with a pixel's point for it to be kept.
pub const MIN_AGREEING_VIEWS: usize = 2;
/// Sparse points a view needs to align its depth map; a view with fewer gives no points.
pub const MIN_ALIGNMENT_POINTS: usize = 8;
/// Candidate pixels per wanted point: the grid is chosen this much denser than `target`, since
/// the agreement test drops a share of them.
const OVERSAMPLING: f64 = 4.0;

/// One view's rendered maps and the camera they are attached to.
pub struct DepthView {
    /// The camera the maps are attached to (the view's confirmed initial camera), world to
    /// camera.
    pub w2c: Se3,
    pub intrinsics: Intrinsics,
    /// `[H,W,3]` rendered colour.
    pub rgb: Vec<f32>,
    /// `[H,W]` rendered opacity `1 − T`.
    pub alpha: Vec<f32>,
    /// `[H,W]` rendered surface depth (camera z; 0 where nothing is drawn).
    pub depth: Vec<f32>,
}

impl DepthView {
    fn size(&self) -> (usize, usize) {
        (
            self.intrinsics.width as usize,
            self.intrinsics.height as usize,
        )
    }

    /// Camera-frame point of world point `p`, and the rendered depth where it projects when
    /// it is in front and the render is opaque there ([`Self::depth_near`]).
    fn depth_seen(&self, p: &Vector3<f64>) -> (Vector3<f64>, Option<f64>) {
        let c = self.w2c.rot * p + self.w2c.trans;
        if c.z <= 0.0 {
            return (c, None);
        }
        let k = &self.intrinsics;
        let (u, v) = (k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy);
        (c, self.depth_near(u, v))
    }

    /// The rendered depth at a pixel when the render is opaque there.
    fn depth_at(&self, pixel: usize) -> Option<f64> {
        let d = self.depth[pixel];
        (self.alpha[pixel] >= MIN_ALPHA && d.is_finite() && d > 0.0).then_some(f64::from(d))
    }

    /// The rendered depth at image point `(u, v)` (a pixel's centre at `x + 0.5`), interpolated
    /// bilinearly between the four nearest pixel centres when all four are opaque: on a slanted
    /// surface the depth changes across one pixel by more than [`DEPTH_TOLERANCE`], so the
    /// nearest pixel's depth would misjudge both the alignment and the agreement.
    fn depth_near(&self, u: f64, v: f64) -> Option<f64> {
        let (w, h) = self.size();
        if !(u >= 0.0 && v >= 0.0 && u <= w as f64 && v <= h as f64) {
            return None;
        }
        let (x, y) = (
            (u - 0.5).clamp(0.0, (w - 1) as f64),
            (v - 0.5).clamp(0.0, (h - 1) as f64),
        );
        let (x0, y0) = (
            (x as usize).min(w.saturating_sub(2)),
            (y as usize).min(h.saturating_sub(2)),
        );
        let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
        let (ax, ay) = (x - x0 as f64, y - y0 as f64);
        let d00 = self.depth_at(y0 * w + x0)?;
        let d10 = self.depth_at(y0 * w + x1)?;
        let d01 = self.depth_at(y1 * w + x0)?;
        let d11 = self.depth_at(y1 * w + x1)?;
        Some((1.0 - ay) * ((1.0 - ax) * d00 + ax * d10) + ay * ((1.0 - ax) * d01 + ax * d11))
    }

    /// The factor that brings the rendered depths onto `sparse`'s: the median over the sparse
    /// points seen at an opaque pixel of (their depth / the rendered one).
    fn alignment(&self, sparse: &[Vector3<f64>]) -> Option<f64> {
        let mut ratios: Vec<f64> = sparse
            .iter()
            .filter_map(|p| {
                let (c, d) = self.depth_seen(p);
                Some(c.z / d?)
            })
            .collect();
        if ratios.len() < MIN_ALIGNMENT_POINTS {
            return None;
        }
        ratios.sort_by(f64::total_cmp);
        Some(ratios[ratios.len() / 2])
    }
}

/// A fused point in the frame of the views' cameras, with its rendered colour.
#[derive(Clone, Debug, PartialEq)]
pub struct DensePoint {
    pub xyz: Vector3<f64>,
    pub rgb: [f32; 3],
}

/// Fuses the views' depth maps into at most `target` points (fewer when fewer agree): each
/// view's map scaled to the `sparse` points (the median ratio of their depths to the rendered
/// ones, `DepthView::alignment`), sampled on a grid as dense as `target` asks, back-projected,
/// and kept where [`MIN_AGREEING_VIEWS`] other views' aligned depths agree within
/// [`DEPTH_TOLERANCE`]. Views that cannot be aligned give and check
/// nothing. Deterministic: the kept points are thinned evenly, in view and pixel order.
pub fn fuse_depth_maps(
    views: &[DepthView],
    sparse: &[Vector3<f64>],
    target: usize,
) -> Vec<DensePoint> {
    if target == 0 {
        return Vec::new();
    }
    let scales: Vec<Option<f64>> = views.iter().map(|v| v.alignment(sparse)).collect();
    tracing::debug!(?scales, "depth maps aligned to the sparse points");
    let opaque: usize = views
        .iter()
        .zip(&scales)
        .filter(|(_, s)| s.is_some())
        .map(|(v, _)| v.alpha.iter().filter(|&&a| a >= MIN_ALPHA).count())
        .sum();
    let stride = ((opaque as f64 / (OVERSAMPLING * target as f64))
        .sqrt()
        .floor() as usize)
        .max(1);
    let mut kept = Vec::new();
    for (i, (view, scale)) in views.iter().zip(&scales).enumerate() {
        let Some(scale) = scale else { continue };
        let (w, h) = view.size();
        let k = &view.intrinsics;
        let c2w = view.w2c.inverse();
        for row in (stride / 2..h).step_by(stride) {
            for col in (stride / 2..w).step_by(stride) {
                let pixel = row * w + col;
                let Some(d) = view.depth_at(pixel) else {
                    continue;
                };
                let z = scale * d;
                let ray = Vector3::new(
                    (col as f64 + 0.5 - k.cx) / k.fx,
                    (row as f64 + 0.5 - k.cy) / k.fy,
                    1.0,
                );
                let xyz = c2w.rot * (ray * z) + c2w.trans;
                let agreeing = views
                    .iter()
                    .zip(&scales)
                    .enumerate()
                    .filter(|&(j, (other, s))| {
                        let Some(s) = s.filter(|_| j != i) else {
                            return false;
                        };
                        let (c, d) = other.depth_seen(&xyz);
                        d.is_some_and(|d| (c.z - s * d).abs() <= DEPTH_TOLERANCE * c.z)
                    })
                    .count();
                if agreeing >= MIN_AGREEING_VIEWS {
                    let rgb = &view.rgb[3 * pixel..3 * pixel + 3];
                    kept.push(DensePoint {
                        xyz,
                        rgb: [rgb[0], rgb[1], rgb[2]],
                    });
                }
            }
        }
    }
    if kept.len() > target {
        let step = kept.len() as f64 / target as f64;
        kept = (0..target)
            .map(|n| kept[(n as f64 * step) as usize].clone())
            .collect();
    }
    kept
}

/// One view to render for the fusion: the camera the first pass's Gaussians are seen from, and
/// the camera of the model the fused points are for, which the maps are attached to. Both
/// cameras have the same image size; their intrinsics differ when the model is another SfM's
/// (it estimated its own focal on the same pixels).
#[derive(Clone, Copy, Debug)]
pub struct DepthCamera {
    /// Where the maps are rendered: the first pass's intrinsics and camera to world.
    pub render: (Intrinsics, Se3),
    /// The model's camera the maps belong to: its intrinsics and camera to world.
    pub attach: (Intrinsics, Se3),
}

/// Renders `gaussians` from each [`DepthCamera`] with surface depth
/// (`gems_splat::Renderer::surface_depth`): the maps made at its `render` camera (where the
/// Gaussians were trained to be seen from), attached to its `attach` camera. On the CPU
/// renderer whatever the training engine: surface depth is a CPU-only, forward-only pass, and a
/// few dozen views cost seconds.
pub fn render_depth_views(
    gaussians: &Gaussians,
    cameras: &[DepthCamera],
) -> Result<Vec<DepthView>, PipelineError> {
    let settings = RenderSettings::default();
    let mut renderer = Renderer::new();
    cameras
        .iter()
        .map(|c| {
            let (k, render_c2w) = &c.render;
            let (attach_k, attach_c2w) = &c.attach;
            let cam = [Camera::from_c2w(k, render_c2w)];
            let out = renderer.forward(gaussians, &cam, &[[0.0; 3]], &settings)?;
            Ok(DepthView {
                w2c: attach_c2w.inverse(),
                intrinsics: *attach_k,
                depth: renderer.surface_depth(gaussians, &cam)?,
                rgb: out.rgb,
                alpha: out.alpha,
            })
        })
        .collect()
}

/// Which cameras of a model the fused points are attached to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelCameras {
    /// The model the first pass trained from: its cameras are the first pass's initial ones,
    /// in the first pass's frame.
    FirstPass,
    /// Another model of the same training views (the SfM on the first pass's renders, which
    /// are these very pixels): its own cameras, matched by image name, in its own frame. A
    /// view the model lacks gives no points.
    Own,
}

/// `model` with dense points added: the first pass (`first`) renders each training view at its
/// trained midpoint, and [`fuse_depth_maps`] turns the maps, attached to the view's camera in
/// `model` (`cameras`), into up to `target` points beside the model's own. Returns the model and
/// how many points it gained.
pub fn with_dense_points(
    first: &TrainOutput,
    model: &SparseModel,
    cameras: ModelCameras,
    target: usize,
) -> Result<(SparseModel, usize), PipelineError> {
    let norm = &first.normalization;
    let depth_cameras: Vec<DepthCamera> = first
        .views
        .iter()
        .filter_map(|v| {
            let render = (v.intrinsics, Se3::from(&v.mid_c2w));
            let attach = match cameras {
                ModelCameras::FirstPass => (v.intrinsics, Se3::from(&v.c2w_init)),
                ModelCameras::Own => {
                    let image = model.image_by_name(&v.name)?;
                    let k = model.camera(image.camera_id)?.intrinsics().ok()?;
                    (
                        k.resized(v.intrinsics.width, v.intrinsics.height),
                        Se3::from(&image.pose()).inverse(),
                    )
                }
            };
            Some(DepthCamera { render, attach })
        })
        .collect();
    let views = render_depth_views(&first.gaussians, &depth_cameras)?;
    // The sparse points in the cameras' frame, and the fused points back in the model's.
    let to_cameras = |p: Vector3<f64>| match cameras {
        ModelCameras::FirstPass => norm.apply_point(&p),
        ModelCameras::Own => p,
    };
    let to_model = |p: &Vector3<f64>| match cameras {
        ModelCameras::FirstPass => norm.invert_point(p),
        ModelCameras::Own => *p,
    };
    let sparse: Vec<Vector3<f64>> = model
        .points
        .iter()
        .map(|p| to_cameras(Vector3::from(p.xyz)))
        .collect();
    let fused = fuse_depth_maps(&views, &sparse, target);
    let next_id = model.points.iter().map(|p| p.id).max().unwrap_or(0) + 1;
    let mut dense = model.clone();
    dense
        .points
        .extend(fused.iter().zip(next_id..).map(|(p, id)| {
            let xyz = to_model(&p.xyz);
            Point3D {
                id,
                xyz: [xyz.x, xyz.y, xyz.z],
                rgb: p.rgb.map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8),
                error: -1.0,
                track: Vec::new(),
            }
        }));
    Ok((dense, fused.len()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use gems_math::Vector6;

    /// The 40×30 camera every test view uses.
    fn test_camera() -> Intrinsics {
        Intrinsics {
            fx: 40.0,
            fy: 40.0,
            cx: 20.0,
            cy: 15.0,
            width: 40,
            height: 30,
        }
    }

    /// The plane z = 5 seen by cameras along x looking down +z; `depth_scale` distorts one
    /// view's rendered depth as a first pass's own scene scale would.
    fn plane_view(x: f64, depth_scale: f64, floater: bool) -> DepthView {
        let k = test_camera();
        let c2w = Se3::exp(&Vector6::new(x, 0.0, 0.0, 0.0, 0.0, 0.0));
        let n = 40 * 30;
        let mut depth = vec![(5.0 / depth_scale) as f32; n];
        if floater {
            // A blob of wrong depth that no other view sees there (away from where the sparse
            // points project, so that the alignment is not what rejects it).
            for row in 10..20 {
                for col in 25..35 {
                    depth[row * 40 + col] = 2.0;
                }
            }
        }
        DepthView {
            w2c: c2w.inverse(),
            intrinsics: k,
            rgb: vec![0.5; 3 * n],
            alpha: vec![1.0; n],
            depth,
        }
    }

    fn sparse_on_plane() -> Vec<Vector3<f64>> {
        (0..40)
            .map(|i| {
                Vector3::new(
                    -1.0 + 0.1 * f64::from(i % 8),
                    -0.8 + 0.4 * f64::from(i / 8),
                    5.0,
                )
            })
            .collect()
    }

    #[test]
    fn fused_points_lie_on_the_surface_in_the_cameras_frame() {
        // Every view's depth off by its own factor: the alignment puts all of them back.
        let views: Vec<DepthView> = [
            (-0.5, 1.1),
            (-0.2, 0.9),
            (0.0, 1.0),
            (0.3, 1.2),
            (0.6, 0.95),
        ]
        .iter()
        .map(|&(x, s)| plane_view(x, s, false))
        .collect();
        let points = fuse_depth_maps(&views, &sparse_on_plane(), 500);
        assert!(points.len() > 300, "{} points", points.len());
        assert!(points.len() <= 500);
        for p in &points {
            assert!((p.xyz.z - 5.0).abs() < 1e-9, "{:?}", p.xyz);
            assert_eq!(p.rgb, [0.5; 3]);
        }
    }

    #[test]
    fn a_depth_no_other_view_agrees_with_gives_no_points() {
        let views: Vec<DepthView> = [-0.5, -0.2, 0.0, 0.3, 0.6]
            .iter()
            .enumerate()
            .map(|(i, &x)| plane_view(x, 1.0, i == 2))
            .collect();
        let points = fuse_depth_maps(&views, &sparse_on_plane(), 100_000);
        assert!(!points.is_empty());
        assert!(points.iter().all(|p| (p.xyz.z - 5.0).abs() < 1e-9));
        // Without the agreement test the blob would give points at z = 2.
        let lone = fuse_depth_maps(&views[2..3], &sparse_on_plane(), 100_000);
        assert!(lone.is_empty(), "one view agrees with nothing");
    }

    /// A similarity of 3D space, `p ↦ scale · rot · p + trans`: another model's frame.
    #[derive(Clone, Copy)]
    struct Similarity {
        rot: Se3,
        scale: f64,
    }

    impl Similarity {
        fn identity() -> Self {
            Self {
                rot: Se3::identity(),
                scale: 1.0,
            }
        }

        fn point(&self, p: &Vector3<f64>) -> Vector3<f64> {
            self.scale * (self.rot.rot * p) + self.rot.trans
        }

        fn inverse_point(&self, p: &Vector3<f64>) -> Vector3<f64> {
            self.rot.rot.transpose() * ((p - self.rot.trans) / self.scale)
        }

        fn c2w(&self, c2w: &Se3) -> Se3 {
            Se3 {
                rot: self.rot.rot * c2w.rot,
                trans: self.point(&c2w.trans),
            }
        }
    }

    /// Points fused from the CPU engine's renders of small opaque discs tiling the slanted
    /// plane z = 5 + `slope`·x, each map attached to the camera it was rendered from carried
    /// into the frame `frame` (with the sparse points); returns each point's signed depth error
    /// along z, once carried back.
    fn fused_slanted_plane(slope: f64, frame: Similarity) -> Vec<f64> {
        let plane_z = |x: f64| 5.0 + slope * x;
        let mut g = Gaussians::with_degree(0);
        let mut sh = [[0.0f32; 3]; gems_splat::SH_COEFFS];
        sh[0] = [0.5; 3];
        // The discs' normal (−slope, 0, 1): the z axis turned about y.
        let half = (-slope).atan() as f32 / 2.0;
        let quat = [half.cos(), 0.0, half.sin(), 0.0];
        let (disc, thin) = (0.015f32.ln(), 0.001f32.ln());
        for i in -100..=100 {
            for j in -90..=90 {
                let (x, y) = (0.02 * f64::from(i), 0.02 * f64::from(j));
                let mean = [x as f32, y as f32, plane_z(x) as f32];
                g.push(mean, quat, [disc, disc, thin], 8.0, sh);
            }
        }
        let k = test_camera();
        let cameras: Vec<DepthCamera> = [-0.3, -0.1, 0.1, 0.3]
            .iter()
            .map(|&x| {
                let c2w = Se3::exp(&Vector6::new(x, 0.1, 0.0, 0.0, 0.0, 0.0));
                DepthCamera {
                    render: (k, c2w),
                    attach: (k, frame.c2w(&c2w)),
                }
            })
            .collect();
        let views = render_depth_views(&g, &cameras).unwrap();
        let sparse: Vec<Vector3<f64>> = (0..40)
            .map(|i| {
                let (x, y) = (
                    -0.5 + 0.15 * f64::from(i % 8),
                    -0.6 + 0.3 * f64::from(i / 8),
                );
                frame.point(&Vector3::new(x, y, plane_z(x)))
            })
            .collect();
        let points = fuse_depth_maps(&views, &sparse, 1000);
        assert!(points.len() > 400, "{} points", points.len());
        points
            .iter()
            .map(|p| {
                let xyz = frame.inverse_point(&p.xyz);
                xyz.z - plane_z(xyz.x)
            })
            .collect()
    }

    #[test]
    fn the_renderers_depth_maps_of_a_surface_fuse_onto_it() {
        // The plane's slant makes the depth change by about 0.12 a pixel. Surface depth follows
        // it: the points lie within 0.2 % of their depth (expected depth, the Gaussians'
        // composited centre depths, put them up to 3 % in front). A pixel-centre convention
        // differing between the renderer and the back-projection would shift the two mirrored
        // planes' points in opposite directions, by about 0.06.
        let (rising, falling) = (
            fused_slanted_plane(1.0, Similarity::identity()),
            fused_slanted_plane(-1.0, Similarity::identity()),
        );
        let mean = |e: &[f64]| e.iter().sum::<f64>() / e.len() as f64;
        for errors in [&rising, &falling] {
            let worst = errors.iter().fold(0.0f64, |w, e| w.max(e.abs()));
            assert!(worst < 0.01, "a point {worst} off the plane");
        }
        let (a, b) = (mean(&rising), mean(&falling));
        assert!((a - b).abs() < 0.002, "mean errors {a} and {b}");
    }

    #[test]
    fn maps_attached_to_another_models_cameras_fuse_in_its_frame() {
        // Another model of the same pixels (the SfM on the renders) has its own frame: turned,
        // moved and three times smaller. The per-view alignment takes its scale, and the points
        // land on the plane as that model places it, as precisely as in the renders' own frame.
        let frame = Similarity {
            rot: Se3::exp(&Vector6::new(0.4, -1.2, 2.0, 0.3, -0.5, 0.2)),
            scale: 1.0 / 3.0,
        };
        let errors = fused_slanted_plane(1.0, frame);
        let worst = errors.iter().fold(0.0f64, |w, e| w.max(e.abs()));
        assert!(worst < 0.01, "a point {worst} off the plane");
    }

    #[test]
    fn views_that_cannot_be_aligned_give_nothing() {
        let views: Vec<DepthView> = [-0.5, 0.0, 0.5]
            .iter()
            .map(|&x| plane_view(x, 1.0, false))
            .collect();
        assert!(
            fuse_depth_maps(&views, &sparse_on_plane()[..MIN_ALIGNMENT_POINTS - 1], 100).is_empty()
        );
        assert!(fuse_depth_maps(&views, &sparse_on_plane(), 0).is_empty());
    }
}
