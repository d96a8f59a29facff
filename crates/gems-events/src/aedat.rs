//! AEDAT 4 (iniVation DV) reader: polarity events and APS frames with their exposure times.
//!
//! Layout (the `aedat` crate's flatbuffer schemas, `neuromorphicsystems/aedat`): ASCII `#!AER-DAT4.0\r\n`, u32 length + `IOHE` flatbuffer {compression,
//! file_data_position, description XML}, then packets `u32 stream id, u32 byte length, payload`;
//! each payload (LZ4 frame or Zstd, as the header declares) is a size-prefixed flatbuffer: `EVTS`
//! {elements: [struct Event {t i64 µs, x i16, y i16, on bool}] (16 bytes each)} or `FRME` {t,
//! begin_t, end_t, exposure_begin_t, exposure_end_t: i64; format i8; width, height, offset_x,
//! offset_y: i16; pixels [u8]}. Other streams (IMU, triggers) are skipped. Stream types and the
//! sensor size come from the description's `typeIdentifier` and `sizeX`/`sizeY` attributes.
//!
//! The flatbuffers are decoded by hand with bounds checks on every access, so malformed input gives
//! an error naming the file and the packet, never a panic.

use std::io::Read;
use std::path::Path;

use crate::{EventError, EventStream};

/// One APS frame.
#[derive(Debug, Clone, PartialEq)]
pub struct AedatFrame {
    /// Frame timestamp (µs).
    pub t: i64,
    /// Exposure start (µs).
    pub exposure_begin: i64,
    /// Exposure end (µs).
    pub exposure_end: i64,
    /// Width in pixels.
    pub width: u16,
    /// Height in pixels.
    pub height: u16,
    /// Position of the frame's top-left pixel on the sensor (region of interest).
    pub offset: (i16, i16),
    /// 1 (gray) or 3 (RGB).
    pub channels: u8,
    /// Row-major interleaved pixels scaled to [0, 1] (8-bit /255, 16-bit /65535), RGB order;
    /// values are the camera's output (not linearised).
    pub pixels: Vec<f32>,
}

/// Everything read from an AEDAT4 file.
#[derive(Debug, Clone, PartialEq)]
pub struct AedatRecording {
    /// All polarity events (time-sorted).
    pub events: EventStream,
    /// APS frames in file order.
    pub frames: Vec<AedatFrame>,
}

const MAGIC: &[u8] = b"#!AER-DAT4.0\r\n";

/// Reads an AEDAT4 file.
pub fn read_aedat4(path: &Path) -> Result<AedatRecording, EventError> {
    let data = std::fs::read(path).map_err(|e| EventError::io(path, e))?;
    parse_aedat4(&data).map_err(|msg| EventError::format(path, msg))
}

#[derive(Clone, Copy, PartialEq)]
enum Kind {
    Events,
    Frames,
    Other,
}

struct StreamInfo {
    id: u32,
    kind: Kind,
    size: Option<(u16, u16)>,
}

pub(crate) fn parse_aedat4(data: &[u8]) -> Result<AedatRecording, String> {
    if !data.starts_with(MAGIC) {
        return Err("not an AEDAT 4.0 file (missing '#!AER-DAT4.0' header)".into());
    }
    let mut pos = MAGIC.len();
    let hlen = u32_at(data, pos).ok_or("truncated header length")? as usize;
    pos += 4;
    let header = data
        .get(pos..pos.checked_add(hlen).ok_or("bad header length")?)
        .ok_or("truncated IOHE header")?;
    pos += hlen;
    let fb = Fb(header);
    let root = fb.root(0).ok_or("corrupt IOHE header")?;
    let compression = fb
        .field_i32(root, 0)
        .ok_or("corrupt IOHE header")?
        .unwrap_or(0);
    let data_end = match fb
        .field_i64(root, 1)
        .ok_or("corrupt IOHE header")?
        .unwrap_or(-1)
    {
        p if p >= 0 && (p as usize) <= data.len() && p as usize >= pos => p as usize,
        _ => data.len(),
    };
    let description = fb
        .field_bytes(root, 2)
        .ok_or("corrupt IOHE description")?
        .unwrap_or(&[]);
    let description =
        std::str::from_utf8(description).map_err(|_| "IOHE description is not UTF-8")?;
    let streams = parse_description(description);

    let (mut t, mut x, mut y, mut p) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut frames = Vec::new();
    let mut packet_index = 0usize;
    let mut buf = Vec::new();
    while pos < data_end {
        let err = |m: &str| format!("packet {packet_index} at byte {pos}: {m}");
        let id = u32_at(data, pos).ok_or_else(|| err("truncated packet header"))?;
        let len = u32_at(data, pos + 4).ok_or_else(|| err("truncated packet header"))? as usize;
        let start = pos + 8;
        let payload = data
            .get(start..start.saturating_add(len))
            .ok_or_else(|| err("truncated packet"))?;
        let kind = streams
            .iter()
            .find(|s| s.id == id)
            .map_or(Kind::Other, |s| s.kind);
        if kind != Kind::Other {
            buf.clear();
            decompress(compression, payload, &mut buf).map_err(|m| err(&m))?;
            let body = buf.get(4..).ok_or_else(|| err("missing size prefix"))?;
            let fb = Fb(body);
            let root = fb.root(0).ok_or_else(|| err("corrupt flatbuffer"))?;
            match kind {
                Kind::Events => {
                    let v = fb
                        .field_vector(root, 0, 16)
                        .ok_or_else(|| err("corrupt event vector"))?;
                    if let Some((vpos, n)) = v {
                        t.reserve(n);
                        for k in 0..n {
                            let e = vpos + 16 * k;
                            t.push(i64_at(body, e).ok_or_else(|| err("corrupt event"))?);
                            x.push(i16_at(body, e + 8).ok_or_else(|| err("corrupt event"))?);
                            y.push(i16_at(body, e + 10).ok_or_else(|| err("corrupt event"))?);
                            p.push(
                                if *body.get(e + 12).ok_or_else(|| err("corrupt event"))? != 0 {
                                    1i8
                                } else {
                                    -1
                                },
                            );
                        }
                    }
                }
                Kind::Frames => frames.push(parse_frame(&fb, root).map_err(|m| err(&m))?),
                Kind::Other => {}
            }
        }
        pos = start + len;
        packet_index += 1;
    }
    let size = streams
        .iter()
        .find(|s| s.kind == Kind::Events)
        .and_then(|s| s.size);
    let (w, h) = match size {
        Some(s) => s,
        None => {
            let mx = x.iter().copied().max().unwrap_or(0).max(0) as u16;
            let my = y.iter().copied().max().unwrap_or(0).max(0) as u16;
            (mx.saturating_add(1), my.saturating_add(1))
        }
    };
    let mut xs = Vec::with_capacity(x.len());
    let mut ys = Vec::with_capacity(y.len());
    for (i, (&a, &b)) in x.iter().zip(&y).enumerate() {
        if a < 0 || b < 0 || a as u16 >= w || b as u16 >= h {
            return Err(format!(
                "event {i}: pixel ({a}, {b}) outside the {w}×{h} sensor"
            ));
        }
        xs.push(a as u16);
        ys.push(b as u16);
    }
    let events = EventStream::from_columns(w, h, t, xs, ys, p).map_err(|e| e.to_string())?;
    Ok(AedatRecording { events, frames })
}

fn decompress(compression: i32, payload: &[u8], out: &mut Vec<u8>) -> Result<(), String> {
    match compression {
        0 => out.extend_from_slice(payload),
        1 | 2 => {
            lz4_flex::frame::FrameDecoder::new(payload)
                .read_to_end(out)
                .map_err(|e| format!("LZ4 decompression failed: {e}"))?;
        }
        3 | 4 => {
            let mut src = payload;
            let mut dec = ruzstd::decoding::StreamingDecoder::new(&mut src)
                .map_err(|e| format!("Zstd decompression failed: {e}"))?;
            dec.read_to_end(out)
                .map_err(|e| format!("Zstd decompression failed: {e}"))?;
        }
        c => return Err(format!("unknown compression code {c}")),
    }
    Ok(())
}

fn parse_frame(fb: &Fb<'_>, root: Table) -> Result<AedatFrame, String> {
    let bad = || "corrupt frame".to_owned();
    let i64f = |id| {
        fb.field_i64(root, id)
            .ok_or_else(bad)
            .map(|v| v.unwrap_or(0))
    };
    let i16f = |id| {
        fb.field_i16(root, id)
            .ok_or_else(bad)
            .map(|v| v.unwrap_or(0))
    };
    let t = i64f(0)?;
    let exposure_begin = i64f(3)?;
    let exposure_end = i64f(4)?;
    let format = fb.field_i8(root, 5).ok_or_else(bad)?.unwrap_or(0);
    let (width, height) = (i16f(6)?, i16f(7)?);
    let offset = (i16f(8)?, i16f(9)?);
    if width <= 0 || height <= 0 {
        return Err(format!("frame size {width}×{height} is not positive"));
    }
    // (source channels, bytes per sample, output channels)
    let (src_c, bytes, channels) = match format {
        0 => (1, 1, 1),
        2 => (1, 2, 1),
        16 => (3, 1, 3),
        18 => (3, 2, 3),
        24 => (4, 1, 3),
        26 => (4, 2, 3),
        f => return Err(format!("unknown frame format {f}")),
    };
    let pixels = fb.field_bytes(root, 10).ok_or_else(bad)?.unwrap_or(&[]);
    let n = width as usize * height as usize;
    if pixels.len() != n * src_c * bytes {
        return Err(format!(
            "frame {width}×{height} format {format} needs {} pixel bytes, has {}",
            n * src_c * bytes,
            pixels.len()
        ));
    }
    let sample = |i: usize| -> f32 {
        if bytes == 1 {
            f32::from(pixels[i]) / 255.0
        } else {
            f32::from(u16::from_le_bytes([pixels[2 * i], pixels[2 * i + 1]])) / 65535.0
        }
    };
    let mut out = Vec::with_capacity(n * channels as usize);
    for k in 0..n {
        if src_c == 1 {
            out.push(sample(k));
        } else {
            // stored BGR(A): emit RGB
            out.extend([
                sample(k * src_c + 2),
                sample(k * src_c + 1),
                sample(k * src_c),
            ]);
        }
    }
    Ok(AedatFrame {
        t,
        exposure_begin,
        exposure_end,
        width: width as u16,
        height: height as u16,
        offset,
        channels,
        pixels: out,
    })
}

/// Stream id → type and size from the description XML (`<node name="N" path=".../outInfo/N/">`
/// with `typeIdentifier`, and `sizeX`/`sizeY` in its `info` child).
fn parse_description(xml: &str) -> Vec<StreamInfo> {
    let mut starts: Vec<(usize, u32)> = Vec::new();
    let mut from = 0;
    while let Some(i) = xml[from..].find("<node name=\"") {
        let a = from + i + "<node name=\"".len();
        from = a;
        let Some(name_end) = xml[a..].find('"') else {
            break;
        };
        let name = &xml[a..a + name_end];
        let Ok(id) = name.parse::<u32>() else {
            continue;
        };
        let rest = &xml[a + name_end..];
        let tag_end = rest.find('>').unwrap_or(rest.len());
        if rest[..tag_end].contains(&format!("outInfo/{id}/\"")) {
            starts.push((a, id));
        }
    }
    let attr = |seg: &str, key: &str| -> Option<String> {
        let k = seg.find(&format!("key=\"{key}\""))?;
        let s = seg[k..].find('>')? + k + 1;
        let e = seg[s..].find('<')? + s;
        Some(seg[s..e].trim().to_owned())
    };
    starts
        .iter()
        .enumerate()
        .map(|(k, &(a, id))| {
            let end = starts.get(k + 1).map_or(xml.len(), |s| s.0);
            let seg = &xml[a..end];
            let kind = match attr(seg, "typeIdentifier").as_deref() {
                Some("EVTS") => Kind::Events,
                Some("FRME") => Kind::Frames,
                _ => Kind::Other,
            };
            let dim = |key| {
                attr(seg, key)
                    .and_then(|v| v.parse::<u16>().ok())
                    .filter(|&v| v > 0)
            };
            let size = dim("sizeX").zip(dim("sizeY"));
            StreamInfo { id, kind, size }
        })
        .collect()
}

fn u32_at(b: &[u8], i: usize) -> Option<u32> {
    Some(u32::from_le_bytes(
        b.get(i..i.checked_add(4)?)?.try_into().ok()?,
    ))
}
fn i64_at(b: &[u8], i: usize) -> Option<i64> {
    Some(i64::from_le_bytes(
        b.get(i..i.checked_add(8)?)?.try_into().ok()?,
    ))
}
fn i32_at(b: &[u8], i: usize) -> Option<i32> {
    Some(i32::from_le_bytes(
        b.get(i..i.checked_add(4)?)?.try_into().ok()?,
    ))
}
fn i16_at(b: &[u8], i: usize) -> Option<i16> {
    Some(i16::from_le_bytes(
        b.get(i..i.checked_add(2)?)?.try_into().ok()?,
    ))
}
fn u16_at(b: &[u8], i: usize) -> Option<u16> {
    Some(u16::from_le_bytes(
        b.get(i..i.checked_add(2)?)?.try_into().ok()?,
    ))
}

/// A flatbuffer table: its position and its vtable's position.
#[derive(Clone, Copy)]
struct Table {
    pos: usize,
    vtable: usize,
}

/// Minimal bounds-checked flatbuffer access. Every accessor returns `None` on corruption and
/// `Some(None)` for an absent field.
struct Fb<'a>(&'a [u8]);

impl<'a> Fb<'a> {
    fn root(&self, at: usize) -> Option<Table> {
        let off = u32_at(self.0, at)? as usize;
        self.table(at.checked_add(off)?)
    }
    fn table(&self, pos: usize) -> Option<Table> {
        let soff = i64::from(i32_at(self.0, pos)?);
        let vtable = usize::try_from(pos as i64 - soff).ok()?;
        let vlen = u16_at(self.0, vtable)? as usize;
        if vlen < 4 || vtable.checked_add(vlen)? > self.0.len() {
            return None;
        }
        Some(Table { pos, vtable })
    }
    /// Absolute position of field `id`, `Some(None)` if absent.
    fn field(&self, t: Table, id: usize) -> Option<Option<usize>> {
        let vlen = u16_at(self.0, t.vtable)? as usize;
        let slot = 4 + 2 * id;
        if slot + 2 > vlen {
            return Some(None);
        }
        let off = u16_at(self.0, t.vtable + slot)? as usize;
        Some(if off == 0 {
            None
        } else {
            Some(t.pos.checked_add(off)?)
        })
    }
    fn field_i64(&self, t: Table, id: usize) -> Option<Option<i64>> {
        match self.field(t, id)? {
            None => Some(None),
            Some(p) => Some(Some(i64_at(self.0, p)?)),
        }
    }
    fn field_i32(&self, t: Table, id: usize) -> Option<Option<i32>> {
        match self.field(t, id)? {
            None => Some(None),
            Some(p) => Some(Some(i32_at(self.0, p)?)),
        }
    }
    fn field_i16(&self, t: Table, id: usize) -> Option<Option<i16>> {
        match self.field(t, id)? {
            None => Some(None),
            Some(p) => Some(Some(i16_at(self.0, p)?)),
        }
    }
    fn field_i8(&self, t: Table, id: usize) -> Option<Option<i8>> {
        match self.field(t, id)? {
            None => Some(None),
            Some(p) => Some(Some(*self.0.get(p)? as i8)),
        }
    }
    /// A vector field: `(position of element 0, count)`, checked to fit `elem` bytes per element.
    fn field_vector(&self, t: Table, id: usize, elem: usize) -> Option<Option<(usize, usize)>> {
        let Some(p) = self.field(t, id)? else {
            return Some(None);
        };
        let vpos = p.checked_add(u32_at(self.0, p)? as usize)?;
        let n = u32_at(self.0, vpos)? as usize;
        let start = vpos.checked_add(4)?;
        if start.checked_add(n.checked_mul(elem)?)? > self.0.len() {
            return None;
        }
        Some(Some((start, n)))
    }
    fn field_bytes(&self, t: Table, id: usize) -> Option<Option<&'a [u8]>> {
        match self.field_vector(t, id, 1)? {
            None => Some(None),
            Some((s, n)) => Some(Some(&self.0[s..s + n])),
        }
    }
}
