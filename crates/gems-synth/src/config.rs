//! Generator settings and presets.

use serde::Serialize;

use crate::SynthError;

/// Event simulation settings (ESIM semantics, via gems-events).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EventOptions {
    /// ON contrast threshold (log-intensity step).
    pub threshold_pos: f32,
    /// OFF contrast threshold.
    pub threshold_neg: f32,
    /// σ of the fixed per-pixel threshold mismatch (0 = none).
    pub threshold_sigma: f32,
    /// Refractory period in µs (0 = none).
    pub refractory_us: i64,
    /// Largest image motion (pixels) between two frames fed to the simulator. The simulator
    /// interpolates log intensity linearly between frames, which is only faithful when edges
    /// move about a pixel or two per frame, so extra frames are rendered inside the exposure as
    /// needed. The default 2 px keeps event timing well inside one of the 13–15 EDI bins of an
    /// exposure while costing at most one extra render per blur sub-frame at 30 px blur.
    pub max_step_px: f64,
}

impl Default for EventOptions {
    fn default() -> Self {
        Self {
            threshold_pos: 0.2,
            threshold_neg: 0.2,
            threshold_sigma: 0.0,
            refractory_us: 0,
            max_step_px: 2.0,
        }
    }
}

/// Everything that defines a generated scene. Same config (including `seed`) → byte-identical
/// output files.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SynthConfig {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Horizontal field of view in degrees.
    pub fov_x_deg: f64,
    /// Number of views (blurry images).
    pub views: usize,
    /// Requested blur: mean image-space path length (pixels) of scene points over one exposure.
    pub blur_px: f64,
    /// Sharp sub-frames averaged into each blurry image (poses at u = k/(S−1), both exposure ends
    /// included, as in BAD-Gaussians/GeMS virtual cameras).
    pub subframes: usize,
    /// Jittered ray samples per pixel (antialiasing).
    pub spp: u32,
    /// Boxes and spheres placed in the scene (besides the ground and the back wall).
    pub objects: usize,
    /// Hold-out interval written as the `hold=<n>` marker (n < 1: no held-out novel views).
    pub hold: i32,
    /// Total angle (degrees) of the arc the views lie on.
    pub arc_deg: f64,
    /// Exposure duration in µs (timestamps of events and exposure windows).
    pub exposure_us: i64,
    /// Time from one exposure start to the next, in µs.
    pub frame_interval_us: i64,
    /// Events to simulate; `None` writes no event files.
    pub events: Option<EventOptions>,
    /// Master seed: world, camera motions, threshold mismatch.
    pub seed: u64,
}

/// The named presets of `gems synth --preset`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Preset {
    Tiny,
    Small,
    Medium,
}

impl SynthConfig {
    /// 96×64, 8 views, 12 px blur, 8 sub-frames: a complete scene in well under a second; for
    /// unit tests of other crates.
    pub fn tiny() -> Self {
        Self {
            width: 96,
            height: 64,
            views: 8,
            blur_px: 12.0,
            subframes: 8,
            spp: 4,
            ..Self::small()
        }
    }

    /// 240×160, 16 views, 30 px blur, 16 sub-frames: the demo scene; a few seconds.
    pub fn small() -> Self {
        Self {
            width: 240,
            height: 160,
            fov_x_deg: 60.0,
            views: 16,
            blur_px: 30.0,
            subframes: 16,
            spp: 4,
            objects: 7,
            hold: 8,
            arc_deg: 40.0,
            exposure_us: 40_000,
            frame_interval_us: 100_000,
            events: Some(EventOptions::default()),
            seed: 0,
        }
    }

    /// 400×270 (ExBluRF at data factor 2), 24 views, 45 px blur, 16 sub-frames.
    pub fn medium() -> Self {
        Self {
            width: 400,
            height: 270,
            views: 24,
            blur_px: 45.0,
            ..Self::small()
        }
    }

    /// The preset's configuration.
    pub fn preset(p: Preset) -> Self {
        match p {
            Preset::Tiny => Self::tiny(),
            Preset::Small => Self::small(),
            Preset::Medium => Self::medium(),
        }
    }

    /// Checks the settings, naming the first bad one.
    pub fn validate(&self) -> Result<(), SynthError> {
        let bad = |msg: String| Err(SynthError::Config(msg));
        if self.width < 8 || self.height < 8 || self.width > 8192 || self.height > 8192 {
            return bad(format!(
                "image size {}×{} must be within 8..=8192",
                self.width, self.height
            ));
        }
        if !(self.fov_x_deg > 1.0 && self.fov_x_deg < 170.0) {
            return bad(format!(
                "field of view {}° must be within (1, 170)",
                self.fov_x_deg
            ));
        }
        if self.views == 0 {
            return bad("at least one view is needed".into());
        }
        if !(self.blur_px.is_finite() && self.blur_px >= 0.0) {
            return bad(format!("blur {} px must be finite and ≥ 0", self.blur_px));
        }
        if self.subframes == 0 {
            return bad("at least one sub-frame is needed".into());
        }
        if self.spp == 0 || self.spp > 256 {
            return bad(format!(
                "samples per pixel {} must be within 1..=256",
                self.spp
            ));
        }
        if !(self.arc_deg.is_finite() && (0.0..=180.0).contains(&self.arc_deg)) {
            return bad(format!("arc {}° must be within [0, 180]", self.arc_deg));
        }
        if self.exposure_us < 1 || self.frame_interval_us <= self.exposure_us {
            return bad(format!(
                "exposure {} µs must be ≥ 1 and shorter than the frame interval {} µs",
                self.exposure_us, self.frame_interval_us
            ));
        }
        if let Some(ev) = &self.events {
            if !(ev.threshold_pos >= 0.01 && ev.threshold_neg >= 0.01) {
                return bad(format!(
                    "event thresholds {}/{} must be ≥ 0.01",
                    ev.threshold_pos, ev.threshold_neg
                ));
            }
            if !(ev.threshold_sigma.is_finite() && ev.threshold_sigma >= 0.0) {
                return bad(format!("threshold σ {} must be ≥ 0", ev.threshold_sigma));
            }
            if ev.refractory_us < 0 {
                return bad(format!(
                    "refractory period {} µs must be ≥ 0",
                    ev.refractory_us
                ));
            }
            if !(ev.max_step_px.is_finite() && ev.max_step_px > 0.05) {
                return bad(format!(
                    "event frame step {} px must be > 0.05",
                    ev.max_step_px
                ));
            }
        }
        Ok(())
    }
}
