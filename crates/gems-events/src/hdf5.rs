//! HDF5 event files (cargo feature `hdf5`, needs the system HDF5 library).
//!
//! Layouts found in the wild (per the loaders of `uzh-rpg/EvDeblurNeRF`, `uzh-rpg/DSEC`,
//! `WU-CVGL/BeNeRF` and `SensorsINI/v2e`):
//! - one 1-D dataset per column at the root (EvDeblurNeRF, LSENeRF: `x`, `y`, `t`, `p`) or in one
//!   group (DSEC, TUM-VIE: `/events/{x,y,t,p}`), with aliases `xs`/`ys`/`ts`/`ps`,
//!   `timestamp(s)`, `polarity`/`polarities`;
//! - v2e: one `events` dataset of shape N×4 with columns (t, x, y, p).
//!
//! Columns are read in their stored dtype (integers exactly); integer times use
//! `ReadOptions::int_time_unit`, float times `ReadOptions::float_time_unit`. Sensor size: the
//! caller's, else `width`/`height` scalar attributes of the events group or the root, else the event
//! bounding box. Compressed datasets need their HDF5 filter plugin (DSEC's blosc is not built in);
//! a missing filter is reported as an error naming the file and dataset.

use std::path::Path;

use hdf5::types::TypeDescriptor;

use crate::npy::{Column, time_column};
use crate::read::{ReadOptions, build_stream};
use crate::{EventError, EventStream};

const X_NAMES: &[&str] = &["x", "xs"];
const Y_NAMES: &[&str] = &["y", "ys"];
const T_NAMES: &[&str] = &["t", "ts", "timestamp", "timestamps"];
const P_NAMES: &[&str] = &["p", "ps", "polarity", "polarities"];

/// Reads an HDF5 event file (layouts above) into a time-sorted [`EventStream`].
pub fn read_events_hdf5(path: &Path, opts: &ReadOptions) -> Result<EventStream, EventError> {
    // A missing or unreadable file is an I/O error, not "not HDF5".
    std::fs::metadata(path).map_err(|e| EventError::io(path, e))?;
    let file = hdf5::File::open(path)
        .map_err(|e| EventError::format(path, format!("not a readable HDF5 file: {e}")))?;
    let fmt = |msg: String| EventError::format(path, msg);

    let group = find_event_group(&file).map_err(|e| fmt(e.to_string()))?;
    let (group, prefix) = match group {
        Some(g) => g,
        None => {
            // v2e: a single N×4 `events` dataset (t, x, y, p).
            if let Ok(ds) = file.dataset("events") {
                return read_v2e(path, opts, &ds, &file);
            }
            let members = file.member_names().unwrap_or_default();
            return Err(fmt(format!(
                "no event datasets found: expected x, y, t, p (or xs, ys, ts, ps) at the root or \
                 in one group, or an N×4 'events' dataset; the root holds {members:?}"
            )));
        }
    };

    let column = |names: &[&str], what: &str| -> Result<Column, EventError> {
        let name = names.iter().find(|n| group.link_exists(n)).ok_or_else(|| {
            fmt(format!(
                "missing dataset {prefix}{} ({what})",
                names.join(&format!(" / {prefix}"))
            ))
        })?;
        let ds = group
            .dataset(name)
            .map_err(|e| fmt(format!("'{prefix}{name}' is not a dataset: {e}")))?;
        let shape = ds.shape();
        if shape.len() != 1 {
            return Err(fmt(format!(
                "dataset '{prefix}{name}' must be 1-D, has shape {shape:?}"
            )));
        }
        read_column(&ds).map_err(|m| fmt(format!("dataset '{prefix}{name}': {m}")))
    };
    let x = column(X_NAMES, "x")?;
    let y = column(Y_NAMES, "y")?;
    let t = column(T_NAMES, "t")?;
    let p = column(P_NAMES, "p")?;
    let t = time_column(t, opts, path)?;
    let mut opts = *opts;
    if opts.size.is_none() {
        opts.size = size_attrs(&group).or_else(|| size_attrs(&file));
    }
    build_stream(path, &opts, t, x, y, p)
}

/// The group holding the column datasets: the root if it has a time and an x dataset, else the
/// one first-level group that does (`events` preferred when several do). Returns the group and the
/// path prefix used in messages.
fn find_event_group(file: &hdf5::File) -> hdf5::Result<Option<(hdf5::Group, String)>> {
    let has_columns = |g: &hdf5::Group| {
        T_NAMES.iter().any(|n| g.link_exists(n)) && X_NAMES.iter().any(|n| g.link_exists(n))
    };
    let root = file.group("/")?;
    if has_columns(&root) {
        return Ok(Some((root, String::new())));
    }
    let mut found = Vec::new();
    for name in root.member_names()? {
        if let Ok(g) = root.group(&name)
            && has_columns(&g)
        {
            found.push((g, format!("{name}/")));
        }
    }
    if let Some(i) = found.iter().position(|(_, n)| n == "events/") {
        return Ok(Some(found.swap_remove(i)));
    }
    Ok(found.into_iter().next())
}

/// v2e's N×4 `events` dataset: columns t, x, y, p in one dtype.
fn read_v2e(
    path: &Path,
    opts: &ReadOptions,
    ds: &hdf5::Dataset,
    file: &hdf5::File,
) -> Result<EventStream, EventError> {
    let shape = ds.shape();
    if shape.len() != 2 || shape[1] != 4 {
        return Err(EventError::format(
            path,
            format!("dataset 'events' must be N×4 (t, x, y, p), has shape {shape:?}"),
        ));
    }
    let all =
        read_column(ds).map_err(|m| EventError::format(path, format!("dataset 'events': {m}")))?;
    let split = |j: usize| -> Column {
        match &all {
            Column::Int(v) => Column::Int(v.iter().skip(j).step_by(4).copied().collect()),
            Column::Float(v) => Column::Float(v.iter().skip(j).step_by(4).copied().collect()),
        }
    };
    let t = time_column(split(0), opts, path)?;
    let mut opts = *opts;
    if opts.size.is_none() {
        opts.size = size_attrs(file);
    }
    build_stream(path, &opts, t, split(1), split(2), split(3))
}

/// Reads a numeric dataset in its stored class: integers exactly as i64, floats as f64.
fn read_column(ds: &hdf5::Dataset) -> Result<Column, String> {
    let desc = ds
        .dtype()
        .and_then(|d| d.to_descriptor())
        .map_err(|e| format!("unsupported element type: {e}"))?;
    let err = |e: hdf5::Error| format!("cannot read: {e}");
    match desc {
        TypeDescriptor::Integer(_) | TypeDescriptor::Boolean => {
            Ok(Column::Int(ds.read_raw::<i64>().map_err(err)?))
        }
        TypeDescriptor::Unsigned(_) => ds
            .read_raw::<u64>()
            .map_err(err)?
            .into_iter()
            .map(|v| i64::try_from(v).map_err(|_| format!("value {v} does not fit in i64")))
            .collect::<Result<Vec<_>, _>>()
            .map(Column::Int),
        TypeDescriptor::Float(_) => Ok(Column::Float(ds.read_raw::<f64>().map_err(err)?)),
        other => Err(format!("element type {other} is not numeric")),
    }
}

/// `width`/`height` integer scalar attributes of a group, when both are present and fit u16.
fn size_attrs(g: &hdf5::Group) -> Option<(u16, u16)> {
    let get = |name: &str| -> Option<u16> {
        let a = g.attr(name).ok()?;
        let v: i64 = match a.dtype().ok()?.to_descriptor().ok()? {
            TypeDescriptor::Integer(_) | TypeDescriptor::Unsigned(_) => a.read_raw::<i64>().ok()?,
            _ => return None,
        }
        .into_iter()
        .next()
        .filter(|_| a.size() == 1)?;
        u16::try_from(v).ok().filter(|&v| v > 0)
    };
    Some((get("width")?, get("height")?))
}
