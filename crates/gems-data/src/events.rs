//! Finding a scene's event data. Reading and slicing events is `gems_events`' job; this module
//! only locates the files by the dataset conventions (E2NeRF `iCVTEAM/E2NeRF`, BeNeRF's
//! repackaging with `exposure_start_ts.txt`/`exposure_end_ts.txt`, PRISM3D-E
//! `GopiRajuMatta/PRISM3D`'s `events_bins_<k>.pt`) so the scene can say what it holds, and
//! resolves the unit of their times ([`resolve_time_units`]).

use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::error::{DataError, Result};

/// Event data found in a scene folder.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct EventFiles {
    /// The raw event stream file, if any: `events.{npz,npy,txt,aedat4,h5,hdf5,pt}` in the scene
    /// root or in `events/` (first match in that order).
    pub stream: Option<PathBuf>,
    /// A per-view signed bin-count tensor `[views, bins, H, W]`, if any: `events_bins_<k>.npy`
    /// (gems / converted) or `events_bins_<k>.pt` / `events.pt` (PRISM3D-E / E2NeRF, torch).
    pub bin_counts: Option<PathBuf>,
    /// Folder holding `exposure_start_ts.txt` and `exposure_end_ts.txt`, if present.
    pub exposure_dir: Option<PathBuf>,
    /// Unit of the stream's time column, as resolved when the scene was opened
    /// ([`resolve_time_units`]; `None`: the reader's format convention, for HDF5/torch files).
    #[serde(skip)]
    pub stream_unit: Option<gems_events::TimeUnit>,
}

impl EventFiles {
    /// Reader options for the stream: its resolved unit, the sensor `size` when known.
    pub fn read_options(&self, size: Option<(u16, u16)>) -> gems_events::ReadOptions {
        match self.stream_unit {
            Some(u) => gems_events::ReadOptions::in_unit(size, u),
            None => gems_events::ReadOptions {
                size,
                ..Default::default()
            },
        }
    }
}

/// The units of a scene's time files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TimeUnits {
    /// The event stream's (`None`: no stream, or a format read by its own convention).
    pub stream: Option<gems_events::TimeUnit>,
    /// The exposure files' (`None`: no exposure files).
    pub exposure: Option<gems_events::TimeUnit>,
}

/// The units of the scene's event stream and exposure files, by the one rule of
/// [`gems_events::detect_units`]: from their values and from each other (exposure windows must
/// fall inside the stream). `given` (the `--time-unit` option) sets every unit that the file
/// format does not fix. An ambiguous scene is an error naming both files' ranges.
pub fn resolve_time_units(
    files: &EventFiles,
    given: Option<gems_events::TimeUnit>,
) -> Result<TimeUnits> {
    let mut series = Vec::new();
    let mut stream_at = None;
    if let Some(p) = &files.stream
        && let Some(s) = gems_events::event_time_summary(p).map_err(DataError::Events)?
    {
        stream_at = Some(series.len());
        series.push(s);
    }
    let mut exposure_at = None;
    if let Some(d) = &files.exposure_dir {
        exposure_at = Some(series.len());
        series.push(gems_events::exposure_summary(d).map_err(DataError::Events)?);
    }
    if let Some(u) = given {
        for s in &mut series {
            s.fixed.get_or_insert(u);
        }
    }
    if series.is_empty() {
        return Ok(TimeUnits::default());
    }
    let units = gems_events::detect_units(&series).map_err(|msg| DataError::Format {
        path: files
            .exposure_dir
            .clone()
            .or_else(|| files.stream.clone())
            .unwrap_or_default(),
        source: crate::error::FormatError(msg),
    })?;
    Ok(TimeUnits {
        stream: stream_at.map(|i| units[i]),
        exposure: exposure_at.map(|i| units[i]),
    })
}

impl EventFiles {
    /// True when nothing event-related was found.
    pub fn is_empty(&self) -> bool {
        self.stream.is_none() && self.bin_counts.is_none() && self.exposure_dir.is_none()
    }
}

/// Stream extensions in order of preference.
const STREAM_EXTS: [&str; 7] = ["npz", "npy", "txt", "aedat4", "h5", "hdf5", "pt"];

/// Looks for event files in `root` and `root/events/`.
pub fn find_event_files(root: &Path) -> EventFiles {
    let dirs = [root.to_path_buf(), root.join("events")];
    let stream = dirs.iter().find_map(|d| {
        STREAM_EXTS
            .iter()
            .map(|e| d.join(format!("events.{e}")))
            .find(|p| p.is_file())
    });
    // E2NeRF stores the binned tensor as events.pt; BeNeRF stores a raw N×4 list under the same
    // name in events/. Only the root-level one is taken as bins.
    let stream =
        stream.filter(|p| !(p.extension().is_some_and(|e| e == "pt") && p.parent() == Some(root)));
    let mut bin_counts = None;
    for d in &dirs {
        if let Ok(rd) = std::fs::read_dir(d) {
            let mut found: Vec<PathBuf> = rd
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    p.file_name().and_then(|n| n.to_str()).is_some_and(|n| {
                        n.starts_with("events_bins_") && (n.ends_with(".npy") || n.ends_with(".pt"))
                    })
                })
                .collect();
            found.sort();
            // Prefer the .npy conversion over the torch original.
            found.sort_by_key(|p| p.extension().is_some_and(|e| e == "pt"));
            if let Some(p) = found.into_iter().next() {
                bin_counts = Some(p);
                break;
            }
        }
    }
    if bin_counts.is_none() && root.join("events.pt").is_file() {
        bin_counts = Some(root.join("events.pt"));
    }
    let exposure_dir = dirs.into_iter().find(|d| {
        d.join("exposure_start_ts.txt").is_file() && d.join("exposure_end_ts.txt").is_file()
    });
    EventFiles {
        stream,
        bin_counts,
        exposure_dir,
        stream_unit: None,
    }
}

/// The one-line conversion of a torch count tensor (`events_bins_<k>.pt`, E2NeRF `events.pt`)
/// to the `.npy` gems reads, printed by `gems info` when only the `.pt` file exists.
pub const PT_TO_NPY_HINT: &str = "python -c \"import torch,numpy,sys; numpy.save(sys.argv[2], torch.load(sys.argv[1]).numpy())\" IN.pt OUT.npy";
