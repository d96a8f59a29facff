//! Built-in blur-robust structure from motion.
//!
//! Pipeline ([`run_sfm`]):
//! 1. the motion-blur length is estimated from the images (autocorrelation of the directional
//!    derivative, [`SfmStats::blur_px_estimate`]); the *working levels* (long side
//!    [`SfmOptions::working_sizes`]) are tried nearest-first to the level where the blur is about
//!    10 px, until one registers every view. Shi–Tomasi keypoints of the smoothed working image
//!    are described by normalised patches ([`features`]);
//! 2. all pairs are matched (mutual nearest neighbour + ratio test) and verified with a
//!    fundamental-matrix RANSAC; verified matches are chained into tracks (union–find);
//! 3. each view's keypoints plus a grid of well-conditioned, isotropic patches
//!    ([`SfmOptions::max_query_points`]) are tracked by patch NCC + Lucas–Kanade into its
//!    best-overlapping views ([`SfmOptions::track_neighbours`], found from thumbnail correlation,
//!    not from the file order), each point from the view of its track nearest the target, so
//!    tracks stay long; every tracked pair is verified by a fundamental-matrix RANSAC;
//! 4. the initial pair maximises inliers × parallax (up to 6°); its essential matrix gives the
//!    first two poses; further views are added by RANSAC PnP, tracks are triangulated with angle,
//!    depth and reprojection checks, and a robust (Huber) Levenberg–Marquardt bundle adjustment
//!    with a Schur complement over points runs after each registration ([`ba`]);
//! 5. the focal length is taken from [`SfmOptions::focal_px`] when known; otherwise a
//!    reconstruction is made with each candidate of [`SfmOptions::focal_candidates`] held fixed
//!    (a free focal drifts along its weak direction under blur). The one registering most views
//!    wins; candidates whose mean errors are within 1 % of the best are ties (under blur the error
//!    is nearly flat in the focal) decided by a 53° field-of-view prior; when the list's first
//!    or last candidate wins, candidates are added beyond it while they win
//!    ([`SfmOptions::focal_search_span`]); a final bundle adjustment refines the focal inside
//!    the bracket of the neighbouring candidates;
//! 6. coarse to fine: the model is re-measured and bundle-adjusted at the finest level where the
//!    estimated blur is at most [`SfmOptions::refine_max_blur_px`], then once more there; each
//!    template is warped into the other view by the model's local surface map, with patches
//!    sized to the blur ([`SfmOptions::refine_patch_blur_ratio`]) and, where the blur there is
//!    short, each match's window corrected by an affine map
//!    ([`SfmOptions::refine_affine_max_blur_px`]); an estimated focal is
//!    refined once more there, anywhere within the candidates' span; with
//!    [`SfmOptions::capture_order`], every bundle adjustment also holds the camera path smooth;
//! 7. a last bundle adjustment moves the cameras on the best-measured points only, the
//!    [`SfmOptions::trim_fraction`] that fit worst sitting out and then re-fitted to them.
//!
//! Every input view is either registered or listed in [`SfmStats::unregistered`]. Fewer than two
//! registered views is an error ([`SfmError::TooFewRegistered`]), as are degenerate inputs.
//!
//! [`write_outputs`] writes the COLMAP model (`sparse/0`, via `gems_data::colmap`), the
//! `sfm_report.json` and a top-view PNG of cameras and points.

pub mod ba;
mod colmap_cli;
pub mod features;
pub mod geometry;
mod incremental;
mod output;
mod refine;
mod tracking;

pub use colmap_cli::{ColmapCliOptions, run_colmap_cli};
pub use gems_data::colmap::SparseModel;
pub use output::{REPORT_FILE, draw_top_view, is_builtin_model, to_colmap_model, write_outputs};

use features::{FeatureParams, Features, Gray};
use rayon::prelude::*;
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;

/// Motion blur, in working-level pixels, that the first working size tried aims at.
const TARGET_BLUR_PX: f64 = 10.0;

/// One input image with the name it will carry in the COLMAP model.
#[derive(Clone, Debug)]
pub struct SfmImage {
    pub name: String,
    pub image: image::RgbImage,
}

/// Relative width (σ over the focal) of the prior under which a focal read from the photos'
/// metadata is refined: EXIF focal lengths are rounded and lens-dependent (blurball's is 4.9 %
/// below its COLMAP model's), and with this prior the SfM brings it within 2 % there while it
/// pulls an exact one by about 1 % on average (crates/gems-init/BENCHMARKS.md, "The focal prior
/// after coarse to fine"). A calibration the user gives is held.
pub const EXIF_FOCAL_PRIOR: f64 = 0.02;

/// Settings of [`run_sfm`].
#[derive(Clone, Debug)]
pub struct SfmOptions {
    /// Focal length in full-resolution pixels when known (a calibration, or metadata); it is
    /// then held fixed, unless `focal_prior` says how well it is known.
    pub focal_px: Option<f64>,
    /// With `focal_px`: its relative uncertainty (σ as a fraction of the focal). The
    /// reconstruction is made with the focal held fixed, then a final bundle adjustment refines
    /// it under a Gaussian prior of that width. `None` keeps it fixed (a calibrated camera).
    pub focal_prior: Option<f64>,
    /// The images' motion-blur length in full-size pixels when it is known, in place of the
    /// estimate from the images' edges ([`estimate_blur_px`]) wherever the blur decides
    /// something: the working levels, coarse to fine, patch sizes, affine matching, trimming.
    /// Renders of a trained scene have no motion blur, yet their softness reads as blur: on a
    /// first pass's renders at 30 px of true blur the estimate said 20 px, the model was made
    /// at 96 px instead of 200 and its cameras came out 3.1 % of the path extent from the
    /// cameras the renders were made at, 0.4 % told 1 px (crates/gems-init/BENCHMARKS.md, "A
    /// known blur for soft, unblurred images"). `None` estimates it; the report's per-photo
    /// figures are the estimates either way.
    pub blur_px: Option<f64>,
    /// Candidate focal lengths as multiples of the long image side, used when `focal_px` is None.
    /// When the chosen one is the first or the last, candidates are added beyond it, in the
    /// list's own ratio at that end, while the added one is chosen, within
    /// `focal_search_span`.
    pub focal_candidates: Vec<f64>,
    /// How far, as multiples of the long image side, the focal candidates are extended beyond
    /// the list's ends when an end candidate wins. Default 0.3–4.0 (fields of view of 118° to
    /// 14° across the long side): the list's 0.6–1.7 (80° to 33°) left a 25° telephoto view
    /// 25 % short of its focal and a 100° wide one 20–43 % long, and their cameras 5–25× less
    /// precise than with the focal given (crates/gems-init/BENCHMARKS.md, "Focal lengths
    /// outside the candidates"). The list's own ends: no extension.
    pub focal_search_span: (f64, f64),
    /// Long side, in pixels, of the pyramid levels, tried nearest-first to the level where the
    /// estimated blur is about 10 px; the first that registers every view is kept, otherwise
    /// the best over all. A size above the images' own long side means the images themselves
    /// (they are never upsampled).
    pub working_sizes: Vec<u32>,
    /// Keypoints per image at the working level.
    pub max_features: usize,
    /// Minimum verified matches for an image pair to count.
    pub min_pair_inliers: usize,
    /// Inlier threshold for RANSAC, PnP and track filtering, in working-level pixels.
    pub max_reproj_px: f64,
    /// Minimum triangulation angle of a new point, degrees.
    pub min_tri_angle_deg: f64,
    /// Spacing of the dense grid of extra tracking query points, as a fraction of the working
    /// level's long side (0 disables the grid and tracks keypoints only).
    pub grid_spacing_frac: f32,
    /// Best-overlapping views each view's points are tracked into.
    pub track_neighbours: usize,
    /// Tracking query points per view: its keypoints, then (only when they are fewer than a
    /// third of this) grid points, up to this many (the cost of tracking grows with it).
    pub max_query_points: usize,
    /// Whether consecutive images (in the order given: the file names' order for a folder,
    /// capture order for video frames) are consecutive captures. Ordered images get a weak
    /// smoothness prior on the camera path in every bundle adjustment ([`ba::PathPrior`]).
    /// Default [`CaptureOrder::Unordered`]: on generated arcs at every blur level the prior
    /// moved centre errors by −4.5 % on average and relative rotations by +6 %, some scenes
    /// either way by 40 %, and it made blurball's rough hand-held path worse
    /// (crates/gems-init/BENCHMARKS.md, "A smoothness prior in capture order").
    pub capture_order: CaptureOrder,
    /// The path prior's σ for the centres' second difference, as a fraction of the mean
    /// distance between consecutive cameras; 0 leaves centres out.
    pub path_centre_sigma: f64,
    /// The path prior's σ for the change of the rotation step between captures, degrees; 0
    /// leaves rotations out.
    pub path_rotation_sigma_deg: f64,
    /// Coarse-to-fine: the model made at the working level is re-measured and bundle-adjusted
    /// at the finest level where the estimated blur is at most this many pixels (the photos'
    /// own size at most; steps of at most 2×, each kept only while every registered view stays
    /// well observed). 0 turns it off. Much past 12 px the smear biases the re-measured points
    /// more than the finer pixels help under heavy blur.
    pub refine_max_blur_px: f64,
    /// Half-size of the tracking patch where the model is re-measured, as a multiple of the
    /// estimated blur at that level (4–10 px). A patch needs about the smear's extent to stay
    /// distinctive, and a smaller one is less biased by foreshortening and by depth edges, so
    /// nearly sharp photos are re-measured with small patches. 0 keeps the working level's
    /// size (9 % of the long side). Default 0.75 (crates/gems-init/BENCHMARKS.md, "Warped,
    /// blur-sized patches").
    pub refine_patch_blur_ratio: f64,
    /// With `focal_px` given: initial pairs (the best by inliers and parallax) each grown into
    /// a model at the working level; the best pair's model is kept unless another explains
    /// the tracks clearly better (truncated reprojection errors over every track, 5 % lower).
    /// Under heavy blur the best pair alone can lock the model into a wrong basin (a 40° arc
    /// reconstructed as 27°). With the focal unknown every focal candidate grows one model from
    /// the best pair: there more pairs cost twice the time and were not better on average.
    /// Default 3
    /// (crates/gems-init/BENCHMARKS.md, "Several initial pairs"); 1 grows one model.
    pub initial_pairs: usize,
    /// Fraction of the points, those with the largest RMS reprojection error, left out of a
    /// last bundle adjustment of the cameras (then re-fitted to them and kept when they fit),
    /// when the photos' estimated blur is at most `trim_max_blur` of their long side. 0 turns
    /// it off. Default 0.4: on generated scenes at blur levels 1–7 centre errors fell by 9–57 %
    /// (level 1: 0.115 → 0.049 % of the path extent); blurball 0.81 → 0.78 %
    /// (crates/gems-init/BENCHMARKS.md, "Cameras adjusted on the best-measured points").
    pub trim_fraction: f64,
    /// The largest estimated blur, as a fraction of the photos' long side, at which
    /// `trim_fraction` applies. Default 0.1: under heavier blur the smear biases every track,
    /// not a minority, and trimming made the cameras 1–3.5 % worse at levels 9–11 (10.8 and
    /// 12.9 % of the long side) and a `gems bench-quality` scene (14.5 %) trained 0.4 dB worse
    /// refined from its better cameras (same section).
    pub trim_max_blur: f64,
    /// Where the model is re-measured and the estimated blur there is at most this many pixels,
    /// each match is refined with an affine map of its window (the predicted surface warp
    /// corrected, damped toward it), not by translation alone: the predicted warp assumes a
    /// surface facing the two views' bisector, and where that is wrong a translation-only match
    /// is biased the same way all along a camera arc. Under more smear the map also fits the
    /// views' differing smears. 0 turns it off. Default 10: on 16 sharp scenes the centres came
    /// out 0.086 → 0.048 % of the path extent and the estimated focal 1.54 → 0.90 % off; at
    /// 5.5 px of true blur the scenes it applies to are no better (0.346 → 0.373 %), and from
    /// 14 px of blur (blurball included) it does not apply (crates/gems-init/BENCHMARKS.md,
    /// "Affine re-measurement of nearly sharp photos").
    pub refine_affine_max_blur_px: f64,
    /// Seed of every random choice (RANSAC); same seed, same result.
    pub seed: u64,
}

/// Whether the images' order is their capture order; see [`SfmOptions::capture_order`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum CaptureOrder {
    /// Measured from the views' thumbnails: ordered when, for at least 80 % of consecutive
    /// images, the next is one of the two whose thumbnails look most like an image's (or the
    /// other way round).
    Detect,
    /// Known to be ordered (frames of a video).
    Ordered,
    /// No order: the path prior is off.
    #[default]
    Unordered,
}

impl Default for SfmOptions {
    fn default() -> Self {
        SfmOptions {
            focal_px: None,
            focal_prior: None,
            blur_px: None,
            focal_candidates: vec![0.6, 0.75, 0.9, 1.1, 1.35, 1.7],
            focal_search_span: (0.3, 4.0),
            // 256 and 384 for photos that are large and not very blurred: Deblur-NeRF's
            // blurball (2400 px, 100 px of blur) registers at 256 with 1.05 % of centre error
            // against the dataset's COLMAP model instead of 1.44 % at 192, and a nearly sharp
            // 240 px scene at its own size with 0.07 % instead of 0.16 %
            // (crates/gems-init/BENCHMARKS.md).
            working_sizes: vec![384, 256, 192, 128, 96, 64],
            max_features: 500,
            min_pair_inliers: 20,
            max_reproj_px: 2.0,
            min_tri_angle_deg: 1.0,
            grid_spacing_frac: 0.04,
            track_neighbours: 8,
            max_query_points: 300,
            capture_order: CaptureOrder::Unordered,
            path_centre_sigma: 0.25,
            path_rotation_sigma_deg: 0.5,
            // 12 px: on 30 generated scenes centre errors 2.24 → 2.16 % and relative rotations
            // 3.33 → 2.96° (16 px: 2.34 % and 2.92°, heavy blur worse); blurball 1.05 → 0.90 %
            // (crates/gems-init/BENCHMARKS.md, "Coarse to fine").
            refine_max_blur_px: 12.0,
            refine_patch_blur_ratio: 0.75,
            initial_pairs: 3,
            trim_fraction: 0.4,
            trim_max_blur: 0.1,
            refine_affine_max_blur_px: 10.0,
            seed: 0,
        }
    }
}

/// Errors of the SfM stage.
#[derive(Debug, thiserror::Error)]
pub enum SfmError {
    #[error("structure from motion needs at least 2 images, got {0}")]
    TooFewImages(usize),
    #[error("image {name} is {width}x{height}; structure from motion needs at least 32x32 pixels")]
    ImageTooSmall {
        name: String,
        width: u32,
        height: u32,
    },
    #[error("images must share one size: {first} is {w0}x{h0} but {name} is {w}x{h}")]
    SizeMismatch {
        first: String,
        w0: u32,
        h0: u32,
        name: String,
        w: u32,
        h: u32,
    },
    #[error(
        "images {0:?} have no texture (no keypoints at any pyramid level); fewer than two images are usable"
    )]
    Textureless(Vec<String>),
    #[error("images {0} and {1} are identical; there is no parallax to reconstruct from")]
    IdenticalImages(String, String),
    #[error("invalid option: {0}")]
    InvalidOption(String),
    #[error(
        "only {registered} of {total} views registered (need at least 2); unregistered: {unregistered:?}. \
         The images may share too little overlap or parallax."
    )]
    TooFewRegistered {
        registered: usize,
        total: usize,
        unregistered: Vec<String>,
    },
    #[error("failed to read {path}: {source}")]
    Read {
        path: PathBuf,
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    #[error("failed to write {path}: {source}")]
    Write {
        path: PathBuf,
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    #[error("COLMAP subprocess: {0}")]
    Colmap(String),
    #[error("reading the COLMAP model: {0}")]
    Data(#[from] gems_data::DataError),
}

impl SfmError {
    /// A failed atomic write (gems-fs), naming the file.
    pub(crate) fn write(e: gems_fs::FsError) -> Self {
        SfmError::Write {
            path: e.path,
            source: Box::new(e.source),
        }
    }
}

/// Shared SIMPLE_PINHOLE camera in full-resolution pixels.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct SfmCamera {
    pub width: u32,
    pub height: u32,
    pub focal: f64,
    pub cx: f64,
    pub cy: f64,
}

/// One input view: its pose when registered and its 2D observations (full-resolution pixels,
/// index into [`SfmResult::points`]).
#[derive(Clone, Debug)]
pub struct SfmView {
    pub name: String,
    /// cam_from_world, or None when the view could not be registered.
    pub pose: Option<gems_math::Se3>,
    pub observations: Vec<([f64; 2], usize)>,
}

/// A triangulated point with its colour, mean reprojection error (full-resolution px) and track
/// as (view index, index into that view's observations).
#[derive(Clone, Debug)]
pub struct SfmPoint {
    pub xyz: [f64; 3],
    pub rgb: [u8; 3],
    pub error: f64,
    pub track: Vec<(usize, usize)>,
}

/// Diagnostics, serialised as `sfm_report.json`.
#[derive(Clone, Debug, Serialize)]
pub struct SfmStats {
    pub registered: usize,
    pub total: usize,
    pub points: usize,
    /// Mean reprojection error over all observations, full-resolution pixels.
    pub mean_reprojection_error: f64,
    pub mean_track_length: f64,
    pub seconds: f64,
    pub unregistered: Vec<String>,
    /// Long side of the pyramid level the reconstruction was made at.
    pub working_size: u32,
    /// Long side of the level it was last bundle-adjusted at: the working size, or finer after
    /// [`SfmOptions::refine_max_blur_px`].
    pub final_size: u32,
    pub focal: f64,
    pub focal_from_metadata: bool,
    /// Whether the focal was estimated (not given, not from EXIF) from photos blurred by more
    /// than [`FOCAL_ADVICE_BLUR`] of their long side, which barely determine it: the report's
    /// advice then asks for `--focal`, and a model so made is not measured accurate by a check
    /// on sharp renders made with its own focal (gems-pipeline, `init.confirmed_hold_blurred_focal`).
    pub focal_barely_determined: bool,
    /// Seconds spent in feature extraction + matching, and in reconstruction.
    pub seconds_features: f64,
    pub seconds_reconstruction: f64,
    /// Median motion-blur length estimated from the images (full-resolution px), which orders
    /// the working sizes tried.
    pub blur_px_estimate: f64,
    /// Whether the images were taken as in capture order, so that the bundle adjustment held
    /// the camera path smooth ([`SfmOptions::capture_order`], [`ba::PathPrior`]).
    pub capture_order: bool,
    /// One entry per input photo, in input order: what the user can act on.
    pub views: Vec<ViewReport>,
    /// Plain sentences on what the user can act on: the photos that were dropped and what to
    /// try, and an estimated focal that blur left barely determined ([`FOCAL_ADVICE_BLUR`];
    /// empty when neither applies).
    pub advice: Vec<String>,
}

/// One photo in the SfM's report.
#[derive(Clone, Debug, Serialize)]
pub struct ViewReport {
    pub name: String,
    pub registered: bool,
    /// This photo's estimated motion-blur length, full-resolution px.
    pub blur_px: f64,
    /// Reconstructed points it observes.
    pub points: usize,
    /// Mean reprojection error of those observations, full-resolution px (`None`: none).
    pub reprojection_error_px: Option<f64>,
    /// Why it was not registered, in words (`None` when it was).
    pub why_not: Option<String>,
}

/// Why each unregistered view of `stats` was dropped, and the advice sentences: a textureless
/// photo; one much more blurred than the others (over twice the median blur); else too little
/// overlap with the registered photos.
fn explain_unregistered(stats: &mut SfmStats, textureless: &[String]) {
    let median = stats.blur_px_estimate;
    let mut dropped = Vec::new();
    for v in stats.views.iter_mut().filter(|v| !v.registered) {
        let why = if textureless.contains(&v.name) {
            "too little texture: fewer than 8 keypoints at every working size".to_owned()
        } else if median > 0.0 && v.blur_px > 2.0 * median {
            format!(
                "much more blurred than the others ({:.0} px against a median of {:.0} px)",
                v.blur_px, median
            )
        } else {
            "too little overlap with the registered photos: too few of its points could be \
             matched and placed"
                .to_owned()
        };
        dropped.push(format!("{} ({why})", v.name));
        v.why_not = Some(why);
    }
    if !dropped.is_empty() {
        stats.advice.push(format!(
            "{} of {} photos were not registered and will not be trained on: {}.",
            dropped.len(),
            stats.total,
            dropped.join("; ")
        ));
        stats.advice.push(
            "To keep them: take photos closer together so that each overlaps its neighbours by \
             more than half, pass --focal if the camera's focal length in pixels is known, or \
             try a smaller working size (--working-size 128,96,64) for heavy blur."
                .into(),
        );
    }
}

/// Estimated blur, as a fraction of the photos' long side, above which an estimated focal is
/// reported as barely determined. On generated scenes the estimated focal came out 2.0 % off on
/// average at blur level 3 (about 2.5 % of the long side), 4.7 % at level 5 (5 %) and 20 % at
/// level 7 (7.5 %); at 7.5 % and 15 % on other scenes a median 13 % and 26 % (up to 126 %). The
/// tracks' optimum itself moves with the blur (crates/gems-init/BENCHMARKS.md, "The estimated
/// focal refined after coarse to fine" and "Under heavy blur the observations' optimum is not
/// the truth").
pub const FOCAL_ADVICE_BLUR: f64 = 0.05;

/// Whether the focal of `stats` was estimated (not given, not from EXIF) from photos blurred by
/// more than [`FOCAL_ADVICE_BLUR`] of their `long` side ([`SfmStats::focal_barely_determined`]).
fn focal_barely_determined(stats: &SfmStats, long: f64) -> bool {
    !stats.focal_from_metadata && stats.blur_px_estimate / long > FOCAL_ADVICE_BLUR
}

/// The advice sentence for a focal the SfM estimated from photos blurred by more than
/// [`FOCAL_ADVICE_BLUR`] of their `long` side ([`focal_barely_determined`]).
fn focal_advice(stats: &SfmStats, long: f64) -> Option<String> {
    let fraction = stats.blur_px_estimate / long;
    focal_barely_determined(stats, long).then(|| {
        format!(
            "The focal length ({:.0} px) was estimated from photos blurred by about {:.0} px \
             ({:.0} % of their long side), which barely determine it: at such blur the estimate \
             is often 10-30 % off and sometimes more. Pass --focal if the camera's focal length \
             in pixels is known.",
            stats.focal,
            stats.blur_px_estimate,
            100.0 * fraction
        )
    })
}

/// The reconstruction: camera, views (in input order), points, diagnostics.
#[derive(Clone, Debug)]
pub struct SfmResult {
    pub camera: SfmCamera,
    pub views: Vec<SfmView>,
    pub points: Vec<SfmPoint>,
    pub stats: SfmStats,
}

/// Two-view correspondences (working-level pixels) of views i < j, geometrically verified.
pub(crate) struct PairCorr {
    pub i: usize,
    pub j: usize,
    pub x1: Vec<nalgebra::Vector2<f64>>,
    pub x2: Vec<nalgebra::Vector2<f64>>,
}

/// Verified descriptor matches (feature indices) of one image pair at the working level.
pub(crate) struct PairMatches {
    pub i: usize,
    pub j: usize,
    pub matches: Vec<(u32, u32)>,
}

/// The images of a scene folder: `<dir>/images/*` when that folder exists, else `<dir>/*`
/// (png/jpg/jpeg, not hidden), sorted by file name: the listing gems-data opens scenes with
/// (`gems_fs::list_images`), so the SfM model names the images the trainer reads.
pub fn load_images(dir: &std::path::Path) -> Result<Vec<SfmImage>, SfmError> {
    let img_dir = gems_fs::image_folder(dir);
    let files = gems_fs::list_images(&img_dir).map_err(|e| SfmError::Read {
        path: e.path,
        source: Box::new(e.source),
    })?;
    if files.is_empty() {
        return Err(SfmError::TooFewImages(0));
    }
    files
        .par_iter()
        .map(|p| {
            let image = image::open(p)
                .map_err(|e| SfmError::Read {
                    path: p.clone(),
                    source: Box::new(e),
                })?
                .to_rgb8();
            let name = p
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            Ok(SfmImage { name, image })
        })
        .collect()
}

/// Each photo's estimated motion-blur length in its own pixels (0 where no blur is found): the
/// measure [`run_sfm`] orders its working sizes by and reports per photo
/// ([`ViewReport::blur_px`]).
pub fn estimate_blur_px(images: &[SfmImage]) -> Vec<f64> {
    images
        .par_iter()
        .map(|im| f64::from(features::estimate_blur_px(&Gray::from_rgb(&im.image))))
        .collect()
}

/// Validate the input and reconstruct. See the module docs for the pipeline.
pub fn run_sfm(images: &[SfmImage], opts: &SfmOptions) -> Result<SfmResult, SfmError> {
    let t0 = Instant::now();
    validate(images, opts)?;
    let (w, h) = images[0].image.dimensions();
    let long = w.max(h) as f64;
    let grays: Vec<Gray> = images
        .par_iter()
        .map(|im| Gray::from_rgb(&im.image))
        .collect();
    check_identical(images, &grays)?;
    let (blurs, blur, sizes) = working_sizes_by_blur(&grays, long, opts);
    tracing::info!(blur_px = blur, working_sizes = ?sizes, "estimated motion blur");

    // With the focal unknown each focal candidate is one more model already, and more initial
    // pairs per candidate did not help on average (`SfmOptions::initial_pairs`).
    let pair_tries = if opts.focal_px.is_some() {
        opts.initial_pairs
    } else {
        1
    };
    let mut best: Option<Attempt> = None;
    let mut attempts: Vec<Attempt> = Vec::new();
    let mut t_feat = 0.0;
    let mut t_rec = 0.0;
    let mut textureless: Option<Vec<String>> = None;
    for &ws in &sizes {
        let tf = Instant::now();
        let scale = features::exact_scale(w, ws as f64 / long);
        let work: Vec<Gray> = grays.par_iter().map(|g| g.resized(scale as f32)).collect();
        let (feats, pairs) = features_and_matches(&work, opts);
        let ov = tracking::overlaps(&work, work[0].w);
        let path = path_prior(&ov, opts);
        let (tracks, corrs) = all_tracks(&work, &feats, &pairs, &ov, opts);
        t_feat += tf.elapsed().as_secs_f64();
        if textureless.is_none() {
            textureless = Some(textureless_views(images, &grays, &feats, long, opts)?);
        }
        let tr = Instant::now();
        let mut focals: Vec<f64> = match opts.focal_px {
            Some(f) => vec![f * scale],
            None => opts
                .focal_candidates
                .iter()
                .map(|c| c * long * scale)
                .collect(),
        };
        let (sw, sh) = (w as f64 * scale, h as f64 * scale);
        let mut next = 0;
        while next < focals.len() {
            let f = focals[next];
            next += 1;
            // One focal for both axes: the bundle adjustment refines fx = fy together.
            let k = gems_math::Intrinsics {
                fx: f,
                fy: f,
                cx: 0.5 * sw,
                cy: 0.5 * sh,
                width: work[0].w as u32,
                height: work[0].h as u32,
            };
            let rec = incremental::reconstruct(
                tracks.clone(),
                &corrs,
                images.len(),
                k,
                path.as_ref(),
                pair_tries,
                opts,
            );
            let Some(rec) = rec else { continue };
            let attempt = Attempt {
                error_px: rec.mean_error() / scale,
                focal_start_px: f / scale,
                recon: rec,
                working_size: ws,
                scale,
            };
            tracing::debug!(
                working_size = ws,
                focal_start = attempt.focal_start_px,
                focal = attempt.recon.k.fx / scale,
                registered = attempt.recon.registered(),
                error_px = attempt.error_px,
                "sfm attempt"
            );
            attempts.push(attempt);
            if next == focals.len()
                && opts.focal_px.is_none()
                && let Some(f) = focal_beyond_the_candidates(&attempts, ws, long, opts)
            {
                focals.push(f * long * scale);
            }
        }
        best = choose_attempt(&attempts, long).cloned();
        t_rec += tr.elapsed().as_secs_f64();
        if best
            .as_ref()
            .is_some_and(|b| b.recon.registered() == images.len())
        {
            break;
        }
    }
    let Some(Attempt {
        recon: mut rec,
        working_size: ws,
        mut scale,
        ..
    }) = best
    else {
        return Err(SfmError::TooFewRegistered {
            registered: 0,
            total: images.len(),
            unregistered: images.iter().map(|i| i.name.clone()).collect(),
        });
    };
    // A given focal is held through the reconstruction; under a prior it is refined at the
    // end, on the finest observations (below).
    // Every focal candidate tried at the kept level (the list and its extensions), as multiples
    // of the long side.
    let candidates: Vec<f64> = attempts
        .iter()
        .filter(|a| a.working_size == ws)
        .map(|a| a.focal_start_px / long)
        .collect();
    // The focal candidates that explain the tracks as well as the kept one, at its level.
    let tied: Vec<f64> = tied_attempts(&attempts)
        .into_iter()
        .filter(|a| a.working_size == ws)
        .map(|a| a.focal_start_px * scale)
        .collect();
    if opts.focal_px.is_none()
        && let Some(r) = refine_focal_around(&rec, long * scale, &candidates, &tied, opts)
    {
        tracing::info!(focal = r.k.fx / scale, "focal refined");
        rec = r;
    }
    // The finest scale whose blur stays within `refine_max_blur_px`; `blur` is in full-size px.
    let finest = if opts.refine_max_blur_px <= 0.0 {
        0.0
    } else if blur > 0.0 {
        opts.refine_max_blur_px / blur
    } else {
        1.0
    };
    loop {
        let to = features::exact_scale(w, finest.min(2.0 * scale));
        if to <= scale * 1.05 {
            break;
        }
        match refine::remeasure(&rec, &grays, scale, to, blur, opts) {
            Some(r) => {
                tracing::info!(size = (long * to).round(), "model refined at a finer level");
                rec = r;
                scale = to;
            }
            None => {
                tracing::info!(
                    size = (long * to).round(),
                    "a finer level left a view with too few observations; kept the coarser"
                );
                break;
            }
        }
    }
    if opts.refine_max_blur_px > 0.0 {
        // Once more at the final level, with the patch warps of the final model.
        match refine::remeasure(&rec, &grays, scale, scale, blur, opts) {
            Some(r) => rec = r,
            None => tracing::info!("re-measuring left a view with too few observations; kept"),
        }
    }
    if opts.focal_px.is_none() {
        // Once more on the finest level's observations, anywhere within the candidates' span:
        // the working level's bracket held it where the coarse tracks, nearly flat in the focal
        // under blur, had put it (crates/gems-init/BENCHMARKS.md, "The estimated focal refined
        // after coarse to fine").
        let lo = candidates.iter().copied().fold(f64::INFINITY, f64::min) * long * scale;
        let hi = candidates.iter().copied().fold(0.0, f64::max) * long * scale;
        if let Some(r) = incremental::refine_focal_bounded(&rec, lo, hi, opts) {
            tracing::info!(focal = r.k.fx / scale, "focal refined at the final level");
            rec = r;
        }
    }
    if let (Some(f), Some(rel)) = (opts.focal_px, opts.focal_prior) {
        // After coarse to fine: the finest level's observations tell the focal best
        // (crates/gems-init/BENCHMARKS.md, "The focal prior after coarse to fine").
        let prior = ba::Focal::Prior {
            focal: f * scale,
            sigma: rel * f * scale,
        };
        if let Some(r) = incremental::refine_focal(&rec, prior, opts) {
            tracing::info!(
                given = f,
                focal = r.k.fx / scale,
                "focal refined under its prior"
            );
            rec = r;
        }
    }
    // Last, so that no adjustment on every point follows it.
    if let Some(gauge) = rec.poses.iter().position(Option::is_some)
        && trims(blur, long, opts)
    {
        incremental::trimmed_ba(&mut rec, gauge, opts.trim_fraction, opts);
    }
    let mut result = output::assemble(images, &rec, scale, opts.focal_px.is_some(), ws);
    result.stats.final_size = (long * scale).round() as u32;
    result.stats.seconds = t0.elapsed().as_secs_f64();
    result.stats.seconds_features = t_feat;
    result.stats.seconds_reconstruction = t_rec;
    result.stats.blur_px_estimate = blur;
    result.stats.capture_order = rec.path.is_some();
    for (v, b) in result.stats.views.iter_mut().zip(&blurs) {
        v.blur_px = f64::from(*b);
    }
    explain_unregistered(&mut result.stats, textureless.as_deref().unwrap_or(&[]));
    result.stats.focal_barely_determined = focal_barely_determined(&result.stats, long);
    if let Some(line) = focal_advice(&result.stats, long) {
        result.stats.advice.push(line);
    }
    for line in &result.stats.advice {
        tracing::warn!("{line}");
    }
    if result.stats.registered < 2 {
        return Err(SfmError::TooFewRegistered {
            registered: result.stats.registered,
            total: result.stats.total,
            unregistered: result.stats.unregistered,
        });
    }
    Ok(result)
}

/// Whether the last bundle adjustment leaves the worst-fitting points out: photos whose
/// estimated `blur` (px) is at most [`SfmOptions::trim_max_blur`] of their `long` side.
fn trims(blur: f64, long: f64, opts: &SfmOptions) -> bool {
    opts.trim_fraction > 0.0 && blur <= opts.trim_max_blur * long
}

/// The median motion-blur length (px at full size) and the working sizes in the order to try:
/// the size where the blur is about [`TARGET_BLUR_PX`] first, then the others by distance (in
/// scale) from it. Too fine a level leaves long smears that bias matching and let the camera
/// path bend, too coarse a level leaves too few pixels.
fn working_sizes_by_blur(
    grays: &[Gray],
    long: f64,
    opts: &SfmOptions,
) -> (Vec<f32>, f64, Vec<u32>) {
    let blurs: Vec<f32> = grays.par_iter().map(features::estimate_blur_px).collect();
    let blur = opts.blur_px.unwrap_or_else(|| {
        let mut sorted = blurs.clone();
        sorted.sort_by(|a, b| a.total_cmp(b));
        f64::from(sorted[sorted.len() / 2])
    });
    let target_ws = if blur > 0.0 {
        long * TARGET_BLUR_PX / blur
    } else {
        f64::INFINITY
    };
    let mut sizes = levels(&opts.working_sizes, long);
    sizes.sort_by(|&a, &b| {
        let d = |s: u32| (s as f64 / target_ws).ln().abs();
        d(a).total_cmp(&d(b)).then(b.cmp(&a))
    });
    (blurs, blur, sizes)
}

/// `sizes` with every size above the images' long side `long` replaced by `long` itself (the
/// images are never upsampled), each once, in their order.
fn levels(sizes: &[u32], long: f64) -> Vec<u32> {
    let mut out: Vec<u32> = Vec::new();
    for &s in sizes {
        let s = s.min(long.round() as u32);
        if !out.contains(&s) {
            out.push(s);
        }
    }
    out
}

/// Fewer keypoints than this at every working size make a view textureless.
const TEXTURELESS_KEYPOINTS: usize = 8;

/// The names of the textureless views (too few keypoints at every level, see
/// [`TEXTURELESS_KEYPOINTS`]): they stay unregistered, and the run fails when fewer than two
/// views have texture.
fn textureless_views(
    images: &[SfmImage],
    grays: &[Gray],
    feats: &[Features],
    long: f64,
    opts: &SfmOptions,
) -> Result<Vec<String>, SfmError> {
    let (w, _) = images[0].image.dimensions();
    let names: Vec<String> = feats
        .iter()
        .enumerate()
        .filter(|(k, f)| {
            f.xy.len() < TEXTURELESS_KEYPOINTS
                && levels(&opts.working_sizes, long).iter().all(|&s| {
                    let sc = features::exact_scale(w, s as f64 / long) as f32;
                    extract_one(&grays[*k], sc, opts).xy.len() < TEXTURELESS_KEYPOINTS
                })
        })
        .map(|(k, _)| images[k].name.clone())
        .collect();
    if images.len() - names.len() < 2 {
        return Err(SfmError::Textureless(names));
    }
    if !names.is_empty() {
        tracing::warn!(?names, "textureless views cannot be registered");
    }
    Ok(names)
}

/// Refines the focal of `rec` in a bundle adjustment, keeping the result only within a bracket:
/// when several focal candidates explain the tracks equally well (`tied`, their starting focals
/// at the working scale), the span of those candidates, since the data did not choose among
/// them and the tie-break toward [`FOCAL_PRIOR`] is only a guess (on generated arcs at blur level
/// 5 it picked 1.1× the long side for a focal of 0.87×, which the refinement then moved most of
/// the way back; crates/gems-init/BENCHMARKS.md, "The focal refined across tied candidates");
/// otherwise halfway (geometrically) to the neighbouring candidates of its own (`candidates`,
/// as multiples of `long_px`, the long image side at the working scale). `None` when the
/// refinement does not improve it.
fn refine_focal_around(
    rec: &incremental::Recon,
    long_px: f64,
    candidates: &[f64],
    tied: &[f64],
    opts: &SfmOptions,
) -> Option<incremental::Recon> {
    if tied.len() > 1 {
        let (lo, hi) = tied
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(l, h), &f| (l.min(f), h.max(f)));
        return incremental::refine_focal_bounded(rec, lo, hi, opts);
    }
    let f0 = rec.k.fx;
    let mut c: Vec<f64> = candidates.iter().map(|c| c * long_px).collect();
    c.sort_by(|a, b| a.total_cmp(b));
    let lo = c
        .iter()
        .rev()
        .find(|&&x| x < f0 * 0.999)
        .map_or(f0 * 0.8, |x| (x * f0).sqrt());
    let hi = c
        .iter()
        .find(|&&x| x > f0 * 1.001)
        .map_or(f0 * 1.25, |x| (x * f0).sqrt());
    incremental::refine_focal_bounded(rec, lo, hi, opts)
}

/// The next focal candidate, as a multiple of the long side `long`, when the attempt chosen
/// among those at working size `ws` started from the smallest or the largest focal tried
/// there: one step beyond it in the ratio of the two candidates at that end, if that stays
/// within [`SfmOptions::focal_search_span`]. A focal outside the list is then found by the
/// same evidence as one inside it (the views registered and the reprojection error, ties
/// broken toward [`FOCAL_PRIOR`]), and the search stops at the first added candidate that is
/// not chosen.
fn focal_beyond_the_candidates(
    attempts: &[Attempt],
    ws: u32,
    long: f64,
    opts: &SfmOptions,
) -> Option<f64> {
    let here = attempts.iter().filter(|a| a.working_size == ws);
    let mut tried: Vec<f64> = here.clone().map(|a| a.focal_start_px / long).collect();
    tried.sort_by(f64::total_cmp);
    if tried.len() < 2 {
        return None;
    }
    let chosen = choose_attempt(here, long)?.focal_start_px / long;
    let (lo, hi) = opts.focal_search_span;
    let n = tried.len();
    // One step beyond `end` in its ratio to `inner`. Two candidates (nearly) equal at an end
    // give no step: without this a repeated candidate would be tried again and again.
    let beyond = |end: f64, inner: f64| {
        let ratio = end / inner;
        (ratio.ln().abs() > 1.01f64.ln()).then_some(end * ratio)
    };
    let next = if chosen >= tried[n - 1] * (1.0 - 1e-9) {
        beyond(tried[n - 1], tried[n - 2])
    } else if chosen <= tried[0] * (1.0 + 1e-9) {
        beyond(tried[0], tried[1])
    } else {
        None
    };
    next.filter(|&f| f >= lo * (1.0 - 1e-9) && f <= hi * (1.0 + 1e-9))
}

/// One reconstruction attempt: a working size and a starting focal.
#[derive(Clone)]
struct Attempt {
    recon: incremental::Recon,
    /// Long image side the features were found at.
    working_size: u32,
    /// Working size over full size.
    scale: f64,
    /// Mean reprojection error in full-resolution px.
    error_px: f64,
    /// The focal the attempt started from, in full-resolution px.
    focal_start_px: f64,
}

/// Relative spread of mean reprojection errors within which focal candidates count as equally
/// good. Under heavy blur the error barely depends on the focal (±1 % over a ×3 range), so the
/// smallest error is noise, not evidence.
const FOCAL_ERROR_TIE: f64 = 0.01;

/// Focal prior, as a multiple of the long image side (a 53° field of view across it), that
/// breaks ties between equally good focal candidates.
const FOCAL_PRIOR: f64 = 1.0;

/// The attempts that are equally good: most registered views, and among those errors within
/// [`FOCAL_ERROR_TIE`] of the smallest.
fn tied_attempts<'a>(attempts: impl IntoIterator<Item = &'a Attempt> + Clone) -> Vec<&'a Attempt> {
    let Some(nreg) = attempts
        .clone()
        .into_iter()
        .map(|a| a.recon.registered())
        .max()
    else {
        return Vec::new();
    };
    let min_err = attempts
        .clone()
        .into_iter()
        .filter(|a| a.recon.registered() == nreg)
        .map(|a| a.error_px)
        .fold(f64::INFINITY, f64::min);
    attempts
        .into_iter()
        .filter(|a| a.recon.registered() == nreg && a.error_px <= min_err * (1.0 + FOCAL_ERROR_TIE))
        .collect()
}

/// The best attempt so far: of the [`tied_attempts`], the one whose starting focal is nearest
/// [`FOCAL_PRIOR`].
fn choose_attempt<'a>(
    attempts: impl IntoIterator<Item = &'a Attempt> + Clone,
    long: f64,
) -> Option<&'a Attempt> {
    let prior = FOCAL_PRIOR * long;
    let dist = |f: f64| (f / prior).ln().abs();
    tied_attempts(attempts).into_iter().min_by(|a, b| {
        dist(a.focal_start_px)
            .total_cmp(&dist(b.focal_start_px))
            .then(a.error_px.total_cmp(&b.error_px))
    })
}

fn validate(images: &[SfmImage], opts: &SfmOptions) -> Result<(), SfmError> {
    if images.len() < 2 {
        return Err(SfmError::TooFewImages(images.len()));
    }
    if opts.working_sizes.is_empty() || opts.working_sizes.iter().any(|&s| s < 32) {
        return Err(SfmError::InvalidOption(
            "working sizes must be ≥ 32 px and non-empty".into(),
        ));
    }
    if opts.focal_px.is_none()
        && (opts.focal_candidates.is_empty()
            || opts
                .focal_candidates
                .iter()
                .any(|c| c.is_nan() || *c <= 0.0))
    {
        return Err(SfmError::InvalidOption(
            "focal candidates must be positive and non-empty".into(),
        ));
    }
    if opts.blur_px.is_some_and(|b| !(b.is_finite() && b >= 0.0)) {
        return Err(SfmError::InvalidOption(
            "the known blur must be finite and >= 0 px".into(),
        ));
    }
    let (lo, hi) = opts.focal_search_span;
    if !(lo > 0.0 && lo <= hi && hi.is_finite()) {
        return Err(SfmError::InvalidOption(
            "the focal search span must be positive and ordered".into(),
        ));
    }
    if opts
        .focal_prior
        .is_some_and(|s| !(s > 0.0 && s.is_finite()))
    {
        return Err(SfmError::InvalidOption(
            "focal_prior must be a positive fraction of the focal".into(),
        ));
    }
    if opts.focal_px.is_some_and(|f| !(f > 0.0 && f.is_finite())) {
        return Err(SfmError::InvalidOption("focal_px must be positive".into()));
    }
    if opts.max_features < 16 || opts.max_reproj_px.is_nan() || opts.max_reproj_px <= 0.0 {
        return Err(SfmError::InvalidOption(
            "max_features ≥ 16 and max_reproj_px > 0 required".into(),
        ));
    }
    if opts.trim_max_blur.is_nan() || opts.trim_max_blur < 0.0 {
        return Err(SfmError::InvalidOption(format!(
            "trim_max_blur must be ≥ 0, got {}",
            opts.trim_max_blur
        )));
    }
    if opts.refine_affine_max_blur_px.is_nan() || opts.refine_affine_max_blur_px < 0.0 {
        return Err(SfmError::InvalidOption(format!(
            "refine_affine_max_blur_px must be ≥ 0, got {}",
            opts.refine_affine_max_blur_px
        )));
    }
    if !(0.0..1.0).contains(&opts.trim_fraction) {
        return Err(SfmError::InvalidOption(format!(
            "trim_fraction must be in [0, 1), got {}",
            opts.trim_fraction
        )));
    }
    if opts.initial_pairs == 0 {
        return Err(SfmError::InvalidOption(
            "initial_pairs must be ≥ 1 (1 grows one model)".into(),
        ));
    }
    if !(0.0..=0.5).contains(&opts.grid_spacing_frac) || opts.max_query_points == 0 {
        return Err(SfmError::InvalidOption(
            "grid_spacing_frac in [0, 0.5] and max_query_points ≥ 1 required".into(),
        ));
    }
    let (w0, h0) = images[0].image.dimensions();
    for im in images {
        let (w, h) = im.image.dimensions();
        if w < 32 || h < 32 {
            return Err(SfmError::ImageTooSmall {
                name: im.name.clone(),
                width: w,
                height: h,
            });
        }
        if (w, h) != (w0, h0) {
            return Err(SfmError::SizeMismatch {
                first: images[0].name.clone(),
                w0,
                h0,
                name: im.name.clone(),
                w,
                h,
            });
        }
    }
    Ok(())
}

/// Identical (or near-identical) images carry no parallax. When *every* image equals the first,
/// the reconstruction is impossible; report the pair.
fn check_identical(images: &[SfmImage], grays: &[Gray]) -> Result<(), SfmError> {
    let first = &grays[0].data;
    let all_same = grays[1..].iter().all(|g| {
        let mad = g
            .data
            .iter()
            .zip(first)
            .map(|(a, b)| (a - b).abs())
            .sum::<f32>()
            / first.len() as f32;
        mad < 1e-4
    });
    if all_same {
        return Err(SfmError::IdenticalImages(
            images[0].name.clone(),
            images[1].name.clone(),
        ));
    }
    Ok(())
}

fn feature_params(opts: &SfmOptions) -> FeatureParams {
    FeatureParams {
        max_features: opts.max_features,
        smooth_sigma: 1.0,
        desc_step: 1.5,
        nms_radius: 3,
    }
}

fn extract_one(g: &Gray, scale: f32, opts: &SfmOptions) -> Features {
    features::extract(&g.resized(scale), &feature_params(opts))
}

/// The smoothness prior on the camera path when the images are in capture order (given, or
/// detected from the views' overlaps `ov`), `None` otherwise or when both of its σ are 0.
fn path_prior(ov: &[Vec<tracking::Overlap>], opts: &SfmOptions) -> Option<ba::PathPrior> {
    let n = ov.len();
    let ordered = match opts.capture_order {
        CaptureOrder::Ordered => true,
        CaptureOrder::Unordered => false,
        CaptureOrder::Detect => {
            let (neighbours, consecutive) = consecutive_best_partners(ov);
            let ordered = detect_capture_order(neighbours, consecutive);
            tracing::info!(
                ordered,
                "capture order: {neighbours} of {consecutive} consecutive images are each other's most similar"
            );
            ordered
        }
    };
    let prior = ba::PathPrior {
        order: (0..n).collect(),
        centre_sigma: opts.path_centre_sigma,
        rotation_sigma: opts.path_rotation_sigma_deg.to_radians(),
    };
    (ordered && n >= 3 && (prior.centre_sigma > 0.0 || prior.rotation_sigma > 0.0)).then_some(prior)
}

/// How many consecutive images (i, i + 1) are among each other's most similar: i + 1 one of
/// the two images whose thumbnails overlap i's best ([`tracking::overlaps`], which blur barely
/// changes, unlike descriptor matches at a coarse working level), or i one of i + 1's two; and
/// how many consecutive pairs there are.
fn consecutive_best_partners(ov: &[Vec<tracking::Overlap>]) -> (usize, usize) {
    let n = ov.len();
    let best: Vec<Vec<usize>> = (0..n)
        .map(|i| {
            let mut v: Vec<usize> = (0..n).filter(|&j| j != i).collect();
            // Best first; ties by index, so the result does not depend on anything else.
            v.sort_by(|&a, &b| ov[i][b].score.total_cmp(&ov[i][a].score).then(a.cmp(&b)));
            v.truncate(2);
            v
        })
        .collect();
    let neighbours = (0..n.saturating_sub(1))
        .filter(|&i| best[i].contains(&(i + 1)) || best[i + 1].contains(&i))
        .count();
    (neighbours, n.saturating_sub(1))
}

/// Images are taken as ordered when at least 80 % of consecutive pairs are best partners
/// ([`consecutive_best_partners`]). In a shuffled set an image's next is one of its two best
/// partners by chance with probability about 4/(n − 1), so the rule holds by chance only for
/// the smallest sets; and there the prior is weak next to the photos.
fn detect_capture_order(neighbours: usize, consecutive: usize) -> bool {
    consecutive >= 2 && neighbours * 5 >= consecutive * 4
}

/// Features of every view (working level) and fundamental-matrix-verified descriptor matches of
/// every pair.
fn features_and_matches(work: &[Gray], opts: &SfmOptions) -> (Vec<Features>, Vec<PairMatches>) {
    let fp = feature_params(opts);
    let feats: Vec<Features> = work.par_iter().map(|g| features::extract(g, &fp)).collect();
    let n = work.len();
    let pairs: Vec<(usize, usize)> = (0..n)
        .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
        .collect();
    let verified: Vec<PairMatches> = pairs
        .par_iter()
        .filter_map(|&(i, j)| {
            let m = features::match_pair(&feats[i], &feats[j], 0.9, 0.6);
            if m.len() < opts.min_pair_inliers {
                return None;
            }
            let x1: Vec<_> = m
                .iter()
                .map(|&(a, _)| to_v(feats[i].xy[a as usize]))
                .collect();
            let x2: Vec<_> = m
                .iter()
                .map(|&(_, b)| to_v(feats[j].xy[b as usize]))
                .collect();
            let seed = opts.seed ^ ((i as u64) << 32 | j as u64);
            let (_, mask) =
                geometry::ransac_epipolar(&x1, &x2, false, opts.max_reproj_px, 1000, seed)?;
            let matches: Vec<(u32, u32)> = m
                .iter()
                .zip(&mask)
                .filter(|(_, k)| **k)
                .map(|(m, _)| *m)
                .collect();
            (matches.len() >= opts.min_pair_inliers).then_some(PairMatches { i, j, matches })
        })
        .collect();
    tracing::debug!(pairs = verified.len(), "verified descriptor pairs");
    (feats, verified)
}

fn to_v(p: [f32; 2]) -> nalgebra::Vector2<f64> {
    nalgebra::Vector2::new(p[0] as f64, p[1] as f64)
}

/// Tracks from both matchers: descriptor matches chained by union–find, and for each root view
/// its keypoints tracked into its best-overlapping neighbours (each pair verified by a
/// fundamental-matrix RANSAC). Also returns every verified pair's correspondences.
fn all_tracks(
    work: &[Gray],
    feats: &[Features],
    pairs: &[PairMatches],
    ov: &[Vec<tracking::Overlap>],
    opts: &SfmOptions,
) -> (Vec<incremental::Track>, Vec<PairCorr>) {
    let n = work.len();
    let mut tracks = incremental::build_tracks(feats, pairs);
    let mut corr = Correspondences::default();
    for pm in pairs {
        for &(a, b) in &pm.matches {
            corr.add(
                pm.i,
                pm.j,
                to_v(feats[pm.i].xy[a as usize]),
                to_v(feats[pm.j].xy[b as usize]),
            );
        }
    }
    let wl = work[0].w.max(work[0].h) as f32;
    let tp = tracking::TrackParams {
        // Large patches: at extreme blur only coarse structure is distinctive.
        half: ((wl * 0.09).round() as i32).clamp(4, 10),
        radius: ((wl * 0.07).round() as i32).clamp(5, 20),
        neighbours: opts.track_neighbours,
        min_ncc: 0.75,
        min_margin: 0.01,
        fb_tol: 1.0,
        affine: false,
    };
    let smooth: Vec<tracking::Prepared> = work
        .par_iter()
        .map(|g| tracking::Prepared::new(g.gaussian(TRACKING_SMOOTH_SIGMA)))
        .collect();
    for i in 0..n {
        let mut nb: Vec<usize> = (0..n)
            .filter(|&j| j != i && ov[i][j].score > MIN_OVERLAP_SCORE)
            .collect();
        nb.sort_by(|&a, &b| ov[i][b].score.total_cmp(&ov[i][a].score).then(a.cmp(&b)));
        nb.truncate(tp.neighbours);
        let pts = query_points(&feats[i], &smooth[i], wl, &tp, opts);
        let mut root: Vec<incremental::Track> = pts
            .iter()
            .map(|p| incremental::Track {
                obs: vec![incremental::TrackObs {
                    view: i,
                    xy: to_v(*p),
                    active: true,
                }],
                xyz: None,
            })
            .collect();
        for &j in &nb {
            let found = chained_track(&root, j, &smooth, ov, &tp);
            for (k, a, b) in epipolar_inliers(&pts, &found, i, j, opts) {
                root[k].obs.push(incremental::TrackObs {
                    view: j,
                    xy: b,
                    active: true,
                });
                corr.add(i, j, a, b);
            }
        }
        tracks.extend(root.into_iter().filter(|t| t.obs.len() >= 2));
    }
    (tracks, corr.0.into_values().collect())
}

/// Views overlapping less than this (the overlap score of [`tracking::overlaps`]) are not
/// tracked into.
const MIN_OVERLAP_SCORE: f32 = 0.2;

/// σ (working-level px) of the Gaussian smoothing applied before patch tracking.
const TRACKING_SMOOTH_SIGMA: f32 = 1.5;

/// RANSAC iterations of the epipolar check on each tracked pair.
const TRACKED_PAIR_RANSAC_ITERS: usize = 1000;

/// Point correspondences per image pair `(i < j)`, in pair order.
#[derive(Default)]
struct Correspondences(std::collections::BTreeMap<(usize, usize), PairCorr>);

impl Correspondences {
    /// Adds the match of `a` in view `i` with `b` in view `j` (either order).
    fn add(&mut self, i: usize, j: usize, a: nalgebra::Vector2<f64>, b: nalgebra::Vector2<f64>) {
        let (key, a, b) = if i < j {
            ((i, j), a, b)
        } else {
            ((j, i), b, a)
        };
        let e = self.0.entry(key).or_insert_with(|| PairCorr {
            i: key.0,
            j: key.1,
            x1: Vec::new(),
            x2: Vec::new(),
        });
        e.x1.push(a);
        e.x2.push(b);
    }
}

/// The points of one view to track into its neighbours: its keypoints (strongest first per grid
/// cell; beyond the budget they are dropped), topped up with grid points where blur has wiped
/// out corners. Where corners are plentiful grid points would only add less precisely localised
/// patches, so they are added only below a third of the budget.
fn query_points(
    feats: &Features,
    smooth: &tracking::Prepared,
    wl: f32,
    tp: &tracking::TrackParams,
    opts: &SfmOptions,
) -> Vec<[f32; 2]> {
    let mut pts = feats.xy.clone();
    pts.truncate(opts.max_query_points);
    if opts.grid_spacing_frac > 0.0 && pts.len() < opts.max_query_points / 3 {
        let spacing = ((wl * opts.grid_spacing_frac).round() as usize).max(2);
        let budget = opts.max_query_points.saturating_sub(pts.len());
        let grid = tracking::grid_points(&smooth.img, tp.half, spacing, 0.1, 0.2, &pts, budget);
        pts.extend(grid);
    }
    pts
}

/// Where each track of `root` lands in view `j` (`None`: lost). Chained prediction: each point
/// is searched for from the view of its track that overlaps j best (a near neighbour of j rather
/// than the root), so tracks reach views whose shift from the root is beyond the search radius
/// and stay long, which is what ties distant views together and keeps the camera path from
/// bending.
fn chained_track(
    root: &[incremental::Track],
    j: usize,
    smooth: &[tracking::Prepared],
    ov: &[Vec<tracking::Overlap>],
    tp: &tracking::TrackParams,
) -> Vec<Option<[f32; 2]>> {
    let mut found: Vec<Option<[f32; 2]>> = vec![None; root.len()];
    let mut by_src: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
    for (k, t) in root.iter().enumerate() {
        let src = t
            .obs
            .iter()
            .map(|o| o.view)
            .max_by(|&a, &b| ov[a][j].score.total_cmp(&ov[b][j].score).then(b.cmp(&a)))
            .expect("root observation");
        by_src.entry(src).or_default().push(k);
    }
    for (src, ks) in by_src {
        let from: Vec<[f32; 2]> = ks
            .iter()
            .map(|&k| {
                let o = root[k].obs.iter().find(|o| o.view == src).expect("source");
                [o.xy.x as f32, o.xy.y as f32]
            })
            .collect();
        let f = tracking::track_points(&smooth[src], &smooth[j], &from, ov[src][j].shift, tp);
        for (&k, q) in ks.iter().zip(f) {
            found[k] = q;
        }
    }
    found
}

/// The tracked points from view `i` to view `j` that pass an epipolar RANSAC check, as (query
/// index, point in i, point in j); empty when fewer than `min_pair_inliers` survive.
fn epipolar_inliers(
    pts: &[[f32; 2]],
    found: &[Option<[f32; 2]>],
    i: usize,
    j: usize,
    opts: &SfmOptions,
) -> Vec<(usize, nalgebra::Vector2<f64>, nalgebra::Vector2<f64>)> {
    let idx: Vec<usize> = (0..pts.len()).filter(|&k| found[k].is_some()).collect();
    if idx.len() < opts.min_pair_inliers {
        return Vec::new();
    }
    let x1: Vec<_> = idx.iter().map(|&k| to_v(pts[k])).collect();
    let x2: Vec<_> = idx
        .iter()
        .map(|&k| to_v(found[k].expect("tracked")))
        .collect();
    let seed = opts.seed ^ 0x5eed ^ ((i as u64) << 32 | j as u64);
    let Some((_, mask)) = geometry::ransac_epipolar(
        &x1,
        &x2,
        false,
        opts.max_reproj_px,
        TRACKED_PAIR_RANSAC_ITERS,
        seed,
    ) else {
        return Vec::new();
    };
    if mask.iter().filter(|&&m| m).count() < opts.min_pair_inliers {
        return Vec::new();
    }
    idx.iter()
        .zip(&mask)
        .zip(x1.iter().zip(&x2))
        .filter(|((_, m), _)| **m)
        .map(|((&k, _), (a, b))| (k, *a, *b))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An attempt at working size 128 (scale 0.5) from focal `f` (full-size px) that registered
    /// `registered` of 4 views with mean error `error_px`.
    fn attempt(f: f64, registered: usize, error_px: f64) -> Attempt {
        let k = gems_math::Intrinsics {
            fx: 0.5 * f,
            fy: 0.5 * f,
            cx: 64.0,
            cy: 40.0,
            width: 128,
            height: 80,
        };
        Attempt {
            recon: incremental::Recon {
                k,
                poses: (0..4)
                    .map(|v| (v < registered).then(gems_math::Se3::identity))
                    .collect(),
                tracks: Vec::new(),
                path: None,
            },
            working_size: 128,
            scale: 0.5,
            error_px,
            focal_start_px: f,
        }
    }

    /// The report of a 240-px-wide capture whose focal was `given` or estimated, with `blur` px
    /// of estimated blur.
    fn stats_with(given: bool, blur: f64) -> SfmStats {
        SfmStats {
            registered: 4,
            total: 4,
            points: 100,
            mean_reprojection_error: 0.5,
            mean_track_length: 3.0,
            seconds: 1.0,
            unregistered: Vec::new(),
            working_size: 128,
            final_size: 128,
            focal: 207.8,
            focal_from_metadata: given,
            focal_barely_determined: false,
            seconds_features: 0.5,
            seconds_reconstruction: 0.5,
            blur_px_estimate: blur,
            capture_order: false,
            views: Vec::new(),
            advice: Vec::new(),
        }
    }

    #[test]
    fn an_estimated_focal_under_heavy_blur_comes_with_advice() {
        let line = focal_advice(&stats_with(false, 18.0), 240.0).expect("7.5 % of the side");
        assert!(
            line.contains("208 px") && line.contains("18 px") && line.contains("8 %"),
            "{line}"
        );
        assert!(line.contains("--focal"), "{line}");
        assert_eq!(focal_advice(&stats_with(false, 12.0), 240.0), None, "5 %");
        assert_eq!(focal_advice(&stats_with(false, 0.0), 240.0), None, "sharp");
        assert_eq!(
            focal_advice(&stats_with(true, 30.0), 240.0),
            None,
            "a focal given or read from EXIF"
        );
        // The report's flag says the same.
        for (given, blur, barely) in [
            (false, 18.0, true),
            (false, 12.0, false),
            (false, 0.0, false),
            (true, 30.0, false),
        ] {
            assert_eq!(
                focal_barely_determined(&stats_with(given, blur), 240.0),
                barely,
                "given {given}, blur {blur}"
            );
        }
    }

    #[test]
    fn only_photos_with_moderate_blur_are_trimmed() {
        let opts = SfmOptions::default();
        assert!(trims(0.0, 240.0, &opts));
        assert!(trims(24.0, 240.0, &opts), "10 % of the long side");
        assert!(!trims(26.0, 240.0, &opts));
        let off = SfmOptions {
            trim_fraction: 0.0,
            ..SfmOptions::default()
        };
        assert!(!trims(0.0, 240.0, &off));
    }

    #[test]
    fn ties_are_the_most_registered_within_the_error_tolerance() {
        let attempts = vec![
            attempt(150.0, 4, 1.000),
            attempt(200.0, 4, 1.005),
            attempt(250.0, 4, 1.020),
            attempt(300.0, 3, 0.500),
        ];
        let tied: Vec<f64> = tied_attempts(&attempts)
            .iter()
            .map(|a| a.focal_start_px)
            .collect();
        // 300 registered fewer views, 250 is 2 % worse than the best.
        assert_eq!(tied, vec![150.0, 200.0]);
        // Of the ties, the one nearest the prior (1.0 × the long side, 256 px) wins.
        let best = choose_attempt(&attempts, 256.0).expect("an attempt");
        assert_eq!(best.focal_start_px, 200.0);
        assert!(tied_attempts(&[]).is_empty());
    }

    /// The candidates grow beyond an end only while that end is the chosen attempt, one step in
    /// the end's own ratio, within the search span; attempts at another working size do not
    /// count.
    #[test]
    fn focal_candidates_extend_beyond_a_winning_end() {
        let long = 256.0;
        let opts = SfmOptions::default();
        let at = |errors: &[f64]| -> Vec<Attempt> {
            opts.focal_candidates
                .iter()
                .zip(errors)
                .map(|(c, &e)| attempt(c * long, 4, e))
                .collect()
        };
        let next = |a: &[Attempt], opts: &SfmOptions| {
            focal_beyond_the_candidates(a, 128, long, opts).map(|f| (f * 1e6).round() / 1e6)
        };
        // The largest wins: one step of 1.7 / 1.35 beyond it.
        let up = at(&[1.3, 1.25, 1.2, 1.15, 1.1, 1.0]);
        assert_eq!(
            next(&up, &opts),
            Some((1.7 * 1.7 / 1.35 * 1e6f64).round() / 1e6)
        );
        // The smallest wins: one step of 0.6 / 0.75 below it.
        let down = at(&[1.0, 1.1, 1.15, 1.2, 1.25, 1.3]);
        assert_eq!(
            next(&down, &opts),
            Some((0.6 * 0.6 / 0.75 * 1e6f64).round() / 1e6)
        );
        // An inner candidate wins, or the winning end is tied with an inner one nearer the
        // prior: no extension.
        assert_eq!(next(&at(&[1.2, 1.1, 1.0, 1.05, 1.1, 1.2]), &opts), None);
        assert_eq!(next(&at(&[1.3, 1.25, 1.2, 1.15, 1.005, 1.0]), &opts), None);
        // The span ends at the list's ends: no extension.
        let held = SfmOptions {
            focal_search_span: (0.6, 1.7),
            ..SfmOptions::default()
        };
        assert_eq!(next(&up, &held), None);
        assert_eq!(next(&down, &held), None);
        // A repeated candidate at the winning end gives no step.
        let repeated: Vec<Attempt> = [1.0, 1.7, 1.7]
            .iter()
            .zip([1.2, 1.0, 1.0])
            .map(|(c, e)| attempt(c * long, 4, e))
            .collect();
        assert_eq!(next(&repeated, &opts), None);
        // Only the attempts at the working size asked about count.
        let mut other = up.clone();
        for a in &mut other {
            a.working_size = 64;
        }
        assert_eq!(next(&other, &opts), None);
    }

    /// Overlaps of views placed along a line at `position`: the nearer, the more similar.
    fn overlaps_along(position: &[f64]) -> Vec<Vec<tracking::Overlap>> {
        position
            .iter()
            .map(|a| {
                position
                    .iter()
                    .map(|b| tracking::Overlap {
                        score: if a == b {
                            -1.0
                        } else {
                            (1.0 / (1.0 + (a - b).abs())) as f32
                        },
                        shift: [0.0, 0.0],
                    })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn capture_order_is_detected_in_order_and_not_when_shuffled() {
        let ordered: Vec<f64> = (0..12).map(f64::from).collect();
        let (k, n) = consecutive_best_partners(&overlaps_along(&ordered));
        assert_eq!((k, n), (11, 11));
        assert!(detect_capture_order(k, n));
        // The same positions visited in a scrambled order.
        let shuffled: Vec<f64> = (0..12).map(|i| f64::from((i * 5) % 12)).collect();
        let (k, n) = consecutive_best_partners(&overlaps_along(&shuffled));
        assert!(k < 4, "{k} of {n}");
        assert!(!detect_capture_order(k, n));
        // One jump back to the start (a second sweep, shifted) keeps the capture ordered.
        let two_sweeps: Vec<f64> = (0..12)
            .map(|i| f64::from(i % 6) + 10.0 * f64::from(i / 6))
            .collect();
        let (k, n) = consecutive_best_partners(&overlaps_along(&two_sweeps));
        assert_eq!((k, n), (10, 11));
        assert!(detect_capture_order(k, n));
        assert!(
            !detect_capture_order(0, 1),
            "two images have no order to speak of"
        );
    }

    #[test]
    fn the_path_prior_follows_the_options() {
        let ov = overlaps_along(&(0..6).map(f64::from).collect::<Vec<_>>());
        let opts = SfmOptions {
            capture_order: CaptureOrder::Detect,
            ..SfmOptions::default()
        };
        let prior = path_prior(&ov, &opts).expect("ordered views");
        assert_eq!(prior.order, (0..6).collect::<Vec<_>>());
        assert!((prior.rotation_sigma - 0.5f64.to_radians()).abs() < 1e-15);
        let off = |o: SfmOptions| path_prior(&ov, &o);
        assert!(off(SfmOptions::default()).is_none(), "off by default");
        assert!(
            off(SfmOptions {
                path_centre_sigma: 0.0,
                path_rotation_sigma_deg: 0.0,
                ..opts.clone()
            })
            .is_none()
        );
        let shuffled = [0.0, 3.0, 1.0, 4.0, 2.0, 5.0];
        assert!(path_prior(&overlaps_along(&shuffled), &opts).is_none());
        assert!(
            path_prior(
                &overlaps_along(&shuffled),
                &SfmOptions {
                    capture_order: CaptureOrder::Ordered,
                    ..SfmOptions::default()
                }
            )
            .is_some()
        );
    }
}
