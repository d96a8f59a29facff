//! Where the GPU's time goes: a timestamp at the start and the end of every compute pass
//! (wgpu's `Features::TIMESTAMP_QUERY`, `ComputePassTimestampWrites`), summed per kernel.
//!
//! Every kernel of gems-gpu runs in its own compute pass, so a pass's two timestamps bracket
//! one dispatch. A context made with [`GpuContext::with_profiler`] hands its profiler to every
//! kernel built from it; [`GpuContext::kernel_times`] resolves what was recorded since the last
//! call. Timestamps are GPU time only: the host's work between submissions (encoding, uploads,
//! readbacks, the CPU's share of a step) shows up as the gap between the kernels' sum and the
//! step's wall time.

use std::sync::{Arc, Mutex};

use crate::{GpuContext, GpuError};

/// Timestamps per query set: wgpu's limit (`wgpu::QUERY_SET_MAX_QUERIES`), two per pass.
const MAX_QUERIES: u32 = wgpu::QUERY_SET_MAX_QUERIES;

/// One kernel's share of the recorded GPU time.
#[derive(Clone, Debug, PartialEq)]
pub struct KernelTime {
    /// The kernel's entry point or pipeline label.
    pub kernel: &'static str,
    /// Compute passes (dispatches) of it.
    pub dispatches: u32,
    /// Their summed GPU time, seconds.
    pub seconds: f64,
}

/// What [`GpuContext::kernel_times`] returns: per kernel, in the order each first ran, and the
/// passes that ran after the query set was full (not timed).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct KernelTimes {
    pub kernels: Vec<KernelTime>,
    pub untimed_passes: u32,
}

impl KernelTimes {
    /// The GPU time of every timed pass, seconds.
    pub fn total_seconds(&self) -> f64 {
        self.kernels.iter().map(|k| k.seconds).sum()
    }

    /// Adds `other`'s dispatches and times to this one's, kernel by kernel (a kernel new here
    /// is appended, so the order stays that in which each first ran).
    pub fn accumulate(&mut self, other: &KernelTimes) {
        for k in &other.kernels {
            match self.kernels.iter_mut().find(|m| m.kernel == k.kernel) {
                Some(m) => {
                    m.dispatches += k.dispatches;
                    m.seconds += k.seconds;
                }
                None => self.kernels.push(k.clone()),
            }
        }
        self.untimed_passes += other.untimed_passes;
    }

    /// A plain-text table, slowest kernel first, with each one's share of the total.
    pub fn table(&self) -> String {
        let total = self.total_seconds().max(f64::MIN_POSITIVE);
        let mut rows = self.kernels.clone();
        rows.sort_by(|a, b| b.seconds.total_cmp(&a.seconds));
        let mut s = format!(
            "{:<28} {:>10} {:>12} {:>7}\n",
            "kernel", "dispatches", "GPU ms", "share"
        );
        for k in &rows {
            s.push_str(&format!(
                "{:<28} {:>10} {:>12.3} {:>6.1}%\n",
                k.kernel,
                k.dispatches,
                k.seconds * 1e3,
                100.0 * k.seconds / total
            ));
        }
        s.push_str(&format!(
            "{:<28} {:>10} {:>12.3}\n",
            "total",
            rows.iter().map(|k| k.dispatches).sum::<u32>(),
            total * 1e3
        ));
        if self.untimed_passes > 0 {
            s.push_str(&format!(
                "({} passes after the query set filled were not timed)\n",
                self.untimed_passes
            ));
        }
        s
    }
}

/// The query set and the labels of the passes recorded into it.
pub(crate) struct Profiler {
    set: wgpu::QuerySet,
    labels: Vec<&'static str>,
    untimed: u32,
}

/// A profiler shared by the kernels of one context.
pub(crate) type SharedProfiler = Arc<Mutex<Profiler>>;

impl Profiler {
    /// Timestamp writes around the next pass, labelled `label`; `None` (counted as untimed)
    /// once the query set is full.
    fn writes(&mut self, label: &'static str) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        let index = 2 * self.labels.len() as u32;
        if index + 2 > MAX_QUERIES {
            self.untimed += 1;
            return None;
        }
        self.labels.push(label);
        Some(wgpu::ComputePassTimestampWrites {
            query_set: &self.set,
            beginning_of_pass_write_index: Some(index),
            end_of_pass_write_index: Some(index + 1),
        })
    }

    pub(crate) fn new(device: &wgpu::Device) -> SharedProfiler {
        let set = device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("kernel timestamps"),
            ty: wgpu::QueryType::Timestamp,
            count: MAX_QUERIES,
        });
        Arc::new(Mutex::new(Profiler {
            set,
            labels: Vec::new(),
            untimed: 0,
        }))
    }
}

/// Begins a compute pass on `encoder` labelled `label`, with timestamps at its start and end
/// when `profiler` is on and has room.
pub(crate) fn begin_pass<'e>(
    profiler: Option<&SharedProfiler>,
    encoder: &'e mut wgpu::CommandEncoder,
    label: &'static str,
) -> wgpu::ComputePass<'e> {
    let mut profiler = profiler.map(|p| p.lock().unwrap_or_else(|e| e.into_inner()));
    let timestamp_writes = profiler.as_deref_mut().and_then(|p| p.writes(label));
    encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some(label),
        timestamp_writes,
    })
}

/// Resolves and reads back the timestamps recorded since the last call (waiting for the GPU),
/// sums them per kernel and starts over.
pub(crate) fn collect(
    ctx: &GpuContext,
    profiler: &SharedProfiler,
) -> Result<KernelTimes, GpuError> {
    let (labels, untimed) = {
        let mut p = profiler.lock().unwrap_or_else(|e| e.into_inner());
        (
            std::mem::take(&mut p.labels),
            std::mem::take(&mut p.untimed),
        )
    };
    let mut out = KernelTimes {
        kernels: Vec::new(),
        untimed_passes: untimed,
    };
    if labels.is_empty() {
        return Ok(out);
    }
    let queries = 2 * labels.len() as u32;
    let resolved = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("kernel timestamps"),
        size: u64::from(queries) * 8,
        usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let mut enc = crate::buffers::encoder(ctx, "resolve timestamps");
    {
        let p = profiler.lock().unwrap_or_else(|e| e.into_inner());
        enc.resolve_query_set(&p.set, 0..queries, &resolved, 0);
    }
    ctx.queue.submit([enc.finish()]);
    // Timestamps are u64; the readback moves 32-bit words (little endian: low word first).
    let words: Vec<u32> = crate::buffers::download(ctx, &resolved, 0, 2 * queries as usize)?;
    let ticks: Vec<u64> = words
        .chunks_exact(2)
        .map(|w| u64::from(w[0]) | (u64::from(w[1]) << 32))
        .collect();
    let period_ns = f64::from(ctx.queue.get_timestamp_period());
    for (i, label) in labels.iter().enumerate() {
        let (start, end) = (ticks[2 * i], ticks[2 * i + 1]);
        let seconds = end.saturating_sub(start) as f64 * period_ns * 1e-9;
        match out.kernels.iter_mut().find(|k| k.kernel == *label) {
            Some(k) => {
                k.dispatches += 1;
                k.seconds += seconds;
            }
            None => out.kernels.push(KernelTime {
                kernel: label,
                dispatches: 1,
                seconds,
            }),
        }
    }
    Ok(out)
}
