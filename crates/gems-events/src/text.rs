//! ECD / v2e text events: one event per line `t x y p` (t in seconds by default, p ∈ {0,1} or ±1,
//! an optional 5th column is ignored), blank lines and lines starting with `#` skipped. Our writer
//! adds a `# … sensor WxH` header line that the reader uses for the sensor size.
//!
//! Speed: the file is read at once and split at line boundaries into chunks parsed in parallel with
//! a hand-written exact decimal parser (timestamps go straight to integer µs without a float round
//! trip); chunks are concatenated in file order.

use std::io::Write;
use std::path::Path;

use rayon::prelude::*;

use crate::read::{ReadOptions, resolve_size};
use crate::{EventError, EventStream, TimeUnit};

#[derive(Default)]
struct Columns {
    t: Vec<i64>,
    x: Vec<u16>,
    y: Vec<u16>,
    p: Vec<i8>,
}

/// A parse failure inside one chunk: byte offset of the offending line within the chunk, and why.
struct ChunkError {
    line_start: usize,
    msg: String,
}

/// Reads an ECD/v2e text event file.
pub fn read_events_text(path: &Path, opts: &ReadOptions) -> Result<EventStream, EventError> {
    let data = std::fs::read(path).map_err(|e| EventError::io(path, e))?;
    parse_text(&data, path, opts)
}

pub(crate) fn parse_text(
    data: &[u8],
    path: &Path,
    opts: &ReadOptions,
) -> Result<EventStream, EventError> {
    let chunks = split_chunks(data, 4 << 20);
    let parsed: Vec<Result<Columns, ChunkError>> = chunks
        .par_iter()
        .map(|&(a, b)| parse_chunk(&data[a..b], opts.text_time_unit))
        .collect();
    let mut total = 0;
    for (k, r) in parsed.iter().enumerate() {
        match r {
            Ok(c) => total += c.t.len(),
            Err(e) => {
                let offset = chunks[k].0 + e.line_start;
                let line = 1 + data[..offset].iter().filter(|&&b| b == b'\n').count();
                return Err(EventError::format(path, format!("line {line}: {}", e.msg)));
            }
        }
    }
    let mut all = Columns {
        t: Vec::with_capacity(total),
        x: Vec::with_capacity(total),
        y: Vec::with_capacity(total),
        p: Vec::with_capacity(total),
    };
    for c in parsed.into_iter().flatten() {
        all.t.extend_from_slice(&c.t);
        all.x.extend_from_slice(&c.x);
        all.y.extend_from_slice(&c.y);
        all.p.extend_from_slice(&c.p);
    }
    let size = match opts.size {
        Some(s) => s,
        None => match header_size(data) {
            Some(s) => s,
            None => resolve_size(path, None, &all.x, &all.y)?,
        },
    };
    EventStream::from_columns(size.0, size.1, all.t, all.x, all.y, all.p)
        .map_err(|e| EventError::format(path, e.to_string()))
}

/// The raw first column (time) of a text event file, unconverted.
pub(crate) fn read_raw_times(path: &Path) -> Result<Vec<f64>, EventError> {
    let text = std::fs::read(path).map_err(|e| EventError::io(path, e))?;
    let mut out = Vec::new();
    for (i, line) in text.split(|&b| b == b'\n').enumerate() {
        let Some(f) = line
            .split(|&b| b == b' ' || b == b'\t' || b == b',' || b == b'\r')
            .find(|f| !f.is_empty())
        else {
            continue;
        };
        if f[0] == b'#' {
            continue;
        }
        let v = std::str::from_utf8(f)
            .ok()
            .and_then(|s| s.parse::<f64>().ok())
            .ok_or_else(|| {
                EventError::format(
                    path,
                    format!(
                        "line {}: bad timestamp '{}'",
                        i + 1,
                        String::from_utf8_lossy(f)
                    ),
                )
            })?;
        out.push(v);
    }
    Ok(out)
}

/// Splits `data` into ranges of about `target` bytes that end at line boundaries.
fn split_chunks(data: &[u8], target: usize) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = 0;
    while start < data.len() {
        let mut end = (start + target).min(data.len());
        while end < data.len() && data[end - 1] != b'\n' {
            end += 1;
        }
        out.push((start, end));
        start = end;
    }
    out
}

/// The `sensor WxH` token of a leading `#` comment line, if any.
fn header_size(data: &[u8]) -> Option<(u16, u16)> {
    for line in data.split(|&b| b == b'\n').take(16) {
        let line = std::str::from_utf8(line).ok()?.trim();
        if !line.starts_with('#') {
            if line.is_empty() {
                continue;
            }
            return None;
        }
        if let Some(rest) = line.split("sensor ").nth(1) {
            let tok = rest.split_whitespace().next()?;
            let (w, h) = tok.split_once('x')?;
            return Some((w.parse().ok()?, h.parse().ok()?));
        }
    }
    None
}

fn parse_chunk(chunk: &[u8], unit: TimeUnit) -> Result<Columns, ChunkError> {
    let mut c = Columns::default();
    let cap = chunk.len() / 24;
    c.t.reserve(cap);
    c.x.reserve(cap);
    c.y.reserve(cap);
    c.p.reserve(cap);
    let mut pos = 0;
    let exp = unit.us_exponent();
    while pos < chunk.len() {
        let end = memchr_newline(&chunk[pos..]).map_or(chunk.len(), |i| pos + i);
        let line = &chunk[pos..end];
        let err = |msg: String| ChunkError {
            line_start: pos,
            msg,
        };
        let mut fields = line
            .split(|&b| b == b' ' || b == b'\t' || b == b',' || b == b'\r')
            .filter(|f| !f.is_empty());
        match fields.next() {
            None => {}
            Some(f) if f[0] == b'#' => {}
            Some(tf) => {
                let t = parse_time(tf, exp).ok_or_else(|| {
                    err(format!("bad timestamp '{}'", String::from_utf8_lossy(tf)))
                })?;
                let mut int = |name: &str| -> Result<u16, ChunkError> {
                    let f = fields
                        .next()
                        .ok_or_else(|| err(format!("missing {name} (expected `t x y p`)")))?;
                    parse_u16(f)
                        .ok_or_else(|| err(format!("bad {name} '{}'", String::from_utf8_lossy(f))))
                };
                let x = int("x")?;
                let y = int("y")?;
                let pf = fields
                    .next()
                    .ok_or_else(|| err("missing polarity (expected `t x y p`)".into()))?;
                let p = match pf {
                    b"1" | b"+1" => 1,
                    b"0" | b"-1" => -1,
                    _ => {
                        return Err(err(format!(
                            "bad polarity '{}'",
                            String::from_utf8_lossy(pf)
                        )));
                    }
                };
                c.t.push(t);
                c.x.push(x);
                c.y.push(y);
                c.p.push(p);
            }
        }
        pos = end + 1;
    }
    Ok(c)
}

fn memchr_newline(s: &[u8]) -> Option<usize> {
    s.iter().position(|&b| b == b'\n')
}

fn parse_u16(f: &[u8]) -> Option<u16> {
    if f.is_empty() || f.len() > 5 {
        return None;
    }
    let mut v: u32 = 0;
    for &b in f {
        if !b.is_ascii_digit() {
            return None;
        }
        v = v * 10 + u32::from(b - b'0');
    }
    u16::try_from(v).ok().filter(|&v| v < u16::MAX)
}

/// Parses a decimal number (optional sign, digits, fraction, exponent) and returns it times
/// 10^`exp`, rounded half away from zero to an integer — exact, no binary float involved.
fn parse_time(f: &[u8], exp: i32) -> Option<i64> {
    let (neg, mut s) = match f.first()? {
        b'-' => (true, &f[1..]),
        b'+' => (false, &f[1..]),
        _ => (false, f),
    };
    let mut mant: i128 = 0;
    let mut digits = 0usize;
    let mut scale: i32 = exp;
    let mut seen_dot = false;
    let mut any = false;
    while let Some((&b, rest)) = s.split_first() {
        match b {
            b'0'..=b'9' => {
                any = true;
                // beyond 30 significant digits the extra ones cannot matter at µs resolution
                if digits < 30 {
                    mant = mant * 10 + i128::from(b - b'0');
                    if mant != 0 {
                        digits += 1;
                    }
                    if seen_dot {
                        scale -= 1;
                    }
                } else if !seen_dot {
                    scale += 1;
                }
            }
            b'.' if !seen_dot => seen_dot = true,
            b'e' | b'E' => {
                let e: i32 = std::str::from_utf8(rest).ok()?.parse().ok()?;
                scale = scale.checked_add(e)?;
                s = &[];
                break;
            }
            _ => return None,
        }
        s = rest;
    }
    let _ = s;
    if !any {
        return None;
    }
    let v = if scale >= 0 {
        if scale > 30 {
            return if mant == 0 { Some(0) } else { None };
        }
        mant.checked_mul(10i128.pow(scale as u32))?
    } else if scale < -38 {
        0
    } else {
        let d = 10i128.pow((-scale) as u32);
        (mant + d / 2) / d
    };
    let v = i64::try_from(v).ok()?;
    Some(if neg { -v } else { v })
}

/// Writes ECD-style text (`t[s] x y p`, p ∈ {0,1}, t with 6 decimals = exact µs) with a comment
/// header recording the sensor size, atomically.
pub fn write_events_text(path: &Path, events: &EventStream) -> Result<(), EventError> {
    Ok(gems_fs::write_atomic_with(path, |w| {
        writeln!(
            w,
            "# gems events: t[s] x y p (1=on, 0=off); sensor {}x{}",
            events.width(),
            events.height()
        )?;
        let mut line = Vec::with_capacity(64);
        for i in 0..events.len() {
            line.clear();
            let t = events.t()[i];
            if t < 0 {
                line.push(b'-');
            }
            let a = t.unsigned_abs();
            push_uint(&mut line, a / 1_000_000);
            line.push(b'.');
            let frac = a % 1_000_000;
            let digits = frac.to_string();
            line.extend(std::iter::repeat_n(b'0', 6 - digits.len()));
            line.extend_from_slice(digits.as_bytes());
            line.push(b' ');
            push_uint(&mut line, u64::from(events.x()[i]));
            line.push(b' ');
            push_uint(&mut line, u64::from(events.y()[i]));
            line.extend_from_slice(if events.p()[i] > 0 { b" 1\n" } else { b" 0\n" });
            w.write_all(&line)?;
        }
        Ok(())
    })?)
}

fn push_uint(out: &mut Vec<u8>, mut v: u64) {
    let mut buf = [0u8; 20];
    let mut i = buf.len();
    loop {
        i -= 1;
        buf[i] = b'0' + (v % 10) as u8;
        v /= 10;
        if v == 0 {
            break;
        }
    }
    out.extend_from_slice(&buf[i..]);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimal_times_are_exact() {
        assert_eq!(parse_time(b"2.097134001", 6), Some(2_097_134));
        assert_eq!(parse_time(b"2.0971345", 6), Some(2_097_135));
        assert_eq!(parse_time(b"-0.5", 6), Some(-500_000));
        assert_eq!(parse_time(b"1e-3", 6), Some(1_000));
        assert_eq!(parse_time(b"123456", 0), Some(123_456));
        assert_eq!(parse_time(b"1500", -3), Some(2));
        assert_eq!(parse_time(b"0.000000", 6), Some(0));
        assert_eq!(parse_time(b"1.2.3", 6), None);
        assert_eq!(parse_time(b"abc", 6), None);
        assert_eq!(parse_time(b"-", 6), None);
        assert_eq!(parse_time(b"1e999", 6), None);
    }
}
