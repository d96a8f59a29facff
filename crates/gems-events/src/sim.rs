//! ESIM-style event simulation from timestamped frames (ESIM, Rebecq et al. 2018;
//! `uzh-rpg/rpg_esim:event_camera_simulator/esim/src/event_simulator.cpp`).
//!
//! Per pixel the simulator tracks the log luminance `log(Y + ε)` of the last frame and a reference
//! level (the last threshold crossing, initialised from the first frame). Between two frames the log
//! signal is interpolated linearly in time; every crossing of `ref ± C` inside the interval emits an
//! event stamped with the interpolated crossing time (rounded to µs). Thresholds `C+`/`C−` can carry
//! a fixed per-pixel mismatch `N(0, σ)` (floored at 0.01, drawn once from the seed). With a
//! refractory period, an event closer than that to the pixel's previous *emitted* event is dropped,
//! but the reference level still advances (ESIM semantics).
//!
//! Determinism: the mismatch is drawn from `ChaCha8Rng::seed_from_u64(seed)` in pixel order; rows are
//! simulated in parallel but collected in row order and stably sorted by time, so the output does
//! not depend on the thread count.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

use crate::{EventError, EventStream};

/// Simulator parameters. `Default` = ESIM's clean setting with the v2e/esim_torch threshold 0.2.
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    /// ON threshold (log-intensity step per positive event).
    pub c_pos: f32,
    /// OFF threshold (positive number; log-intensity step per negative event).
    pub c_neg: f32,
    /// Standard deviation of the fixed per-pixel mismatch added to `c_pos` (0 = none).
    pub sigma_pos: f32,
    /// Standard deviation of the fixed per-pixel mismatch added to `c_neg` (0 = none).
    pub sigma_neg: f32,
    /// Refractory period in µs (0 = none).
    pub refractory_us: i64,
    /// ε in `log(Y + ε)`.
    pub log_eps: f32,
    /// Seed of the threshold mismatch.
    pub seed: u64,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            c_pos: 0.2,
            c_neg: 0.2,
            sigma_pos: 0.0,
            sigma_neg: 0.0,
            refractory_us: 0,
            log_eps: 1e-3,
            seed: 0,
        }
    }
}

/// Smallest threshold after mismatch (ESIM/v2e floor).
const MIN_THRESHOLD: f32 = 0.01;

/// Rec. 709 / sRGB luminance of linear RGB.
pub fn luminance(r: f32, g: f32, b: f32) -> f32 {
    0.2126 * r + 0.7152 * g + 0.0722 * b
}

/// Incremental event simulator for one `width × height` sensor.
#[derive(Debug, Clone)]
pub struct Simulator {
    config: SimConfig,
    width: u16,
    height: u16,
    c_pos: Vec<f32>,
    c_neg: Vec<f32>,
    last_log: Vec<f32>,
    ref_log: Vec<f32>,
    /// Time of the pixel's last emitted event; `i64::MIN` = none yet.
    last_event: Vec<i64>,
    last_t: Option<i64>,
    events: EventStream,
    log_buf: Vec<f32>,
}

impl Simulator {
    /// A simulator with no frame seen yet.
    pub fn new(config: SimConfig, width: u16, height: u16) -> Result<Self, EventError> {
        let bad = |what: &str| Err(EventError::Invalid(format!("simulator: {what}")));
        if !(config.c_pos >= MIN_THRESHOLD && config.c_neg >= MIN_THRESHOLD) {
            return bad("thresholds must be ≥ 0.01");
        }
        if !(config.sigma_pos >= 0.0 && config.sigma_neg >= 0.0) {
            return bad("mismatch σ must be ≥ 0");
        }
        if config.refractory_us < 0 {
            return bad("refractory period must be ≥ 0");
        }
        if config.log_eps.is_nan() || config.log_eps <= 0.0 {
            return bad("log ε must be > 0");
        }
        if width == 0 || height == 0 {
            return bad("sensor size must be non-zero");
        }
        let n = width as usize * height as usize;
        let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
        let mismatch = |c: f32, sigma: f32, rng: &mut ChaCha8Rng| -> Vec<f32> {
            if sigma == 0.0 {
                return vec![c; n];
            }
            let normal = Normal::new(0.0f32, sigma).expect("σ checked finite and ≥ 0");
            (0..n)
                .map(|_| (c + normal.sample(rng)).max(MIN_THRESHOLD))
                .collect()
        };
        let c_pos = mismatch(config.c_pos, config.sigma_pos, &mut rng);
        let c_neg = mismatch(config.c_neg, config.sigma_neg, &mut rng);
        Ok(Self {
            config,
            width,
            height,
            c_pos,
            c_neg,
            last_log: vec![0.0; n],
            ref_log: vec![0.0; n],
            last_event: vec![i64::MIN; n],
            last_t: None,
            events: EventStream::empty(width, height),
            log_buf: vec![0.0; n],
        })
    }

    /// The per-pixel ON thresholds in use (after mismatch).
    pub fn thresholds_pos(&self) -> &[f32] {
        &self.c_pos
    }
    /// The per-pixel OFF thresholds in use (after mismatch).
    pub fn thresholds_neg(&self) -> &[f32] {
        &self.c_neg
    }

    /// Feeds a frame of linear luminance (row-major, `width·height` values ≥ 0) taken at `t_us`.
    /// Times must strictly increase.
    pub fn feed_luma(&mut self, luma: &[f32], t_us: i64) -> Result<(), EventError> {
        let n = self.c_pos.len();
        if luma.len() != n {
            return Err(EventError::Invalid(format!(
                "simulator: frame has {} values, sensor has {n}",
                luma.len()
            )));
        }
        if let Some(i) = luma.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(EventError::Invalid(format!(
                "simulator: luminance {} at pixel {i} is not a finite value ≥ 0",
                luma[i]
            )));
        }
        let eps = self.config.log_eps;
        let mut logs = std::mem::take(&mut self.log_buf);
        logs.par_iter_mut()
            .zip(luma.par_iter())
            .for_each(|(l, &y)| *l = (y + eps).ln());
        let result = self.feed_log(&logs, t_us);
        self.log_buf = logs;
        result
    }

    /// Feeds a frame of linear RGB (row-major, interleaved, `3·width·height` values).
    pub fn feed_rgb(&mut self, rgb: &[f32], t_us: i64) -> Result<(), EventError> {
        if rgb.len() != 3 * self.c_pos.len() {
            return Err(EventError::Invalid(format!(
                "simulator: RGB frame has {} values, expected {}",
                rgb.len(),
                3 * self.c_pos.len()
            )));
        }
        let luma: Vec<f32> = rgb
            .chunks_exact(3)
            .map(|c| luminance(c[0], c[1], c[2]))
            .collect();
        self.feed_luma(&luma, t_us)
    }

    fn feed_log(&mut self, logs: &[f32], t1: i64) -> Result<(), EventError> {
        let Some(t0) = self.last_t else {
            self.last_log.copy_from_slice(logs);
            self.ref_log.copy_from_slice(logs);
            self.last_t = Some(t1);
            return Ok(());
        };
        if t1 <= t0 {
            return Err(EventError::Invalid(format!(
                "simulator: frame time {t1} µs is not after the previous frame at {t0} µs"
            )));
        }
        let w = self.width as usize;
        let refractory = self.config.refractory_us;
        let rows: Vec<Vec<(i64, u16, i8)>> = self
            .last_log
            .par_chunks_mut(w)
            .zip(self.ref_log.par_chunks_mut(w))
            .zip(self.last_event.par_chunks_mut(w))
            .zip(self.c_pos.par_chunks(w).zip(self.c_neg.par_chunks(w)))
            .zip(logs.par_chunks(w))
            .map(|((((last, reference), last_ev), (cp, cn)), new)| {
                let mut out = Vec::new();
                for x in 0..w {
                    simulate_pixel(
                        PixelStep {
                            it: last[x],
                            itdt: new[x],
                            t0,
                            t1,
                            c_pos: cp[x],
                            c_neg: cn[x],
                        },
                        &mut reference[x],
                        &mut last_ev[x],
                        refractory,
                        |t, p| out.push((t, x as u16, p)),
                    );
                    last[x] = new[x];
                }
                out
            })
            .collect();
        let total: usize = rows.iter().map(Vec::len).sum();
        let mut order: Vec<(i64, u32, u16, i8)> = Vec::with_capacity(total);
        for (y, row) in rows.into_iter().enumerate() {
            order.extend(row.into_iter().map(|(t, x, p)| (t, y as u32, x, p)));
        }
        // Stable by time: equal timestamps keep (row, column, emission) order.
        order.sort_by_key(|e| e.0);
        let mut batch = EventStream::empty(self.width, self.height);
        let (mut tt, mut xx, mut yy, mut pp) = (
            Vec::with_capacity(total),
            Vec::with_capacity(total),
            Vec::with_capacity(total),
            Vec::with_capacity(total),
        );
        for (t, y, x, p) in order {
            tt.push(t);
            xx.push(x);
            yy.push(y as u16);
            pp.push(p);
        }
        if total > 0 {
            batch = EventStream::from_columns(self.width, self.height, tt, xx, yy, pp)?;
        }
        self.events.append(batch)?;
        self.last_t = Some(t1);
        Ok(())
    }

    /// Events emitted so far.
    pub fn events(&self) -> &EventStream {
        &self.events
    }

    /// Ends the simulation and returns every event.
    pub fn finish(self) -> EventStream {
        self.events
    }
}

/// One pixel's log samples at the two ends of a frame interval.
struct PixelStep {
    it: f32,
    itdt: f32,
    t0: i64,
    t1: i64,
    c_pos: f32,
    c_neg: f32,
}

/// ESIM's crossing loop for one pixel and one frame interval.
fn simulate_pixel(
    s: PixelStep,
    reference: &mut f32,
    last_event: &mut i64,
    refractory: i64,
    mut emit: impl FnMut(i64, i8),
) {
    let delta = s.itdt - s.it;
    if delta.abs() <= 1e-6 {
        return;
    }
    let (pol, c) = if delta > 0.0 {
        (1i8, s.c_pos)
    } else {
        (-1i8, s.c_neg)
    };
    let step = f32::from(pol) * c;
    let span = (s.t1 - s.t0) as f64;
    loop {
        let level = *reference + step;
        let inside = if pol > 0 {
            level > s.it && level <= s.itdt
        } else {
            level < s.it && level >= s.itdt
        };
        if !inside {
            break;
        }
        let frac = f64::from(level - s.it) / f64::from(delta);
        let t = s.t0 + (frac * span).round() as i64;
        if *last_event == i64::MIN || t - *last_event >= refractory {
            emit(t, pol);
            *last_event = t;
        }
        *reference = level;
    }
}
