//! Per-view exposure windows from `exposure_start_ts.txt` / `exposure_end_ts.txt` (BeNeRF's
//! repackaging of E2NeRF real data): one number per line, line i = view i, `#` comments skipped.

use std::path::Path;

use crate::{EventError, TimeUnit};

/// The exposure interval `[start, end]` of one view, in µs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ExposureWindow {
    /// Exposure start (µs).
    pub start: i64,
    /// Exposure end (µs).
    pub end: i64,
}

impl ExposureWindow {
    /// Mid-exposure time (µs).
    pub fn mid(&self) -> i64 {
        self.start + (self.end - self.start) / 2
    }
    /// Exposure length (µs).
    pub fn duration(&self) -> i64 {
        self.end - self.start
    }
}

/// Reads the two files in `dir`, whose values are in `unit` (the E2NeRF/BeNeRF files hold µs;
/// [`exposure_summary`] and [`crate::detect_units`] tell the unit from the values).
pub fn read_exposure_windows(
    dir: &Path,
    unit: TimeUnit,
) -> Result<Vec<ExposureWindow>, EventError> {
    let (starts, ends, end_path) = read_raw(dir)?;
    let to_us = |v: &[f64], path: &Path| {
        unit.floats_to_us(v)
            .map_err(|m| EventError::format(path, m))
    };
    let starts = to_us(&starts, &dir.join("exposure_start_ts.txt"))?;
    let ends = to_us(&ends, &end_path)?;
    if starts.len() != ends.len() {
        return Err(EventError::format(
            &end_path,
            format!(
                "{} exposure ends but {} starts in exposure_start_ts.txt",
                ends.len(),
                starts.len()
            ),
        ));
    }
    starts
        .into_iter()
        .zip(ends)
        .enumerate()
        .map(|(i, (start, end))| {
            if end < start {
                Err(EventError::format(
                    &end_path,
                    format!("view {i}: exposure ends ({end} µs) before it starts ({start} µs)"),
                ))
            } else {
                Ok(ExposureWindow { start, end })
            }
        })
        .collect()
}

/// The raw windows of `dir` as a [`crate::TimeSummary`] (convention µs), for unit detection.
pub fn exposure_summary(dir: &Path) -> Result<crate::TimeSummary, EventError> {
    let (starts, ends, _) = read_raw(dir)?;
    let w: Vec<(f64, f64)> = starts.into_iter().zip(ends).collect();
    Ok(crate::TimeSummary::of_windows(
        dir.join("exposure_start_ts.txt").display().to_string(),
        &w,
        TimeUnit::Microseconds,
    ))
}

fn read_raw(dir: &Path) -> Result<(Vec<f64>, Vec<f64>, std::path::PathBuf), EventError> {
    let starts = read_column(&dir.join("exposure_start_ts.txt"))?;
    let end_path = dir.join("exposure_end_ts.txt");
    let ends = read_column(&end_path)?;
    Ok((starts, ends, end_path))
}

fn read_column(path: &Path) -> Result<Vec<f64>, EventError> {
    let text = std::fs::read_to_string(path).map_err(|e| EventError::io(path, e))?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let v: f64 = line.parse().map_err(|_| {
            EventError::format(path, format!("line {}: '{line}' is not a number", i + 1))
        })?;
        if !v.is_finite() {
            return Err(EventError::format(
                path,
                format!("line {}: '{line}' is not a finite time", i + 1),
            ));
        }
        out.push(v);
    }
    Ok(out)
}
