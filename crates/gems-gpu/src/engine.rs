//! [`Engine`]: the splatting engine a run uses, the CPU one (`gems_splat::Renderer`) or the GPU
//! one (`gems_gpu::GpuRenderer`), chosen with `--device`.
//!
//! Both implement the same contract and are tested against each other (gems-gpu's parity
//! tests), so a run may switch engines between a checkpoint and its `--resume`. Renders of the
//! two engines differ by float rounding only; each engine alone is deterministic (the GPU one
//! on a given adapter and driver: it adds no floats atomically). With the GPU engine the
//! trainer (gems-train) keeps the training step resident on the GPU ([`crate::ResidentStep`]);
//! the calls here serve evaluation and the CPU engine's training step. Evaluation renders one
//! frozen scene from many single cameras and takes their pose gradients ([`FrozenScene`]).

use gems_splat::{Camera, Gaussians, Gradients, RenderOutput, RenderSettings, Renderer};

use crate::renderer::POSE_FLOATS;
use crate::{
    CameraChunk, DeviceChoice, GpuError, GpuGaussians, GpuGradients, GpuRenderer, ImageBatch,
    buffers,
};

/// A splatting engine (both boxed: the CPU engine's buffers are kept inline).
pub enum Engine {
    Cpu(Box<Renderer>),
    Gpu(Box<GpuRenderer>),
}

impl Default for Engine {
    fn default() -> Self {
        Engine::cpu()
    }
}

impl std::fmt::Debug for Engine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Engine({})", self.describe())
    }
}

impl Engine {
    /// The CPU engine.
    pub fn cpu() -> Self {
        Engine::Cpu(Box::new(Renderer::new()))
    }

    /// The engine for `--device`: `auto` takes a hardware GPU when there is one and the CPU
    /// otherwise; `gpu` with no adapter is an error.
    pub fn select(choice: DeviceChoice) -> Result<Self, GpuError> {
        Ok(match crate::select(choice)? {
            Some(ctx) => Engine::Gpu(Box::new(GpuRenderer::new(&ctx))),
            None => Engine::cpu(),
        })
    }

    /// The same engine with every GPU kernel timed ([`GpuContext::with_profiler`]); the CPU
    /// engine and adapters that cannot time compute passes are an error.
    pub fn profiled(self) -> Result<Self, GpuError> {
        match self {
            Engine::Cpu(_) => Err(GpuError::Operation(
                "GPU profiling needs the GPU engine (--device gpu)".into(),
            )),
            Engine::Gpu(r) => Ok(Engine::Gpu(Box::new(GpuRenderer::new(
                &r.context().with_profiler()?,
            )))),
        }
    }

    /// The GPU time of each kernel since the previous call (waits for the GPU); `None` unless
    /// the engine is [`Engine::profiled`].
    pub fn kernel_times(&self) -> Option<Result<crate::KernelTimes, GpuError>> {
        match self {
            Engine::Cpu(_) => None,
            Engine::Gpu(r) => r.context().kernel_times(),
        }
    }

    /// What runs the renders, for the user: "CPU" or the GPU adapter.
    pub fn describe(&self) -> String {
        match self {
            Engine::Cpu(_) => format!("CPU ({} threads)", rayon::current_num_threads()),
            Engine::Gpu(r) => format!("GPU {}", r.adapter()),
        }
    }

    /// Renders C cameras of one scene (see `gems_splat::Renderer::forward`).
    pub fn forward(
        &mut self,
        g: &Gaussians,
        cams: &[Camera],
        bgs: &[[f32; 3]],
        s: &RenderSettings,
    ) -> Result<RenderOutput, GpuError> {
        Ok(match self {
            Engine::Cpu(r) => r.forward(g, cams, bgs, s)?,
            Engine::Gpu(r) => r.forward(g, cams, bgs, s)?,
        })
    }

    /// Backward of the last [`Engine::forward`] (see `gems_splat::Renderer::backward`).
    pub fn backward(
        &mut self,
        g: &Gaussians,
        cams: &[Camera],
        bgs: &[[f32; 3]],
        d_rgb: &[f32],
        d_alpha: Option<&[f32]>,
    ) -> Result<Gradients, GpuError> {
        Ok(match self {
            Engine::Cpu(r) => r.backward(g, cams, bgs, d_rgb, d_alpha)?,
            Engine::Gpu(r) => r.backward(g, cams, bgs, d_rgb, d_alpha)?,
        })
    }

    /// Freezes `g` for [`FrozenScene`]'s single-camera renders and pose gradients. The GPU
    /// engine uploads the Gaussians here, once.
    pub fn freeze<'e>(&'e mut self, g: &'e Gaussians) -> Result<FrozenScene<'e>, GpuError> {
        let resident = match self {
            Engine::Cpu(_) => None,
            Engine::Gpu(r) => {
                let ctx = r.context();
                Some(ResidentScene {
                    gaussians: GpuGaussians::upload(ctx, g, g.len())?,
                    grads: GpuGradients::new(ctx, g.len())?,
                    d_rgb: None,
                })
            }
        };
        Ok(FrozenScene {
            engine: self,
            gaussians: g,
            resident,
        })
    }
}

/// Gaussians held fixed while single cameras are rendered and their pose gradients taken: the
/// evaluation's test-time pose refinement (100 render + pose-gradient steps per view) and its
/// renders. On the GPU the Gaussians stay resident: per render only the camera goes up and the
/// image comes back, per pose gradient dL/dRGB goes up and 12 floats come back, where
/// [`Engine::forward`] and [`Engine::backward`] upload every Gaussian twice and read every
/// Gaussian's gradient back. Same results as those calls up to float rounding (the CPU engine
/// runs exactly them).
pub struct FrozenScene<'e> {
    engine: &'e mut Engine,
    gaussians: &'e Gaussians,
    resident: Option<ResidentScene>,
}

/// The GPU side of a [`FrozenScene`].
struct ResidentScene {
    gaussians: GpuGaussians,
    /// Where the backward writes the Gaussian gradients (never read back).
    grads: GpuGradients,
    /// dL/dRGB of the last pose gradient, grown to the largest image.
    d_rgb: Option<wgpu::Buffer>,
}

impl FrozenScene<'_> {
    /// The frozen Gaussians.
    pub fn gaussians(&self) -> &Gaussians {
        self.gaussians
    }

    /// Renders one camera over `background`: RGB `[H,W,3]`, unclamped.
    pub fn render(
        &mut self,
        cam: &Camera,
        background: [f32; 3],
        s: &RenderSettings,
    ) -> Result<Vec<f32>, GpuError> {
        match (&mut *self.engine, &mut self.resident) {
            (Engine::Gpu(r), Some(res)) => {
                let batch = r.forward_resident(&res.gaussians, &[*cam], &[background], s)?;
                let len = batch.width as usize * batch.height as usize * 3;
                buffers::download(r.context(), &batch.buffer, 0, len)
            }
            (engine, _) => Ok(engine
                .forward(self.gaussians, &[*cam], &[background], s)?
                .rgb),
        }
    }

    /// dL/dR (row-major) and dL/dt of the world-to-camera pose of the last
    /// [`FrozenScene::render`] (same camera and background) for `d_rgb` = dL/dRGB `[H,W,3]`.
    pub fn pose_gradient(
        &mut self,
        cam: &Camera,
        background: [f32; 3],
        d_rgb: &[f32],
    ) -> Result<([[f32; 3]; 3], [f32; 3]), GpuError> {
        match (&mut *self.engine, &mut self.resident) {
            (Engine::Gpu(r), Some(res)) => {
                let len = cam.width as usize * cam.height as usize * 3;
                if d_rgb.len() != len {
                    return Err(GpuError::Shape(format!(
                        "dL/dRGB has {} values, the camera is {}x{}x3",
                        d_rgb.len(),
                        cam.width,
                        cam.height
                    )));
                }
                let ctx = r.context().clone();
                let bytes = (len * 4) as u64;
                if res.d_rgb.as_ref().is_none_or(|b| b.size() < bytes) {
                    res.d_rgb = Some(buffers::storage_buffer(&ctx, "dL/dRGB", len)?);
                }
                let buffer = res.d_rgb.clone().expect("allocated above");
                ctx.queue
                    .write_buffer(&buffer, 0, bytemuck::cast_slice(d_rgb));
                let batch = ImageBatch {
                    buffer,
                    count: 1,
                    width: cam.width,
                    height: cam.height,
                };
                r.backward_resident(
                    &res.gaussians,
                    &[*cam],
                    &[background],
                    &batch,
                    &res.grads,
                    CameraChunk::WHOLE,
                )?;
                let p: Vec<f32> = buffers::download(&ctx, r.pose_gradients()?, 0, POSE_FLOATS)?;
                Ok((
                    [[p[0], p[1], p[2]], [p[3], p[4], p[5]], [p[6], p[7], p[8]]],
                    [p[9], p[10], p[11]],
                ))
            }
            (engine, _) => {
                let g = engine.backward(self.gaussians, &[*cam], &[background], d_rgb, None)?;
                Ok((g.cam_rotation[0], g.cam_translation[0]))
            }
        }
    }
}
