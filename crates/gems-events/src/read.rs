//! Format dispatch and the options shared by all readers.

use std::path::Path;

use crate::npy::Column;
use crate::{EventError, EventStream};

/// Unit of timestamps stored in a file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimeUnit {
    /// Seconds.
    Seconds,
    /// Milliseconds.
    Milliseconds,
    /// Microseconds.
    Microseconds,
    /// Nanoseconds.
    Nanoseconds,
}

impl TimeUnit {
    /// The unit's symbol: `s`, `ms`, `us`, `ns`.
    pub fn symbol(self) -> &'static str {
        match self {
            TimeUnit::Seconds => "s",
            TimeUnit::Milliseconds => "ms",
            TimeUnit::Microseconds => "us",
            TimeUnit::Nanoseconds => "ns",
        }
    }

    /// `(mul, div)` such that µs = value·mul/div.
    pub(crate) fn us_ratio(self) -> (i64, i64) {
        match self {
            TimeUnit::Seconds => (1_000_000, 1),
            TimeUnit::Milliseconds => (1_000, 1),
            TimeUnit::Microseconds => (1, 1),
            TimeUnit::Nanoseconds => (1, 1_000),
        }
    }
    /// Power of ten taking this unit to µs (6 for seconds, −3 for ns).
    pub(crate) fn us_exponent(self) -> i32 {
        match self {
            TimeUnit::Seconds => 6,
            TimeUnit::Milliseconds => 3,
            TimeUnit::Microseconds => 0,
            TimeUnit::Nanoseconds => -3,
        }
    }
}

impl std::fmt::Display for TimeUnit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.symbol())
    }
}

impl std::str::FromStr for TimeUnit {
    type Err = String;
    /// Parses `s`, `ms`, `us` (or `µs`) and `ns`.
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "s" => Ok(TimeUnit::Seconds),
            "ms" => Ok(TimeUnit::Milliseconds),
            "us" | "µs" => Ok(TimeUnit::Microseconds),
            "ns" => Ok(TimeUnit::Nanoseconds),
            other => Err(format!(
                "unknown time unit {other:?} (expected s, ms, us or ns)"
            )),
        }
    }
}

/// How to interpret files whose format leaves things open.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReadOptions {
    /// Sensor `(width, height)`. `None`: taken from the file when it stores it (AEDAT4, our npz and
    /// text writers), else the bounding box of the events (`max + 1`).
    pub size: Option<(u16, u16)>,
    /// Unit of the time column of text files (ECD and v2e: seconds).
    pub text_time_unit: TimeUnit,
    /// Unit of integer time arrays in npy/npz (DAVIS/DSEC convention: µs; rpg_vid2e writes ns).
    pub int_time_unit: TimeUnit,
    /// Unit of floating-point time arrays in npy/npz (seconds, as in tub-rip's `events.npy`).
    pub float_time_unit: TimeUnit,
}

impl ReadOptions {
    /// Options reading every time column of any format in `unit`.
    pub fn in_unit(size: Option<(u16, u16)>, unit: TimeUnit) -> ReadOptions {
        ReadOptions {
            size,
            text_time_unit: unit,
            int_time_unit: unit,
            float_time_unit: unit,
        }
    }
}

impl Default for ReadOptions {
    fn default() -> Self {
        Self {
            size: None,
            text_time_unit: TimeUnit::Seconds,
            int_time_unit: TimeUnit::Microseconds,
            float_time_unit: TimeUnit::Seconds,
        }
    }
}

/// Reads an event file, choosing the format from the extension: `.txt`/`.csv`/`.dat` (ECD/v2e
/// text), `.npy`/`.npz`, `.aedat4`, and `.h5`/`.hdf5` when built with the `hdf5` feature (without it,
/// the error shows a one-line h5py → npz conversion). The result is time-sorted (stably, when the file is not).
pub fn read_events(path: &Path, opts: &ReadOptions) -> Result<EventStream, EventError> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "txt" | "csv" | "dat" => crate::read_events_text(path, opts),
        "npy" | "npz" => crate::read_events_npy(path, opts),
        "aedat4" => {
            let rec = crate::read_aedat4(path)?;
            match opts.size {
                Some((w, h)) if (w, h) != (rec.events.width(), rec.events.height()) => {
                    Err(EventError::format(
                        path,
                        format!(
                            "file is {}×{}, caller expected {w}×{h}",
                            rec.events.width(),
                            rec.events.height()
                        ),
                    ))
                }
                _ => Ok(rec.events),
            }
        }
        #[cfg(feature = "hdf5")]
        "h5" | "hdf5" => crate::read_events_hdf5(path, opts),
        #[cfg(not(feature = "hdf5"))]
        "h5" | "hdf5" => Err(EventError::format(
            path,
            "HDF5 event files are not supported by this build; convert once with \
             `python -c \"import h5py,numpy as n,sys; f=h5py.File(sys.argv[1]); n.savez(sys.argv[2], **{k: f[k][:] for k in 'xytp'})\" events.h5 events.npz`",
        )),
        _ => Err(EventError::format(
            path,
            "unknown event file type (expected .txt, .csv, .npy, .npz, .aedat4 or .h5)",
        )),
    }
}

/// Validates coordinate/polarity columns and assembles a stream (shared by npy/npz).
pub(crate) fn build_stream(
    path: &Path,
    opts: &ReadOptions,
    t: Vec<i64>,
    x: Column,
    y: Column,
    p: Column,
) -> Result<EventStream, EventError> {
    let n = t.len();
    if x.len() != n || y.len() != n || p.len() != n {
        return Err(EventError::format(
            path,
            format!(
                "arrays differ in length: t {n}, x {}, y {}, p {}",
                x.len(),
                y.len(),
                p.len()
            ),
        ));
    }
    let bad = |i: usize, what: &str, v: String| {
        EventError::format(
            path,
            format!("event {i}: {what} = {v} is not a pixel index"),
        )
    };
    let coord = |c: Column, what: &str| -> Result<Vec<u16>, EventError> {
        match c {
            Column::Int(v) => v
                .iter()
                .enumerate()
                .map(|(i, &a)| {
                    u16::try_from(a)
                        .ok()
                        .filter(|&a| a < u16::MAX)
                        .ok_or_else(|| bad(i, what, a.to_string()))
                })
                .collect(),
            Column::Float(v) => v
                .iter()
                .enumerate()
                .map(|(i, &a)| {
                    if a >= 0.0 && a <= f64::from(u16::MAX - 1) && a.fract() == 0.0 {
                        Ok(a as u16)
                    } else {
                        Err(bad(i, what, a.to_string()))
                    }
                })
                .collect(),
        }
    };
    let (xs, ys) = (coord(x, "x")?, coord(y, "y")?);
    let pol = |i: usize, a: f64| match a {
        1.0 => Ok(1),
        0.0 | -1.0 => Ok(-1),
        v => Err(EventError::format(
            path,
            format!("event {i}: polarity {v} is not 0/1 or ±1"),
        )),
    };
    let ps = match p {
        Column::Int(v) => v
            .iter()
            .enumerate()
            .map(|(i, &a)| pol(i, a as f64))
            .collect::<Result<Vec<i8>, _>>()?,
        Column::Float(v) => v
            .iter()
            .enumerate()
            .map(|(i, &a)| pol(i, a))
            .collect::<Result<Vec<i8>, _>>()?,
    };
    let (w, h) = resolve_size(path, opts.size, &xs, &ys)?;
    EventStream::from_columns(w, h, t, xs, ys, ps)
        .map_err(|e| EventError::format(path, e.to_string()))
}

/// The sensor size: the caller's, else the event bounding box.
pub(crate) fn resolve_size(
    path: &Path,
    size: Option<(u16, u16)>,
    xs: &[u16],
    ys: &[u16],
) -> Result<(u16, u16), EventError> {
    if let Some(s) = size {
        return Ok(s);
    }
    let w = xs.iter().max().map_or(0, |&m| m + 1);
    let h = ys.iter().max().map_or(0, |&m| m + 1);
    if xs.is_empty() {
        return Err(EventError::format(
            path,
            "no events and no sensor size given",
        ));
    }
    Ok((w, h))
}
