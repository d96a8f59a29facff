//! `simulate_folder`: events from a folder of timestamped sharp frames.
//!
//! Accepted layouts (first match wins):
//! 1. `timestamps.txt` or `images.txt` (ECD): lines `<t in seconds> <image path relative to the
//!    folder>`;
//! 2. `images.csv` (ESIM): lines `<t in nanoseconds>, <relative image path>`;
//! 3. otherwise every `.png`/`.jpg`/`.jpeg` whose file stem is an integer, read as the frame time in
//!    **microseconds** (e.g. `000000.png`, `001000.png`, …).
//!
//! `#`/`%` lines are comments. Frames are read with `image` (8/16-bit gray or colour), decoded to
//! linear light per [`FrameEncoding`] and reduced to luminance before simulation.

use std::path::{Path, PathBuf};

use crate::{EventError, EventStream, SimConfig, Simulator, TimeUnit, luminance};

/// How frame pixel values map to linear light.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FrameEncoding {
    /// sRGB-encoded (ordinary PNG/JPEG): decoded with the sRGB transfer function.
    #[default]
    Srgb,
    /// Already linear (e.g. rendered radiance written without a transfer curve).
    Linear,
}

fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// Lists `(t µs, path)` of the frames in `dir`, sorted by time. The unit of a timestamps file is
/// `unit` when given, else detected from its values ([`crate::detect_units`]; the file's
/// convention — `timestamps.txt`/`images.txt` s, `images.csv` ns — breaks ties).
pub fn list_frames(dir: &Path, unit: Option<TimeUnit>) -> Result<Vec<(i64, PathBuf)>, EventError> {
    let mut frames = Vec::new();
    let listed = [
        ("timestamps.txt", TimeUnit::Seconds),
        ("images.txt", TimeUnit::Seconds),
        ("images.csv", TimeUnit::Nanoseconds),
    ];
    if let Some((name, convention)) = listed.iter().find(|(n, _)| dir.join(n).is_file()) {
        let path = dir.join(name);
        let text = std::fs::read_to_string(&path).map_err(|e| EventError::io(&path, e))?;
        let mut raw: Vec<(f64, PathBuf)> = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') || line.starts_with('%') {
                continue;
            }
            let mut parts = line
                .split(|c: char| c == ',' || c.is_whitespace())
                .filter(|s| !s.is_empty());
            let (Some(ts), Some(file)) = (parts.next(), parts.next()) else {
                return Err(EventError::format(
                    &path,
                    format!("line {}: expected `<time> <image>`", i + 1),
                ));
            };
            let t: f64 = ts.parse().map_err(|_| {
                EventError::format(&path, format!("line {}: bad time '{ts}'", i + 1))
            })?;
            raw.push((t, dir.join(file)));
        }
        let unit = match unit {
            Some(u) => u,
            None => {
                let mut values: Vec<f64> = raw.iter().map(|r| r.0).collect();
                values.sort_by(f64::total_cmp);
                let summary = crate::TimeSummary::of_values(
                    path.display().to_string(),
                    crate::SeriesKind::Frames,
                    &values,
                    *convention,
                );
                crate::detect_units(&[summary]).map_err(|m| EventError::format(&path, m))?[0]
            }
        };
        for (t, file) in raw {
            let us = unit
                .floats_to_us(&[t])
                .map_err(|m| EventError::format(&path, m))?[0];
            frames.push((us, file));
        }
    } else {
        for path in gems_fs::list_images(dir)? {
            if let Some(t) = path
                .file_stem()
                .and_then(|s| s.to_str())
                .and_then(|s| s.parse::<i64>().ok())
            {
                frames.push((t, path));
            }
        }
    }
    if frames.len() < 2 {
        return Err(EventError::format(
            dir,
            "need at least 2 timestamped frames (timestamps.txt, images.txt, images.csv, or images named by µs)",
        ));
    }
    frames.sort_by_key(|f| f.0);
    if let Some(w) = frames.windows(2).find(|w| w[0].0 == w[1].0) {
        return Err(EventError::format(
            dir,
            format!(
                "two frames share the timestamp {} µs: {}",
                w[0].0,
                w[1].1.display()
            ),
        ));
    }
    Ok(frames)
}

/// Reads an image as linear luminance, row-major; returns `(width, height, luma)`.
pub fn read_luminance(
    path: &Path,
    encoding: FrameEncoding,
) -> Result<(u32, u32, Vec<f32>), EventError> {
    let img = image::open(path)
        .map_err(|e| EventError::format(path, format!("cannot read image: {e}")))?;
    let rgb = img.to_rgb32f();
    let (w, h) = rgb.dimensions();
    let dec = |v: f32| match encoding {
        FrameEncoding::Srgb => srgb_to_linear(v),
        FrameEncoding::Linear => v,
    };
    let luma = rgb
        .pixels()
        .map(|p| luminance(dec(p[0]), dec(p[1]), dec(p[2])))
        .collect();
    Ok((w, h, luma))
}

/// Simulates events over every frame of `dir` (layouts in the module docs).
/// `unit` is the unit of a timestamps file (`None`: detected, see [`list_frames`]).
pub fn simulate_folder(
    dir: &Path,
    config: &SimConfig,
    encoding: FrameEncoding,
    unit: Option<TimeUnit>,
) -> Result<EventStream, EventError> {
    let frames = list_frames(dir, unit)?;
    let mut sim: Option<Simulator> = None;
    let mut size = (0, 0);
    for (t, path) in &frames {
        let (w, h, luma) = read_luminance(path, encoding)?;
        let s = match &mut sim {
            Some(s) => {
                if (w, h) != size {
                    return Err(EventError::format(
                        path,
                        format!("frame is {w}×{h}, earlier frames are {}×{}", size.0, size.1),
                    ));
                }
                s
            }
            None => {
                size = (w, h);
                let (w16, h16) = (u16::try_from(w), u16::try_from(h));
                let (Ok(w16), Ok(h16)) = (w16, h16) else {
                    return Err(EventError::format(
                        path,
                        "frame larger than 65535 pixels per side",
                    ));
                };
                sim.insert(Simulator::new(config.clone(), w16, h16)?)
            }
        };
        s.feed_luma(&luma, *t)
            .map_err(|e| EventError::format(path, e.to_string()))?;
        tracing::debug!(frame = %path.display(), events = s.events().len(), "simulated");
    }
    Ok(sim.expect("at least two frames").finish())
}
