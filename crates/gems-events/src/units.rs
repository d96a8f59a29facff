//! One rule for the unit of every time file: event streams, exposure windows and frame
//! timestamps may hold seconds, milliseconds, microseconds or nanoseconds, and none of these
//! formats says which.
//!
//! # The rule ([`detect_units`])
//! Each file is summarised by its raw values ([`TimeSummary`]); every unit is tried for every file
//! whose unit is not fixed by its format (AEDAT4 is µs) or by the caller, and a combination is
//! kept when
//! - each file is plausible on its own, in µs after conversion:
//!   - an absolute time (a Unix epoch between 2001 and 2096) pins the unit it reads as;
//!   - event streams span 100 µs to 12 days, and whole-number values are not seconds;
//!   - exposure windows last 1 ms to 10 s (median of the non-empty ones: motion blur needs a
//!     long exposure, sharp frames with start = end are skipped);
//!   - frame timestamps are 10 µs to 10 s apart (median step);
//! - and the files agree: the exposure windows lie at least half inside the event stream's span.
//!
//! One surviving combination is the answer. Several: the one that keeps the most files at their
//! format's convention (float event times in s, integer ones in µs, exposure files in µs, as in
//! E2NeRF/BeNeRF) wins when it is unique. Otherwise, or when none survives, the error names every
//! file's raw range and the candidates, and asks for `--time-unit`.

use std::path::Path;

use crate::{EventError, TimeUnit};

/// What a time file holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SeriesKind {
    /// Event timestamps.
    Events,
    /// Exposure start/end times (median duration in [`TimeSummary::step`]).
    Exposures,
    /// Frame timestamps (median step in [`TimeSummary::step`]).
    Frames,
}

/// The raw values of one time file, before any unit is applied.
#[derive(Debug, Clone, PartialEq)]
pub struct TimeSummary {
    /// File name, for messages.
    pub label: String,
    /// What the file holds.
    pub kind: SeriesKind,
    /// Smallest and largest raw value.
    pub min: f64,
    /// Largest raw value.
    pub max: f64,
    /// Number of values.
    pub count: usize,
    /// Whether every value is a whole number.
    pub whole: bool,
    /// Exposures: median non-zero duration; frames: median step (raw units; 0 when none).
    pub step: f64,
    /// The unit the file's format conventionally uses.
    pub convention: TimeUnit,
    /// The unit fixed by the format or the caller (no detection).
    pub fixed: Option<TimeUnit>,
}

impl TimeSummary {
    /// Summary of event times (or any plain time column).
    pub fn of_values(
        label: impl Into<String>,
        kind: SeriesKind,
        values: &[f64],
        convention: TimeUnit,
    ) -> TimeSummary {
        let min = values.iter().copied().fold(f64::INFINITY, f64::min);
        let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let mut steps: Vec<f64> = values
            .windows(2)
            .map(|w| w[1] - w[0])
            .filter(|d| *d > 0.0)
            .collect();
        TimeSummary {
            label: label.into(),
            kind,
            min,
            max,
            count: values.len(),
            whole: values.iter().all(|v| v.fract() == 0.0),
            step: median(&mut steps),
            convention,
            fixed: None,
        }
    }

    /// Summary of exposure windows given as raw `(start, end)` pairs.
    pub fn of_windows(
        label: impl Into<String>,
        windows: &[(f64, f64)],
        convention: TimeUnit,
    ) -> TimeSummary {
        let all: Vec<f64> = windows.iter().flat_map(|&(a, b)| [a, b]).collect();
        let mut s = TimeSummary::of_values(label, SeriesKind::Exposures, &all, convention);
        let mut d: Vec<f64> = windows
            .iter()
            .map(|&(a, b)| b - a)
            .filter(|d| *d > 0.0)
            .collect();
        s.step = median(&mut d);
        s
    }

    fn range_text(&self) -> String {
        format!("{} holds {} .. {}", self.label, self.min, self.max)
    }
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

const UNITS: [TimeUnit; 4] = [
    TimeUnit::Seconds,
    TimeUnit::Milliseconds,
    TimeUnit::Microseconds,
    TimeUnit::Nanoseconds,
];

/// µs per raw unit.
fn scale(u: TimeUnit) -> f64 {
    10f64.powi(u.us_exponent())
}

/// Whether `s` read in `u` is plausible on its own (see the module docs).
fn plausible(s: &TimeSummary, u: TimeUnit) -> bool {
    let k = scale(u);
    // A Unix time (2001..2096) reads as one unit only; values that are one pin that unit.
    let unix = |w: TimeUnit| (1.0e9..4.0e9).contains(&(s.min * scale(w) * 1e-6));
    if let Some(w) = UNITS.iter().copied().find(|&w| unix(w)) {
        return w == u;
    }
    match s.kind {
        SeriesKind::Events => {
            let span = (s.max - s.min) * k;
            let span_ok = s.count < 2 || (100.0..=1.0e12).contains(&span);
            span_ok && !(s.whole && s.count >= 2 && u == TimeUnit::Seconds)
        }
        SeriesKind::Exposures => s.step == 0.0 || (1.0e3..=1.0e7).contains(&(s.step * k)),
        SeriesKind::Frames => s.step == 0.0 || (10.0..=1.0e7).contains(&(s.step * k)),
    }
}

/// Whether the exposure windows `x` (in `ux`) lie at least half inside the events `e` (in `ue`).
fn consistent(e: &TimeSummary, ue: TimeUnit, x: &TimeSummary, ux: TimeUnit) -> bool {
    let (e0, e1) = (e.min * scale(ue), e.max * scale(ue));
    let (x0, x1) = (x.min * scale(ux), x.max * scale(ux));
    let overlap = (x1.min(e1) - x0.max(e0)).max(0.0);
    if x1 > x0 {
        overlap >= 0.5 * (x1 - x0)
    } else {
        (e0..=e1).contains(&x0)
    }
}

/// The unit of each series (same order), by the rule in the module docs. `Err` is the message:
/// every file's raw range, the candidates, and the `--time-unit` option.
pub fn detect_units(series: &[TimeSummary]) -> Result<Vec<TimeUnit>, String> {
    let choices: Vec<Vec<TimeUnit>> = series
        .iter()
        .map(|s| match s.fixed {
            Some(u) => vec![u],
            None => UNITS.iter().copied().filter(|&u| plausible(s, u)).collect(),
        })
        .collect();
    let mut survivors: Vec<Vec<TimeUnit>> = vec![vec![]];
    for c in &choices {
        survivors = survivors
            .into_iter()
            .flat_map(|prefix| {
                c.iter().map(move |&u| {
                    let mut p = prefix.clone();
                    p.push(u);
                    p
                })
            })
            .collect();
    }
    survivors.retain(|combo| {
        series.iter().zip(combo).all(|(e, &ue)| {
            e.kind != SeriesKind::Events
                || series
                    .iter()
                    .zip(combo)
                    .all(|(x, &ux)| x.kind != SeriesKind::Exposures || consistent(e, ue, x, ux))
        })
    });
    let ranges = series
        .iter()
        .map(TimeSummary::range_text)
        .collect::<Vec<_>>()
        .join("; ");
    let hint = "pass --time-unit s|ms|us|ns to say which";
    match survivors.len() {
        0 => Err(format!(
            "the time unit cannot be told: no unit makes these files plausible together ({ranges}); {hint}"
        )),
        1 => Ok(survivors.pop().expect("one survivor")),
        _ => {
            let score = |c: &Vec<TimeUnit>| {
                series
                    .iter()
                    .zip(c)
                    .filter(|(s, u)| s.convention == **u)
                    .count()
            };
            let best = survivors.iter().map(score).max().expect("non-empty");
            let top: Vec<&Vec<TimeUnit>> = survivors.iter().filter(|c| score(c) == best).collect();
            if let [one] = top.as_slice() {
                return Ok((*one).clone());
            }
            let cands = top
                .iter()
                .map(|c| {
                    series
                        .iter()
                        .zip(c.iter())
                        .map(|(s, u)| format!("{} {}..{} {}", s.label, s.min, s.max, u.symbol()))
                        .collect::<Vec<_>>()
                        .join(" with ")
                })
                .collect::<Vec<_>>()
                .join(", or ");
            Err(format!(
                "the time unit is ambiguous: {ranges}; it reads as {cands}; {hint}"
            ))
        }
    }
}

/// The raw time summary of an event file, for [`detect_units`]: `.npz`/`.npy`/`.txt`/`.csv`/`.dat`
/// read raw (convention: float s, integer µs; text s), `.aedat4` fixed to µs by its format.
/// `None` for formats read elsewhere (HDF5, torch), which keep their reader's convention.
pub fn event_time_summary(path: &Path) -> Result<Option<TimeSummary>, EventError> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let label = path.display().to_string();
    let summary = match ext.as_str() {
        "npz" | "npy" => {
            let (t, int) = crate::npy::read_raw_times(path)?;
            let conv = if int {
                TimeUnit::Microseconds
            } else {
                TimeUnit::Seconds
            };
            TimeSummary::of_values(label, SeriesKind::Events, &t, conv)
        }
        "txt" | "csv" | "dat" => {
            let t = crate::text::read_raw_times(path)?;
            TimeSummary::of_values(label, SeriesKind::Events, &t, TimeUnit::Seconds)
        }
        "aedat4" => {
            let rec = crate::read_aedat4(path)?;
            let t: Vec<f64> = rec.events.t().iter().map(|&v| v as f64).collect();
            let mut s =
                TimeSummary::of_values(label, SeriesKind::Events, &t, TimeUnit::Microseconds);
            s.fixed = Some(TimeUnit::Microseconds);
            s
        }
        _ => return Ok(None),
    };
    Ok(Some(summary))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn events(v: &[f64]) -> TimeSummary {
        let conv = if v.iter().all(|a| a.fract() == 0.0) {
            TimeUnit::Microseconds
        } else {
            TimeUnit::Seconds
        };
        TimeSummary::of_values("events.npz", SeriesKind::Events, v, conv)
    }

    fn windows(w: &[(f64, f64)]) -> TimeSummary {
        TimeSummary::of_windows("exposure_start_ts.txt", w, TimeUnit::Microseconds)
    }

    #[test]
    fn seconds_everywhere_are_seconds() {
        let ev: Vec<f64> = (0..1000).map(|i| i as f64 * 0.001 + 0.0005).collect();
        let x = windows(&[(0.1, 0.2), (0.4, 0.5), (0.7, 0.8)]);
        assert_eq!(
            detect_units(&[events(&ev), x]).unwrap(),
            [TimeUnit::Seconds, TimeUnit::Seconds]
        );
    }

    #[test]
    fn microsecond_integers_stay_microseconds() {
        let ev: Vec<f64> = (0..1000).map(|i| (i * 1000) as f64).collect();
        let x = windows(&[(100_000.0, 200_000.0), (400_000.0, 500_000.0)]);
        assert_eq!(
            detect_units(&[events(&ev), x]).unwrap(),
            [TimeUnit::Microseconds, TimeUnit::Microseconds]
        );
    }

    #[test]
    fn exposures_follow_the_events_they_must_overlap() {
        // Events in µs, exposure windows in ms: only ms puts the windows inside the stream.
        let ev: Vec<f64> = (0..1000).map(|i| (i * 1000) as f64).collect();
        let x = windows(&[(100.0, 200.0), (400.0, 500.0)]);
        assert_eq!(
            detect_units(&[events(&ev), x]).unwrap(),
            [TimeUnit::Microseconds, TimeUnit::Milliseconds]
        );
    }

    #[test]
    fn unix_times_pin_their_unit() {
        let ns: Vec<f64> = (0..10).map(|i| 1.7e18 + i as f64 * 1e6).collect();
        assert_eq!(
            detect_units(&[events(&ns)]).unwrap(),
            [TimeUnit::Nanoseconds]
        );
    }

    #[test]
    fn ambiguous_names_both_ranges_and_the_option() {
        // 5-unit exposures alone: 5 ms or 5 s, neither the µs convention.
        let x = windows(&[(0.0, 5.0), (10.0, 15.0)]);
        let e = detect_units(&[x]).unwrap_err();
        assert!(
            e.contains("ambiguous")
                && e.contains("0 .. 15")
                && e.contains("15 s")
                && e.contains("15 ms")
                && e.contains("--time-unit"),
            "{e}"
        );
    }

    #[test]
    fn fixed_units_are_kept() {
        let mut x = windows(&[(0.0, 5.0), (10.0, 15.0)]);
        x.fixed = Some(TimeUnit::Seconds);
        assert_eq!(detect_units(&[x]).unwrap(), [TimeUnit::Seconds]);
    }
}
