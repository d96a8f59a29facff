//! Adapter selection and the device/queue pair every kernel runs on.

use crate::GpuError;

/// Which engine to run on, as given by `--device`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum DeviceChoice {
    /// A hardware GPU when one exists, else the CPU engine. Software adapters (Mesa lavapipe,
    /// WARP, SwiftShader) are never taken automatically: they are slower than the CPU engine.
    #[default]
    Auto,
    /// The CPU engine.
    Cpu,
    /// A GPU adapter, software ones included (that is how CI tests the GPU path on lavapipe);
    /// an error when there is none.
    Gpu,
}

impl std::str::FromStr for DeviceChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "auto" => Ok(DeviceChoice::Auto),
            "cpu" => Ok(DeviceChoice::Cpu),
            "gpu" => Ok(DeviceChoice::Gpu),
            other => Err(format!(
                "unknown device {other:?}: expected auto, cpu or gpu"
            )),
        }
    }
}

/// What a user needs to know about the adapter a run uses.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AdapterSummary {
    pub name: String,
    pub backend: String,
    pub device_type: String,
    pub driver: String,
    /// A CPU (software) implementation such as lavapipe.
    pub is_software: bool,
}

impl std::fmt::Display for AdapterSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} ({}, {}, {})",
            self.name, self.backend, self.device_type, self.driver
        )
    }
}

/// One wgpu device and queue (cloning shares them: wgpu handles are reference-counted).
#[derive(Clone)]
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub adapter: AdapterSummary,
    /// The device's limits (as requested: the adapter's own).
    pub limits: wgpu::Limits,
    /// Subgroup operations (`Features::SUBGROUP`) are enabled and every subgroup has at least
    /// 8 invocations: the backward rasterizer sums each tile entry's gradient with subgroup adds
    /// (`rasterize_backward_subgroup.wgsl`); otherwise in workgroup memory, three barriers per
    /// entry (`rasterize_backward.wgsl`).
    pub subgroups: bool,
    /// The device can time compute passes (`Features::TIMESTAMP_QUERY`, enabled when the
    /// adapter has it); see [`GpuContext::with_profiler`].
    pub timestamps: bool,
    /// Times every compute pass of the kernels built from this context, when on.
    pub(crate) profiler: Option<crate::profiler::SharedProfiler>,
}

impl std::fmt::Debug for GpuContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuContext")
            .field("adapter", &self.adapter)
            .field("subgroups", &self.subgroups)
            .field("timestamps", &self.timestamps)
            .field("profiling", &self.profiler.is_some())
            .finish_non_exhaustive()
    }
}

impl GpuContext {
    /// Opens the best adapter wgpu offers (high performance), software adapters included.
    /// `WGPU_BACKEND` (e.g. `vulkan`) restricts the backends probed.
    pub fn new() -> Result<Self, GpuError> {
        Self::open(true)
    }

    fn open(allow_software: bool) -> Result<Self, GpuError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: None,
            // Kernels size their buffers from the adapter's real limits.
            apply_limit_buckets: false,
        }))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let info = adapter.get_info();
        let summary = AdapterSummary {
            name: info.name.clone(),
            backend: format!("{:?}", info.backend),
            device_type: format!("{:?}", info.device_type),
            driver: format!("{} {}", info.driver, info.driver_info)
                .trim()
                .to_owned(),
            is_software: info.device_type == wgpu::DeviceType::Cpu,
        };
        if summary.is_software && !allow_software {
            return Err(GpuError::NoAdapter(format!(
                "only a software adapter was found: {summary}"
            )));
        }
        // The subgroup kernel parks one sum per subgroup for up to 256 / 8 subgroups.
        let subgroups =
            adapter.features().contains(wgpu::Features::SUBGROUP) && info.subgroup_min_size >= 8;
        let mut features = wgpu::Features::empty();
        if subgroups {
            features |= wgpu::Features::SUBGROUP;
        }
        // Timestamp queries cost nothing until a profiler writes them (`with_profiler`).
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        if timestamps {
            features |= wgpu::Features::TIMESTAMP_QUERY;
        }
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("gems"),
            required_features: features,
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device {
            adapter: summary.to_string(),
            reason: e.to_string(),
        })?;
        Ok(GpuContext {
            device,
            queue,
            adapter: summary,
            limits,
            subgroups,
            timestamps,
            profiler: None,
        })
    }

    /// The same device with a profiler: every compute pass of the kernels built from the
    /// returned context (renderer, loss, Adam, MCMC, regularisers, the resident step) is timed
    /// on the GPU; [`GpuContext::kernel_times`] reads the times. An error where the adapter
    /// cannot time passes.
    pub fn with_profiler(&self) -> Result<GpuContext, GpuError> {
        if !self.timestamps {
            return Err(GpuError::Operation(format!(
                "{} cannot time compute passes (no TIMESTAMP_QUERY)",
                self.adapter
            )));
        }
        Ok(GpuContext {
            profiler: Some(crate::profiler::Profiler::new(&self.device)),
            ..self.clone()
        })
    }

    /// The GPU time of each kernel since the previous call (waits for the GPU); `None` for a
    /// context without a profiler.
    pub fn kernel_times(&self) -> Option<Result<crate::KernelTimes, GpuError>> {
        self.profiler
            .as_ref()
            .map(|p| crate::profiler::collect(self, p))
    }

    /// The same device with [`GpuContext::subgroups`] off: kernels compiled for it take the
    /// workgroup-memory paths. For the tests and benchmarks that compare both paths on one
    /// adapter.
    pub fn without_subgroups(&self) -> GpuContext {
        GpuContext {
            subgroups: false,
            ..self.clone()
        }
    }
}

/// The context for a [`DeviceChoice`]: `Ok(None)` means "use the CPU engine".
///
/// `Auto` takes a hardware adapter when one exists and otherwise falls back to the CPU quietly;
/// `Gpu` takes any adapter and is an error when there is none.
pub fn select(choice: DeviceChoice) -> Result<Option<GpuContext>, GpuError> {
    match choice {
        DeviceChoice::Cpu => Ok(None),
        DeviceChoice::Gpu => GpuContext::new().map(Some),
        DeviceChoice::Auto => match GpuContext::open(false) {
            Ok(ctx) => Ok(Some(ctx)),
            Err(e) => {
                tracing::debug!("no hardware GPU adapter, using the CPU: {e}");
                Ok(None)
            }
        },
    }
}
