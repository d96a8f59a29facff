//! Event-camera streams for gems: one columnar type, readers/writers for the common file formats,
//! and an ESIM-style simulator that turns timestamped sharp frames into events.
//!
//! # Data model
//! [`EventStream`] holds time-sorted events column-wise: `t: i64` **microseconds**, `x`/`y: u16`
//! pixel column/row, `p: i8` polarity ±1, plus the sensor `width × height`. [`EventStream::window`]
//! returns a borrowed [`EventSlice`] of the events in `[t0, t1]` by binary search (no copy).
//! [`BinCounts`] is the signed per-bin count tensor `[views, bins, H, W]` used by E2NeRF/GeMS-E.
//!
//! # Files
//! - [`read_events`] dispatches on the extension: `.txt`/`.csv` ECD/v2e text, `.npy`/`.npz`,
//!   `.aedat4` (events only; [`read_aedat4`] also returns the APS frames with their exposure times),
//!   and `.h5`/`.hdf5` with the cargo feature `hdf5` (`read_events_hdf5`; needs the system HDF5
//!   library, e.g. Debian's `libhdf5-dev`). Without the feature, HDF5 files get an error that
//!   shows a one-line h5py → npz conversion.
//! - [`write_events_npz`] / [`write_events_text`] write atomically (temp file + rename).
//! - [`read_exposure_windows`] reads `exposure_start_ts.txt`/`exposure_end_ts.txt`.
//! - [`detect_units`] tells the time unit (s, ms, µs, ns) of event, exposure and frame-timestamp
//!   files from their values and from each other ([`event_time_summary`], [`exposure_summary`]).
//! - [`read_bin_counts`] / [`write_bin_counts`] handle count tensors as `.npy`.
//!
//! # Simulation
//! [`Simulator`] (`new(config, width, height)`, then `feed_luma`/`feed_rgb` per frame, `finish`)
//! follows ESIM; [`simulate_folder`] runs it over a folder of timestamped frames.

mod aedat;
mod exposure;
mod folder;
#[cfg(feature = "hdf5")]
mod hdf5;
mod npy;
mod read;
mod sim;
mod stream;
mod text;
mod units;

use std::path::PathBuf;

#[cfg(feature = "hdf5")]
pub use self::hdf5::read_events_hdf5;
pub use aedat::{AedatFrame, AedatRecording, read_aedat4};
pub use exposure::{ExposureWindow, exposure_summary, read_exposure_windows};
pub use folder::{FrameEncoding, list_frames, read_luminance, simulate_folder};
pub use npy::{read_bin_counts, read_events_npy, write_bin_counts, write_events_npz};
pub use read::{ReadOptions, TimeUnit, read_events};
pub use sim::{SimConfig, Simulator, luminance};
pub use stream::{BinCounts, EventSlice, EventStream};
pub use text::{read_events_text, write_events_text};
pub use units::{SeriesKind, TimeSummary, detect_units, event_time_summary};

/// Everything that can go wrong reading, writing or simulating events. File errors name the file.
#[derive(Debug, thiserror::Error)]
pub enum EventError {
    /// The operating system refused a read or write.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file's contents are not what its format requires.
    #[error("{path}: {msg}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong, with the position where known.
        msg: String,
    },
    /// In-memory data violates an invariant (lengths, ranges, ordering, parameters).
    #[error("invalid event data: {0}")]
    Invalid(String),
}

impl EventError {
    pub(crate) fn io(path: &std::path::Path, source: std::io::Error) -> Self {
        EventError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
    pub(crate) fn format(path: &std::path::Path, msg: impl Into<String>) -> Self {
        EventError::Format {
            path: path.to_path_buf(),
            msg: msg.into(),
        }
    }
}

/// A failed atomic write (gems-fs) is an I/O error on the path it names.
impl From<gems_fs::FsError> for EventError {
    fn from(e: gems_fs::FsError) -> Self {
        EventError::Io {
            path: e.path,
            source: e.source,
        }
    }
}
