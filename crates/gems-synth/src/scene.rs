//! The in-memory ground truth: world, cameras, per-view exposure motions, and the renders made
//! from them (blurry image, sharp mid-exposure image, events).

use gems_events::{EventStream, SimConfig, Simulator};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::SynthError;
use crate::camera::{CameraPose, ExposureMotion, arc_path, mean_path_length_px};
use crate::config::SynthConfig;
use crate::geom::V3;
use crate::render::{Image, encode_srgb, render_linear};
use crate::world::World;
use gems_math::Intrinsics;

/// Ground truth of one view.
#[derive(Clone, Debug)]
pub struct ViewTruth {
    /// Mid-exposure pose (the ground-truth pose of the blurry image and of its sharp twin).
    pub mid: CameraPose,
    /// Camera motion inside the exposure.
    pub motion: ExposureMotion,
    /// LLFF depth bounds: 0.1th / 99.9th percentile of visible depth at mid-exposure.
    pub near: f64,
    pub far: f64,
    /// Blur actually achieved (mean path length in pixels over the whole exposure curve).
    pub blur_px: f64,
}

/// What one view renders to.
#[derive(Clone, Debug)]
pub struct ViewRender {
    /// Mean of the sRGB-encoded sharp sub-frames (values in [0, 1], not yet quantised).
    pub blurry: Image,
    /// sRGB sharp image at mid-exposure (u = 0.5).
    pub sharp: Image,
    /// Events of this exposure (time-sorted, µs), when events are enabled.
    pub events: Option<EventStream>,
}

/// A generated scene held in memory. [`SynthScene::new`] is cheap (no image rendering), so tests
/// can build one and render any view, sub-frame or ground-truth depth directly.
#[derive(Clone, Debug)]
pub struct SynthScene {
    pub config: SynthConfig,
    pub world: World,
    pub intrinsics: Intrinsics,
    pub views: Vec<ViewTruth>,
    jitter_seed: u32,
}

/// Probe grid used for depth bounds and blur calibration (cells per axis).
const PROBE: u32 = 32;
/// Samples of the exposure curve used to measure its image-space length.
const CURVE_SAMPLES: usize = 64;

impl SynthScene {
    /// Builds the world, the view path and each view's calibrated exposure motion.
    pub fn new(config: &SynthConfig) -> Result<Self, SynthError> {
        config.validate()?;
        let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
        let world = World::random(&mut rng, config.objects);
        let intrinsics = Intrinsics::from_fov(config.width, config.height, config.fov_x_deg);
        let mids = arc_path(config.views, world.target, 5.0, 1.0, config.arc_deg);
        let jitter_seed = rng.random::<u32>();
        let views = mids
            .into_iter()
            .map(|mid| {
                let points = probe_points(&world, &intrinsics, &mid);
                let mut depths: Vec<f64> = points.iter().map(|p| mid.to_camera(*p)[2]).collect();
                depths.sort_by(f64::total_cmp);
                let pct = |q: f64| depths[((depths.len() - 1) as f64 * q).round() as usize];
                let (near, far, median) = if depths.is_empty() {
                    (0.1, 100.0, 5.0)
                } else {
                    (pct(0.001), pct(0.999), pct(0.5))
                };
                let (motion, blur_px) =
                    calibrated_motion(&mut rng, median, &mid, &points, &intrinsics, config.blur_px);
                ViewTruth {
                    mid,
                    motion,
                    near,
                    far,
                    blur_px,
                }
            })
            .collect();
        Ok(Self {
            config: config.clone(),
            world,
            intrinsics,
            views,
            jitter_seed,
        })
    }

    /// Exposure fractions of the blur sub-frames: u = k/(S−1), or 0.5 when S = 1.
    pub fn subframe_times(&self) -> Vec<f64> {
        uniform_times(self.config.subframes)
    }

    /// Poses of view `view`'s blur sub-frames.
    pub fn subframe_poses(&self, view: usize) -> Vec<CameraPose> {
        let v = &self.views[view];
        self.subframe_times()
            .iter()
            .map(|&u| v.motion.pose_at(&v.mid, u))
            .collect()
    }

    /// Linear-radiance render of view `view` at exposure fraction `u`.
    pub fn render_linear(&self, view: usize, u: f64) -> Image {
        let v = &self.views[view];
        render_linear(
            &self.world,
            &self.intrinsics,
            &v.motion.pose_at(&v.mid, u),
            self.config.spp,
            self.jitter_seed,
        )
    }

    /// sRGB render of view `view` at exposure fraction `u` (u = 0.5 is the sharp ground truth).
    pub fn render_sharp(&self, view: usize, u: f64) -> Image {
        encode_srgb(&self.render_linear(view, u))
    }

    /// Number of frames rendered per exposure for the event simulator, chosen so the image moves
    /// at most `max_step_px` between frames; a multiple of the blur sub-frame spacing so that every
    /// blur sub-frame is also an event frame (rendered once, used twice).
    pub fn event_frames_per_exposure(&self) -> Option<usize> {
        let ev = self.config.events.as_ref()?;
        let s = self.config.subframes;
        // The requested blur, not the calibrated one (which may exceed it by a hair): a 2.0004 px
        // step must not double the frames.
        let blur = self.config.blur_px;
        Some(if s > 1 {
            let refine = (blur / (s - 1) as f64 / ev.max_step_px).ceil().max(1.0) as usize;
            (s - 1) * refine + 1
        } else {
            (blur / ev.max_step_px).ceil().max(1.0) as usize + 1
        })
    }

    /// Exposure window of view `view` in µs: `[start, end]`.
    pub fn exposure_window_us(&self, view: usize) -> (i64, i64) {
        let start = view as i64 * self.config.frame_interval_us;
        (start, start + self.config.exposure_us)
    }

    /// Renders view `view`: blurry image (mean of the S sharp sRGB sub-frames), sharp ground
    /// truth, and, when enabled, the events of the exposure.
    ///
    /// The blur average is taken over sRGB-encoded frames, not linear radiance: this is exactly
    /// the GeMS / BAD-Gaussians image-formation model (B = mean of sRGB renders), so a trainer
    /// using that model can fit these images without model mismatch. (Real sensors average linear
    /// light; ExBluRF averages linear then encodes. The difference is confined to high-contrast
    /// edges.) Events see linear luminance clipped at 1, as a saturating event pixel does.
    pub fn render_view(&self, view: usize) -> Result<ViewRender, SynthError> {
        let s = self.config.subframes;
        let k = &self.intrinsics;
        let event_frames = self.event_frames_per_exposure();
        // Every frame time is an integer key n/den so blur, event and mid-exposure frames that
        // coincide are recognised exactly and rendered once.
        let (sd, ed) = ((s.max(2) - 1), event_frames.map_or(1, |m| m - 1));
        let den = 2 * sd * ed;
        let mut keys: std::collections::BTreeMap<usize, (bool, bool)> =
            std::collections::BTreeMap::new();
        if s == 1 {
            keys.entry(den / 2).or_default().0 = true;
        } else {
            for i in 0..s {
                keys.entry(i * den / sd).or_default().0 = true;
            }
        }
        if event_frames.is_some() {
            for j in 0..=ed {
                keys.entry(j * den / ed).or_default().1 = true;
            }
        }
        let mut sim = match &self.config.events {
            Some(ev) => {
                let (Ok(w), Ok(h)) = (u16::try_from(k.width), u16::try_from(k.height)) else {
                    return Err(SynthError::Config(format!(
                        "events need an image size ≤ 65535, got {}×{}",
                        k.width, k.height
                    )));
                };
                if 2 * ed as i64 > self.config.exposure_us {
                    return Err(SynthError::Config(format!(
                        "{ed} event frames do not fit in a {} µs exposure at µs resolution",
                        self.config.exposure_us
                    )));
                }
                let sc = SimConfig {
                    c_pos: ev.threshold_pos,
                    c_neg: ev.threshold_neg,
                    sigma_pos: ev.threshold_sigma,
                    sigma_neg: ev.threshold_sigma,
                    refractory_us: ev.refractory_us,
                    log_eps: 1e-3,
                    // One seed for every view: the mismatch is a fixed property of the sensor.
                    seed: self.config.seed ^ 0x5eed_e7e7,
                };
                Some(Simulator::new(sc, w, h)?)
            }
            None => None,
        };
        let (start, _) = self.exposure_window_us(view);
        let mut blurry = Image::zeros(k.width, k.height);
        let mut sharp = None;
        for (&key, &(blur_member, event_member)) in &keys {
            let u = key as f64 / den as f64;
            let lin = self.render_linear(view, u);
            if let (Some(sim), true) = (sim.as_mut(), event_member) {
                // Integer arithmetic keeps the timestamps exact and strictly increasing.
                let t = start + (key as i64 * self.config.exposure_us) / den as i64;
                let clipped: Vec<f32> = lin.data.iter().map(|v| v.clamp(0.0, 1.0)).collect();
                sim.feed_rgb(&clipped, t)?;
            }
            if blur_member || 2 * key == den {
                let enc = encode_srgb(&lin);
                if blur_member {
                    for (b, e) in blurry.data.iter_mut().zip(&enc.data) {
                        *b += e;
                    }
                }
                if 2 * key == den {
                    sharp = Some(enc);
                }
            }
        }
        let inv = 1.0 / s as f32;
        blurry.data.iter_mut().for_each(|v| *v *= inv);
        let sharp = match sharp {
            Some(img) => img,
            None => self.render_sharp(view, 0.5),
        };
        Ok(ViewRender {
            blurry,
            sharp,
            events: sim.map(Simulator::finish),
        })
    }
}

/// `n` uniformly spaced exposure fractions including both ends; `[0.5]` for a single frame.
pub fn uniform_times(n: usize) -> Vec<f64> {
    if n <= 1 {
        vec![0.5]
    } else {
        (0..n).map(|k| k as f64 / (n - 1) as f64).collect()
    }
}

/// World points seen through a `PROBE × PROBE` grid of pixel centres (sky rays are skipped).
pub(crate) fn probe_points(world: &World, k: &Intrinsics, pose: &CameraPose) -> Vec<[f64; 3]> {
    let mut pts = Vec::with_capacity((PROBE * PROBE) as usize);
    for j in 0..PROBE {
        for i in 0..PROBE {
            let u = (f64::from(i) + 0.5) / f64::from(PROBE) * f64::from(k.width);
            let v = (f64::from(j) + 0.5) / f64::from(PROBE) * f64::from(k.height);
            let (o, d) = pose.ray(k, u, v);
            if let Some(hit) = world.intersect(o, d) {
                let p: V3 = o + d * hit.t;
                pts.push([f64::from(p.x), f64::from(p.y), f64::from(p.z)]);
            }
        }
    }
    pts
}

/// Mean image-space path length of `points` over the motion's whole exposure curve.
pub(crate) fn curve_blur_px(
    motion: &ExposureMotion,
    mid: &CameraPose,
    points: &[[f64; 3]],
    k: &Intrinsics,
) -> f64 {
    let poses: Vec<CameraPose> = uniform_times(CURVE_SAMPLES)
        .iter()
        .map(|&u| motion.pose_at(mid, u))
        .collect();
    mean_path_length_px(points, k, &poses)
}

/// A random exposure motion for the view at `mid` scaled to `target` px of blur, and the blur
/// it achieves. The blur is not continuous in the motion's scale (a scene point that passes
/// behind the camera during the exposure leaves the mean), so the target can fall in a jump that
/// no scale of one motion reaches; then up to [`MOTION_DRAWS`] motions are drawn and the closest
/// kept. A view with nothing to blur (no target, no scene points) takes the first draw.
fn calibrated_motion(
    rng: &mut ChaCha8Rng,
    median_depth: f64,
    mid: &CameraPose,
    points: &[[f64; 3]],
    k: &Intrinsics,
    target: f64,
) -> (ExposureMotion, f64) {
    let mut motion = ExposureMotion::random(rng, median_depth);
    let mut blur = calibrate(&mut motion, mid, points, k, target);
    if target == 0.0 || points.is_empty() {
        return (motion, blur);
    }
    let err = |b: f64| (b / target - 1.0).abs();
    for _ in 1..MOTION_DRAWS {
        if err(blur) < BLUR_TOLERANCE {
            break;
        }
        let mut other = ExposureMotion::random(rng, median_depth);
        let b = calibrate(&mut other, mid, points, k, target);
        if err(b) < err(blur) {
            (motion, blur) = (other, b);
        }
    }
    (motion, blur)
}

/// Scales `motion` so the blur is `target` px; returns the achieved blur. The path length is
/// nearly proportional to the scale (exactly so for pure rotation about the centre), so
/// [`PROPORTIONAL_STEPS`] proportional corrections usually converge to well under 1 %. At long
/// blurs perspective makes it superlinear and they can overshoot back and forth; then the rest
/// bisects the bracket of scales seen to fall short of and beyond the target.
fn calibrate(
    motion: &mut ExposureMotion,
    mid: &CameraPose,
    points: &[[f64; 3]],
    k: &Intrinsics,
    target: f64,
) -> f64 {
    if target == 0.0 || points.is_empty() {
        motion.scale = 0.0;
        return 0.0;
    }
    motion.scale = 1e-3;
    let mut blur = curve_blur_px(motion, mid, points, k);
    let (mut short, mut beyond) = (0.0f64, f64::INFINITY);
    for step in 0..CALIBRATION_STEPS {
        if blur <= 0.0 || (step > 0 && (blur / target - 1.0).abs() < 1e-3) {
            break;
        }
        if blur < target {
            short = short.max(motion.scale);
        } else {
            beyond = beyond.min(motion.scale);
        }
        motion.scale = if step < PROPORTIONAL_STEPS || beyond.is_infinite() {
            motion.scale * target / blur
        } else {
            0.5 * (short + beyond)
        };
        blur = curve_blur_px(motion, mid, points, k);
    }
    blur
}

/// Proportional corrections [`calibrate`] tries before it bisects.
const PROPORTIONAL_STEPS: usize = 6;

/// Blur evaluations [`calibrate`] may spend on one motion.
const CALIBRATION_STEPS: usize = 48;

/// Random motions [`calibrated_motion`] draws for one view at most.
const MOTION_DRAWS: usize = 8;

/// Relative blur error at which a motion is redrawn.
const BLUR_TOLERANCE: f64 = 5e-3;
