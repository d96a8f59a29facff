//! The columnar event type and its borrowed time-window view.

use crate::EventError;

/// A time-sorted stream of events from a `width × height` sensor, stored column-wise.
///
/// Timestamps are `i64` **microseconds** (the native unit of DAVIS/AEDAT4, DSEC and v2e h5 files;
/// 2⁶³ µs is ~292 000 years, and at µs resolution the exposure integrals of EDI lose nothing
/// measurable for exposures of a millisecond or more). Coordinates are pixel column `x` and row `y`
/// (origin top-left), polarity is `+1` (ON, brighter) or `-1` (OFF, darker).
///
/// Invariants, checked by every constructor: all columns have the same length, `t` is
/// non-decreasing, `x < width`, `y < height`, `p ∈ {−1, +1}`. Fields are private so the invariants
/// cannot be broken after construction; read them through [`EventStream::t`] etc.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct EventStream {
    width: u16,
    height: u16,
    t: Vec<i64>,
    x: Vec<u16>,
    y: Vec<u16>,
    p: Vec<i8>,
}

impl EventStream {
    /// An empty stream for a sensor of the given size.
    pub fn empty(width: u16, height: u16) -> Self {
        Self {
            width,
            height,
            ..Self::default()
        }
    }

    /// Builds a stream from columns. Events that are not time-sorted are sorted stably (equal
    /// timestamps keep their input order), so the result is deterministic.
    pub fn from_columns(
        width: u16,
        height: u16,
        t: Vec<i64>,
        x: Vec<u16>,
        y: Vec<u16>,
        p: Vec<i8>,
    ) -> Result<Self, EventError> {
        let n = t.len();
        if x.len() != n || y.len() != n || p.len() != n {
            return Err(EventError::Invalid(format!(
                "column lengths differ: t {n}, x {}, y {}, p {}",
                x.len(),
                y.len(),
                p.len()
            )));
        }
        if let Some(i) = x.iter().position(|&v| v >= width) {
            return Err(EventError::Invalid(format!(
                "event {i}: x = {} outside sensor width {width}",
                x[i]
            )));
        }
        if let Some(i) = y.iter().position(|&v| v >= height) {
            return Err(EventError::Invalid(format!(
                "event {i}: y = {} outside sensor height {height}",
                y[i]
            )));
        }
        if let Some(i) = p.iter().position(|&v| v != 1 && v != -1) {
            return Err(EventError::Invalid(format!(
                "event {i}: polarity {} is not ±1",
                p[i]
            )));
        }
        let mut s = Self {
            width,
            height,
            t,
            x,
            y,
            p,
        };
        if !s.t.is_sorted() {
            s.sort_stable();
        }
        Ok(s)
    }

    fn sort_stable(&mut self) {
        let mut order: Vec<u32> = (0..self.t.len() as u32).collect();
        order.sort_by_key(|&i| self.t[i as usize]);
        self.t = order.iter().map(|&i| self.t[i as usize]).collect();
        self.x = order.iter().map(|&i| self.x[i as usize]).collect();
        self.y = order.iter().map(|&i| self.y[i as usize]).collect();
        self.p = order.iter().map(|&i| self.p[i as usize]).collect();
    }

    /// Sensor width in pixels.
    pub fn width(&self) -> u16 {
        self.width
    }
    /// Sensor height in pixels.
    pub fn height(&self) -> u16 {
        self.height
    }
    /// Number of events.
    pub fn len(&self) -> usize {
        self.t.len()
    }
    /// True when the stream holds no events.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }
    /// Timestamps in µs, non-decreasing.
    pub fn t(&self) -> &[i64] {
        &self.t
    }
    /// Pixel columns.
    pub fn x(&self) -> &[u16] {
        &self.x
    }
    /// Pixel rows.
    pub fn y(&self) -> &[u16] {
        &self.y
    }
    /// Polarities, ±1.
    pub fn p(&self) -> &[i8] {
        &self.p
    }
    /// `(first, last)` timestamp, or `None` for an empty stream.
    pub fn time_span(&self) -> Option<(i64, i64)> {
        Some((*self.t.first()?, *self.t.last()?))
    }
    /// The whole stream as a borrowed slice.
    pub fn as_slice(&self) -> EventSlice<'_> {
        EventSlice {
            width: self.width,
            height: self.height,
            t: &self.t,
            x: &self.x,
            y: &self.y,
            p: &self.p,
        }
    }
    /// Events with `t0 <= t <= t1` (inclusive: an exposure window `[start, end]`), found by binary
    /// search; nothing is copied.
    pub fn window(&self, t0: i64, t1: i64) -> EventSlice<'_> {
        self.as_slice().window(t0, t1)
    }
    /// Appends another stream of the same sensor whose events are not earlier than ours (the way
    /// the simulator and chunked readers grow a stream).
    pub fn append(&mut self, other: EventStream) -> Result<(), EventError> {
        if (other.width, other.height) != (self.width, self.height) {
            return Err(EventError::Invalid(format!(
                "cannot append a {}×{} stream to a {}×{} one",
                other.width, other.height, self.width, self.height
            )));
        }
        if let (Some(&a), Some(&b)) = (self.t.last(), other.t.first())
            && b < a
        {
            return Err(EventError::Invalid(format!(
                "appended events start at {b} µs, before the stream's last event at {a} µs"
            )));
        }
        self.t.extend_from_slice(&other.t);
        self.x.extend_from_slice(&other.x);
        self.y.extend_from_slice(&other.y);
        self.p.extend_from_slice(&other.p);
        Ok(())
    }
}

/// A borrowed, time-sorted window of an [`EventStream`] (same invariants, no copy).
#[derive(Debug, Clone, Copy)]
pub struct EventSlice<'a> {
    width: u16,
    height: u16,
    t: &'a [i64],
    x: &'a [u16],
    y: &'a [u16],
    p: &'a [i8],
}

impl<'a> EventSlice<'a> {
    /// Sensor width in pixels.
    pub fn width(&self) -> u16 {
        self.width
    }
    /// Sensor height in pixels.
    pub fn height(&self) -> u16 {
        self.height
    }
    /// Number of events.
    pub fn len(&self) -> usize {
        self.t.len()
    }
    /// True when the window holds no events.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }
    /// Timestamps in µs.
    pub fn t(&self) -> &'a [i64] {
        self.t
    }
    /// Pixel columns.
    pub fn x(&self) -> &'a [u16] {
        self.x
    }
    /// Pixel rows.
    pub fn y(&self) -> &'a [u16] {
        self.y
    }
    /// Polarities, ±1.
    pub fn p(&self) -> &'a [i8] {
        self.p
    }
    /// Events with `t0 <= t <= t1`; empty when `t1 < t0`.
    pub fn window(&self, t0: i64, t1: i64) -> EventSlice<'a> {
        let a = self.t.partition_point(|&t| t < t0);
        let b = self.t.partition_point(|&t| t <= t1).max(a);
        EventSlice {
            width: self.width,
            height: self.height,
            t: &self.t[a..b],
            x: &self.x[a..b],
            y: &self.y[a..b],
            p: &self.p[a..b],
        }
    }
    /// Signed per-pixel event counts in `bins` equal bins over `[t0, t1]`, bin k holding events
    /// with `t0 + k·T/b < t ≤ t0 + (k+1)·T/b` (E2NeRF's convention; an event exactly at `t0` goes
    /// to bin 0). Events outside `[t0, t1]` are ignored.
    pub fn bin_counts(&self, t0: i64, t1: i64, bins: usize) -> Result<BinCounts, EventError> {
        if bins == 0 || t1 <= t0 {
            return Err(EventError::Invalid(format!(
                "bin_counts needs bins ≥ 1 and t1 > t0 (got bins {bins}, window [{t0}, {t1}])"
            )));
        }
        let (w, h) = (self.width as usize, self.height as usize);
        let mut counts = vec![0f32; bins * w * h];
        let win = self.window(t0, t1);
        let span = (t1 - t0) as i128;
        for i in 0..win.len() {
            let dt = (win.t[i] - t0) as i128;
            // smallest k with dt <= (k+1)·span/bins  ⇔  k = ceil(dt·bins/span) − 1, clamped at 0
            let k = ((dt * bins as i128 + span - 1) / span - 1).clamp(0, bins as i128 - 1) as usize;
            counts[(k * h + win.y[i] as usize) * w + win.x[i] as usize] += f32::from(win.p[i]);
        }
        Ok(BinCounts {
            views: 1,
            bins,
            height: h,
            width: w,
            data: counts,
        })
    }
}

/// Signed per-bin event counts, tensor `[views, bins, height, width]` in row-major order — the
/// E2NeRF/PRISM3D `events*.pt` layout (see [`crate::read_bin_counts`]).
#[derive(Debug, Clone, PartialEq)]
pub struct BinCounts {
    /// Number of views (exposures).
    pub views: usize,
    /// Bins per exposure.
    pub bins: usize,
    /// Image height.
    pub height: usize,
    /// Image width.
    pub width: usize,
    /// `views·bins·height·width` signed counts.
    pub data: Vec<f32>,
}

impl BinCounts {
    /// The `height·width` counts of one bin of one view.
    pub fn bin(&self, view: usize, bin: usize) -> &[f32] {
        let n = self.height * self.width;
        let o = (view * self.bins + bin) * n;
        &self.data[o..o + n]
    }
    /// Stacks single-view tensors of the same shape into one multi-view tensor.
    pub fn stack(parts: &[BinCounts]) -> Result<BinCounts, EventError> {
        let first = parts
            .first()
            .ok_or_else(|| EventError::Invalid("cannot stack zero count tensors".into()))?;
        let mut data = Vec::new();
        let mut views = 0;
        for p in parts {
            if (p.bins, p.height, p.width) != (first.bins, first.height, first.width) {
                return Err(EventError::Invalid(
                    "count tensors to stack differ in shape".into(),
                ));
            }
            views += p.views;
            data.extend_from_slice(&p.data);
        }
        Ok(BinCounts {
            views,
            bins: first.bins,
            height: first.height,
            width: first.width,
            data,
        })
    }
}
