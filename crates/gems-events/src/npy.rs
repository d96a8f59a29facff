//! NumPy `.npy`/`.npz` events and count tensors.
//!
//! Events: an `.npz` with 1-D arrays `t`, `x`, `y`, `p` (any integer/float/bool dtypes; what
//! rpg_vid2e, EvDeblurNeRF conversions and our own writer use), or an `.npy` N×4 array. For N×4 the
//! time column is column 0 (`t x y p`, ECD/tub-rip) unless column 0 is not sorted and column 2 is
//! (`x y t p`, BeNeRF's `events.pt` layout). Polarity 0 is read as OFF.
//!
//! Count tensors: `.npy` of shape `[views, bins, H, W]` (or `[views, bins, H·W]` with the size
//! given). E2NeRF/PRISM3D store this tensor with `torch.save`; convert once with
//! `python -c "import torch,numpy as n,sys; n.save(sys.argv[2], torch.load(sys.argv[1]).numpy())" events.pt events.npy`.

use std::io::{Read, Seek};
use std::path::Path;

use npyz::WriterBuilder;
use npyz::npz::NpzArchive;
use npyz::{NpyFile, TypeChar};

use crate::read::{ReadOptions, TimeUnit, build_stream};
use crate::{BinCounts, EventError, EventStream};

/// A numeric column read from any plain dtype, kept exact for integers.
pub(crate) enum Column {
    Int(Vec<i64>),
    Float(Vec<f64>),
}

impl Column {
    pub(crate) fn len(&self) -> usize {
        match self {
            Column::Int(v) => v.len(),
            Column::Float(v) => v.len(),
        }
    }
    fn as_f64(&self) -> Vec<f64> {
        match self {
            Column::Int(v) => v.iter().map(|&a| a as f64).collect(),
            Column::Float(v) => v.clone(),
        }
    }
}

fn read_column<R: Read>(
    npy: NpyFile<R>,
    path: &Path,
    name: &str,
) -> Result<(Vec<u64>, Column), EventError> {
    let shape = npy.shape().to_vec();
    let dtype = npy.dtype();
    let npyz::DType::Plain(ts) = dtype.clone() else {
        return Err(EventError::format(
            path,
            format!("array '{name}': unsupported dtype {}", dtype.descr()),
        ));
    };
    let ioerr = |e: std::io::Error| EventError::format(path, format!("array '{name}': {e}"));
    let col = match (ts.type_char(), ts.size_field()) {
        (TypeChar::Bool, 1) => Column::Int(
            npy.into_vec::<bool>()
                .map_err(ioerr)?
                .into_iter()
                .map(i64::from)
                .collect(),
        ),
        (TypeChar::Int, 1) => Column::Int(
            npy.into_vec::<i8>()
                .map_err(ioerr)?
                .into_iter()
                .map(i64::from)
                .collect(),
        ),
        (TypeChar::Int, 2) => Column::Int(
            npy.into_vec::<i16>()
                .map_err(ioerr)?
                .into_iter()
                .map(i64::from)
                .collect(),
        ),
        (TypeChar::Int, 4) => Column::Int(
            npy.into_vec::<i32>()
                .map_err(ioerr)?
                .into_iter()
                .map(i64::from)
                .collect(),
        ),
        (TypeChar::Int, 8) => Column::Int(npy.into_vec::<i64>().map_err(ioerr)?),
        (TypeChar::Uint, 1) => Column::Int(
            npy.into_vec::<u8>()
                .map_err(ioerr)?
                .into_iter()
                .map(i64::from)
                .collect(),
        ),
        (TypeChar::Uint, 2) => Column::Int(
            npy.into_vec::<u16>()
                .map_err(ioerr)?
                .into_iter()
                .map(i64::from)
                .collect(),
        ),
        (TypeChar::Uint, 4) => Column::Int(
            npy.into_vec::<u32>()
                .map_err(ioerr)?
                .into_iter()
                .map(i64::from)
                .collect(),
        ),
        (TypeChar::Uint, 8) => {
            let v = npy.into_vec::<u64>().map_err(ioerr)?;
            let mut out = Vec::with_capacity(v.len());
            for a in v {
                out.push(i64::try_from(a).map_err(|_| {
                    EventError::format(
                        path,
                        format!("array '{name}': value {a} does not fit in i64"),
                    )
                })?);
            }
            Column::Int(out)
        }
        (TypeChar::Float, 4) => Column::Float(
            npy.into_vec::<f32>()
                .map_err(ioerr)?
                .into_iter()
                .map(f64::from)
                .collect(),
        ),
        (TypeChar::Float, 8) => Column::Float(npy.into_vec::<f64>().map_err(ioerr)?),
        _ => {
            return Err(EventError::format(
                path,
                format!("array '{name}': unsupported dtype {ts}"),
            ));
        }
    };
    let expect: u64 = shape.iter().product();
    if col.len() as u64 != expect {
        return Err(EventError::format(
            path,
            format!("array '{name}': data shorter than its shape {shape:?}"),
        ));
    }
    Ok((shape, col))
}

/// Decodes an in-memory `.npy` 1-D little-endian numeric array straight from its bytes (one
/// pass, no per-element reader calls); other layouts go through npyz's generic reader.
fn read_column_bytes(
    bytes: &[u8],
    path: &Path,
    name: &str,
) -> Result<(Vec<u64>, Column), EventError> {
    let npy = NpyFile::new(bytes)
        .map_err(|e| EventError::format(path, format!("array '{name}': {e}")))?;
    let shape = npy.shape().to_vec();
    let fast = match npy.dtype() {
        npyz::DType::Plain(ts) if shape.len() == 1 && ts.endianness() != npyz::Endianness::Big => {
            Some((ts.type_char(), ts.size_field()))
        }
        _ => None,
    };
    let Some((kind, size)) = fast else {
        return read_column(npy, path, name);
    };
    let n = shape[0] as usize;
    let data = npy.into_inner();
    let need = n.checked_mul(size as usize).filter(|&b| b <= data.len());
    if need.is_none() {
        return Err(EventError::format(
            path,
            format!("array '{name}': data shorter than its shape {shape:?}"),
        ));
    }
    macro_rules! ints {
        ($t:ty) => {
            Column::Int(
                data.chunks_exact(std::mem::size_of::<$t>())
                    .take(n)
                    .map(|c| i64::from(<$t>::from_le_bytes(c.try_into().expect("chunk size"))))
                    .collect(),
            )
        };
    }
    let col = match (kind, size) {
        (TypeChar::Bool | TypeChar::Uint, 1) => ints!(u8),
        (TypeChar::Int, 1) => ints!(i8),
        (TypeChar::Int, 2) => ints!(i16),
        (TypeChar::Uint, 2) => ints!(u16),
        (TypeChar::Int, 4) => ints!(i32),
        (TypeChar::Uint, 4) => ints!(u32),
        (TypeChar::Int, 8) => ints!(i64),
        (TypeChar::Float, 4) => Column::Float(
            data.chunks_exact(4)
                .take(n)
                .map(|c| f64::from(f32::from_le_bytes(c.try_into().expect("chunk size"))))
                .collect(),
        ),
        (TypeChar::Float, 8) => Column::Float(
            data.chunks_exact(8)
                .take(n)
                .map(|c| f64::from_le_bytes(c.try_into().expect("chunk size")))
                .collect(),
        ),
        _ => {
            return read_column(
                NpyFile::new(bytes).map_err(|e| EventError::format(path, e.to_string()))?,
                path,
                name,
            );
        }
    };
    Ok((shape, col))
}

/// Converts a time column to µs: integers use `opts.int_time_unit`, floats `opts.float_time_unit`.
pub(crate) fn time_column(
    col: Column,
    opts: &ReadOptions,
    path: &Path,
) -> Result<Vec<i64>, EventError> {
    match col {
        Column::Int(v) => opts
            .int_time_unit
            .ints_to_us(&v)
            .map_err(|m| EventError::format(path, m)),
        Column::Float(v) => opts
            .float_time_unit
            .floats_to_us(&v)
            .map_err(|m| EventError::format(path, m)),
    }
}

fn open_npy(path: &Path) -> Result<NpyFile<std::io::BufReader<std::fs::File>>, EventError> {
    let f = std::fs::File::open(path).map_err(|e| EventError::io(path, e))?;
    NpyFile::new(std::io::BufReader::with_capacity(1 << 20, f))
        .map_err(|e| EventError::format(path, format!("not a valid .npy file: {e}")))
}

/// Reads events from `.npy` (N×4) or `.npz` (`t`, `x`, `y`, `p` arrays).
pub fn read_events_npy(path: &Path, opts: &ReadOptions) -> Result<EventStream, EventError> {
    let is_npz = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("npz"));
    if is_npz {
        let f = std::fs::File::open(path).map_err(|e| EventError::io(path, e))?;
        return read_npz_from(std::io::BufReader::new(f), path, opts);
    }
    let (shape, col) = read_column(open_npy(path)?, path, "events")?;
    if shape.len() != 2 || shape[1] != 4 {
        return Err(EventError::format(
            path,
            format!("expected an N×4 event array (t, x, y, p), got shape {shape:?}"),
        ));
    }
    let n = shape[0] as usize;
    let all = col.as_f64();
    let column = |j: usize| -> Vec<f64> { (0..n).map(|i| all[i * 4 + j]).collect() };
    let sorted = |v: &[f64]| v.windows(2).all(|w| w[0] <= w[1]);
    let c0 = column(0);
    let (tc, xc, yc) = if sorted(&c0) {
        (0, 1, 2)
    } else if sorted(&column(2)) {
        (2, 0, 1)
    } else {
        return Err(EventError::format(
            path,
            "neither column 0 nor column 2 is a sorted time column",
        ));
    };
    let t = match &col {
        Column::Int(v) => {
            let ints: Vec<i64> = (0..n).map(|i| v[i * 4 + tc]).collect();
            time_column(Column::Int(ints), opts, path)?
        }
        Column::Float(_) => time_column(Column::Float(column(tc)), opts, path)?,
    };
    build_stream(
        path,
        opts,
        t,
        Column::Float(column(xc)),
        Column::Float(column(yc)),
        Column::Float(column(3)),
    )
}

/// The raw time column of an `.npz` (`t`) or `.npy` (N×4, column 0 or 2) event file, unconverted,
/// and whether it has an integer dtype.
pub(crate) fn read_raw_times(path: &Path) -> Result<(Vec<f64>, bool), EventError> {
    let is_npz = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("npz"));
    let col = if is_npz {
        let f = std::fs::File::open(path).map_err(|e| EventError::io(path, e))?;
        let mut npz = NpzArchive::new(std::io::BufReader::new(f))
            .map_err(|e| EventError::format(path, format!("not a valid .npz archive: {e}")))?;
        let mut entry = npz
            .zip_archive()
            .by_name("t.npy")
            .map_err(|e| EventError::format(path, format!("array 't': {e}")))?;
        let mut bytes = Vec::new();
        entry
            .read_to_end(&mut bytes)
            .map_err(|e| EventError::format(path, format!("array 't': {e}")))?;
        read_column_bytes(&bytes, path, "t")?.1
    } else {
        let (shape, col) = read_column(open_npy(path)?, path, "events")?;
        if shape.len() != 2 || shape[1] != 4 {
            return Err(EventError::format(
                path,
                format!("expected an N×4 event array (t, x, y, p), got shape {shape:?}"),
            ));
        }
        let all = col.as_f64();
        let c0: Vec<f64> = all.chunks_exact(4).map(|r| r[0]).collect();
        let t = if c0.windows(2).all(|w| w[0] <= w[1]) {
            c0
        } else {
            all.chunks_exact(4).map(|r| r[2]).collect()
        };
        return Ok((t, matches!(col, Column::Int(_))));
    };
    let int = matches!(col, Column::Int(_));
    Ok((col.as_f64(), int))
}

/// Reads the `t`, `x`, `y`, `p` arrays of an npz archive from any seekable reader.
pub(crate) fn read_npz_from<R: Read + Seek>(
    reader: R,
    path: &Path,
    opts: &ReadOptions,
) -> Result<EventStream, EventError> {
    let mut npz = NpzArchive::new(reader)
        .map_err(|e| EventError::format(path, format!("not a valid .npz archive: {e}")))?;
    let mut get = |name: &str| -> Result<Option<(Vec<u64>, Column)>, EventError> {
        // Read the member into memory first: npyz decodes element by element, which is slow on
        // the unbuffered zip stream and fast on a byte slice.
        let mut entry = match npz.zip_archive().by_name(&format!("{name}.npy")) {
            Ok(e) => e,
            Err(npyz::zip::result::ZipError::FileNotFound) => return Ok(None),
            Err(e) => return Err(EventError::format(path, format!("array '{name}': {e}"))),
        };
        let mut bytes = Vec::with_capacity((entry.size() as usize).min(1 << 30));
        entry
            .read_to_end(&mut bytes)
            .map_err(|e| EventError::format(path, format!("array '{name}': {e}")))?;
        read_column_bytes(&bytes, path, name).map(Some)
    };
    let mut vector = |name: &str| -> Result<Column, EventError> {
        let (shape, col) = get(name)?.ok_or_else(|| {
            EventError::format(path, format!("missing array '{name}' (need t, x, y, p)"))
        })?;
        if shape.len() != 1 {
            return Err(EventError::format(
                path,
                format!("array '{name}' must be 1-D, has shape {shape:?}"),
            ));
        }
        Ok(col)
    };
    let (t, x, y, p) = (vector("t")?, vector("x")?, vector("y")?, vector("p")?);
    let t = time_column(t, opts, path)?;
    let mut opts = *opts;
    if opts.size.is_none() {
        // our writer stores the sensor size; other producers do not
        let mut scalar = |name: &str| -> Option<u16> {
            match get(name).ok()??.1 {
                Column::Int(v) if v.len() == 1 => u16::try_from(v[0]).ok(),
                _ => None,
            }
        };
        if let (Some(w), Some(h)) = (scalar("width"), scalar("height")) {
            opts.size = Some((w, h));
        }
    }
    build_stream(path, &opts, t, x, y, p)
}

/// Writes `events` as an uncompressed `.npz` with `t` (int64 µs), `x`, `y` (uint16), `p` (int8 ±1),
/// and `width`/`height` (uint16 scalars in 1-element arrays) — atomically.
pub fn write_events_npz(path: &Path, events: &EventStream) -> Result<(), EventError> {
    Ok(gems_fs::write_atomic_with(path, |w| {
        let mut npz = npyz::npz::NpzWriter::new(w);
        let opts = || {
            npyz::zip::write::FileOptions::default()
                .compression_method(npyz::zip::CompressionMethod::Stored)
                .large_file(true)
                // A fixed timestamp: the same events give a byte-identical file.
                .last_modified_time(npyz::zip::DateTime::default())
        };
        fn put<T: npyz::Serialize + npyz::AutoSerialize + Copy, W: std::io::Write + Seek>(
            npz: &mut npyz::npz::NpzWriter<W>,
            name: &str,
            data: &[T],
            options: npyz::zip::write::FileOptions,
        ) -> std::io::Result<()> {
            let mut a = npz
                .array::<T>(name, options)?
                .default_dtype()
                .shape(&[data.len() as u64])
                .begin_nd()?;
            a.extend(data.iter().copied())?;
            a.finish()
        }
        put(&mut npz, "t", events.t(), opts())?;
        put(&mut npz, "x", events.x(), opts())?;
        put(&mut npz, "y", events.y(), opts())?;
        put(&mut npz, "p", events.p(), opts())?;
        put(&mut npz, "width", &[events.width()], opts())?;
        put(&mut npz, "height", &[events.height()], opts())?;
        npz.zip_writer()
            .finish()
            .map(|_| ())
            .map_err(std::io::Error::other)
    })?)
}

/// Reads a signed count tensor `[views, bins, H, W]` (or `[views, bins, H·W]` when `size =
/// Some((width, height))`) from `.npy`.
pub fn read_bin_counts(path: &Path, size: Option<(usize, usize)>) -> Result<BinCounts, EventError> {
    let (shape, col) = read_column(open_npy(path)?, path, "counts")?;
    let (views, bins, height, width) = match (shape.as_slice(), size) {
        (&[v, b, h, w], _) => (v as usize, b as usize, h as usize, w as usize),
        (&[v, b, hw], Some((w, h))) if hw as usize == w * h => (v as usize, b as usize, h, w),
        (&[_, _, hw], Some((w, h))) => {
            return Err(EventError::format(
                path,
                format!("count tensor has {hw} pixels per bin, expected {w}×{h}"),
            ));
        }
        (&[_, _, _], None) => {
            return Err(EventError::format(
                path,
                "count tensor [views, bins, H·W] needs the image size",
            ));
        }
        (s, _) => {
            return Err(EventError::format(
                path,
                format!("count tensor must be [views, bins, H, W], got {s:?}"),
            ));
        }
    };
    let data: Vec<f32> = col.as_f64().into_iter().map(|v| v as f32).collect();
    if let Some(i) = data.iter().position(|v| !v.is_finite()) {
        return Err(EventError::format(path, format!("count {i} is not finite")));
    }
    Ok(BinCounts {
        views,
        bins,
        height,
        width,
        data,
    })
}

/// Writes a count tensor as a float32 `.npy` of shape `[views, bins, H, W]`, atomically.
pub fn write_bin_counts(path: &Path, counts: &BinCounts) -> Result<(), EventError> {
    let shape = [
        counts.views as u64,
        counts.bins as u64,
        counts.height as u64,
        counts.width as u64,
    ];
    if shape.iter().product::<u64>() != counts.data.len() as u64 {
        return Err(EventError::Invalid(
            "count tensor data does not match its shape".into(),
        ));
    }
    Ok(gems_fs::write_atomic_with(path, |w| {
        let mut a = npyz::WriteOptions::<f32>::new()
            .default_dtype()
            .shape(&shape)
            .writer(w)
            .begin_nd()?;
        a.extend(counts.data.iter().copied())?;
        a.finish()
    })?)
}

/// Shared by the npz reader: a time column unit conversion is exact for integers.
impl TimeUnit {
    pub(crate) fn ints_to_us(self, v: &[i64]) -> Result<Vec<i64>, String> {
        let (mul, div) = self.us_ratio();
        v.iter()
            .map(|&a| {
                if div > 1 {
                    // round half away from zero
                    Ok((a + a.signum() * (div / 2)) / div)
                } else {
                    a.checked_mul(mul)
                        .ok_or_else(|| format!("timestamp {a} overflows µs"))
                }
            })
            .collect()
    }
    pub(crate) fn floats_to_us(self, v: &[f64]) -> Result<Vec<i64>, String> {
        let (mul, div) = self.us_ratio();
        let scale = mul as f64 / div as f64;
        v.iter()
            .map(|&a| {
                let us = (a * scale).round();
                if us.is_finite() && us.abs() < 9.0e18 {
                    Ok(us as i64)
                } else {
                    Err(format!("timestamp {a} is not a valid time"))
                }
            })
            .collect()
    }
}
