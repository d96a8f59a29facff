//! The gems half of the side-by-side benchmark against gsplat (`bench/gsplat/`, its README has
//! the whole procedure).
//!
//! `side_by_side write DIR` writes the shared inputs, one safetensors file per size
//! (`inputs_<n>.safetensors`: 10k, 100k and 300k Gaussians with SH degree 3, the same 15
//! cameras at 400×270, their backgrounds and a target image), which both sides read: gsplat's
//! script (`bench.py`) and `side_by_side run DIR`, which times on the GPU engine, with the
//! Gaussians resident:
//! - `forward`: rendering the 15 cameras (`ResidentStep::render`);
//! - `forward_backward`: that and the backward pass to every Gaussian parameter and every
//!   camera's pose (`ResidentStep::backpropagate`, dL/dRGB fixed);
//! - `step`: the whole GeMS step (`ResidentStep::step`: render, blur mean, (1−λ)·L1 +
//!   λ·(1 − SSIM), backward, regularisers, Adam, the pose gradients read back).
//!
//! Each figure is the median wall time of `--iters` calls after `--warmup`, with the queue
//! drained after each (`buffers::wait_idle`; a step reads its pose gradients back anyway), and
//! is written to `--out` (JSON) for `compare.py`. `--sizes` picks some of the sizes. Where
//! the adapter can time compute passes, one more step per size runs with GPU timestamps around
//! every kernel, and the per-kernel table is printed and written beside the figures.

#[path = "../../gems-splat/tests/common/mod.rs"]
mod splat_common;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use gems_gpu::{DeviceChoice, GpuContext, GpuRenderer, ResidentStep, StepSettings, buffers};
use gems_splat::{Camera, Gaussians, RenderSettings};
use safetensors::{Dtype, SafeTensors, tensor::TensorView};

const SIZES: [usize; 3] = [10_000, 100_000, 300_000];
const CAMERAS: usize = 15;
const WIDTH: u32 = 400;
const HEIGHT: u32 = 270;
/// What both sides train with: gems's defaults at the first step for a scene of extent 1
/// (loss weights, MCMC regularisers, learning rates, Adam), written into the inputs' metadata
/// for bench.py.
fn settings() -> StepSettings {
    gems_train::TrainConfig::default().step_settings(0, 1.0)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: side_by_side write DIR | run DIR [--out FILE] [--iters N] [--warmup N] \
                 [--sizes 10000,100000]";
    let (Some(verb), Some(dir)) = (args.first(), args.get(1)) else {
        eprintln!("{usage}");
        std::process::exit(2);
    };
    let dir = PathBuf::from(dir);
    let flag = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    let sizes: Vec<usize> = flag("--sizes").map_or(SIZES.to_vec(), |v| {
        v.split(',')
            .map(|n| n.parse().expect("--sizes N,N"))
            .collect()
    });
    let result = match verb.as_str() {
        "write" => write(&dir, &sizes),
        "run" => run(
            &dir,
            &sizes,
            &flag("--out").map_or_else(|| dir.join("gems.json"), PathBuf::from),
            flag("--iters").map_or(20, |v| v.parse().expect("--iters N")),
            flag("--warmup").map_or(3, |v| v.parse().expect("--warmup N")),
        ),
        _ => Err(usage.to_owned()),
    };
    if let Err(e) = result {
        eprintln!("side_by_side: {e}");
        std::process::exit(1);
    }
}

fn inputs(dir: &Path, n: usize) -> PathBuf {
    dir.join(format!("inputs_{n}.safetensors"))
}

/// The shared inputs: the gems-gpu render bench's random scene (gems-splat tests'
/// `random_scene`, seed 1), in gsplat's conventions (quaternions w x y z, world-to-camera 4×4
/// view matrices, OpenCV camera), with the parameters both as optimised (log scales, opacity
/// logits) and as rendered (scales, opacities).
fn write(dir: &Path, sizes: &[usize]) -> Result<(), String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    for &n in sizes {
        let (g, cams, bgs) =
            splat_common::random_scene(1, n, CAMERAS, WIDTH, HEIGHT, 3, (-4.6, -3.2));
        let flat = |v: &[[f32; 3]]| v.iter().flatten().copied().collect::<Vec<f32>>();
        let mut t: Vec<(&str, Vec<usize>, Vec<f32>)> = vec![
            ("means", vec![n, 3], flat(&g.means)),
            (
                "quats",
                vec![n, 4],
                g.quats.iter().flatten().copied().collect(),
            ),
            ("log_scales", vec![n, 3], flat(&g.log_scales)),
            (
                "scales",
                vec![n, 3],
                flat(&g.log_scales).iter().map(|v| v.exp()).collect(),
            ),
            ("opacity_logits", vec![n], g.opacity_logits.clone()),
            (
                "opacities",
                vec![n],
                g.opacity_logits
                    .iter()
                    .map(|v| 1.0 / (1.0 + (-v).exp()))
                    .collect(),
            ),
            (
                "sh",
                vec![n, 16, 3],
                g.sh.iter().flatten().flatten().copied().collect(),
            ),
            ("backgrounds", vec![CAMERAS, 3], flat(&bgs)),
        ];
        let viewmats = cams
            .iter()
            .flat_map(|c| {
                let (r, tr) = (c.rotation, c.translation);
                [
                    r[0][0], r[0][1], r[0][2], tr[0], r[1][0], r[1][1], r[1][2], tr[1], r[2][0],
                    r[2][1], r[2][2], tr[2], 0.0, 0.0, 0.0, 1.0,
                ]
            })
            .collect();
        t.push(("viewmats", vec![CAMERAS, 4, 4], viewmats));
        let ks = cams
            .iter()
            .flat_map(|c| [c.fx, 0.0, c.cx, 0.0, c.fy, c.cy, 0.0, 0.0, 1.0])
            .collect();
        t.push(("Ks", vec![CAMERAS, 3, 3], ks));
        // A smooth target: what matters for timing is its size, not its content.
        let target = (0..HEIGHT)
            .flat_map(|y| {
                (0..WIDTH).flat_map(move |x| {
                    [
                        x as f32 / WIDTH as f32,
                        y as f32 / HEIGHT as f32,
                        0.5 + 0.3 * ((x + y) as f32 * 0.05).sin(),
                    ]
                })
            })
            .collect();
        t.push(("target", vec![HEIGHT as usize, WIDTH as usize, 3], target));
        let bytes: Vec<(String, Vec<usize>, Vec<u8>)> = t
            .into_iter()
            .map(|(name, shape, v)| (name.to_owned(), shape, bytemuck::cast_slice(&v).to_vec()))
            .collect();
        let views: Vec<(String, TensorView<'_>)> = bytes
            .iter()
            .map(|(name, shape, b)| {
                TensorView::new(Dtype::F32, shape.clone(), b)
                    .map(|v| (name.clone(), v))
                    .map_err(|e| e.to_string())
            })
            .collect::<Result<_, _>>()?;
        let st = settings();
        let meta: HashMap<String, String> = [
            ("width", WIDTH.to_string()),
            ("height", HEIGHT.to_string()),
            ("sh_degree", "3".to_owned()),
            ("ssim_lambda", st.ssim_lambda.to_string()),
            ("opacity_reg", st.opacity_reg.to_string()),
            ("scale_reg", st.scale_reg.to_string()),
            ("lr_means", st.lrs.means.to_string()),
            ("lr_quats", st.lrs.quats.to_string()),
            ("lr_log_scales", st.lrs.log_scales.to_string()),
            ("lr_opacity_logits", st.lrs.opacity_logits.to_string()),
            ("lr_sh_dc", st.lrs.sh_dc.to_string()),
            ("lr_sh_rest", st.lrs.sh_rest.to_string()),
            ("adam_beta1", st.adam.beta1.to_string()),
            ("adam_beta2", st.adam.beta2.to_string()),
            ("adam_eps", st.adam.eps.to_string()),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_owned(), v))
        .collect();
        let path = inputs(dir, n);
        safetensors::serialize_to_file(views, Some(meta), &path)
            .map_err(|e| format!("{}: {e}", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// A tensor of the input file as f32 values.
fn tensor(st: &SafeTensors<'_>, name: &str) -> Result<Vec<f32>, String> {
    let t = st.tensor(name).map_err(|e| format!("{name}: {e}"))?;
    Ok(bytemuck::pod_collect_to_vec(t.data()))
}

/// One input file as gems reads it.
struct Inputs {
    gaussians: Gaussians,
    cameras: Vec<Camera>,
    backgrounds: Vec<[f32; 3]>,
    target: Vec<f32>,
}

fn read(path: &Path) -> Result<Inputs, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let st = SafeTensors::deserialize(&bytes).map_err(|e| format!("{}: {e}", path.display()))?;
    let (means, quats, ls, logits, sh) = (
        tensor(&st, "means")?,
        tensor(&st, "quats")?,
        tensor(&st, "log_scales")?,
        tensor(&st, "opacity_logits")?,
        tensor(&st, "sh")?,
    );
    let mut g = Gaussians::with_degree(3);
    for i in 0..logits.len() {
        let mut coeffs = [[0.0f32; 3]; 16];
        for (k, row) in coeffs.iter_mut().enumerate() {
            *row = [0, 1, 2].map(|c| sh[(i * 16 + k) * 3 + c]);
        }
        g.push(
            [0, 1, 2].map(|k| means[i * 3 + k]),
            [0, 1, 2, 3].map(|k| quats[i * 4 + k]),
            [0, 1, 2].map(|k| ls[i * 3 + k]),
            logits[i],
            coeffs,
        );
    }
    let (vm, ks) = (tensor(&st, "viewmats")?, tensor(&st, "Ks")?);
    let cams = (0..vm.len() / 16)
        .map(|c| {
            let m = &vm[c * 16..(c + 1) * 16];
            let k = &ks[c * 9..(c + 1) * 9];
            Camera {
                fx: k[0],
                fy: k[4],
                cx: k[2],
                cy: k[5],
                width: WIDTH,
                height: HEIGHT,
                rotation: [0, 1, 2].map(|r| [0, 1, 2].map(|cc| m[r * 4 + cc])),
                translation: [0, 1, 2].map(|r| m[r * 4 + 3]),
            }
        })
        .collect();
    let bgs = tensor(&st, "backgrounds")?
        .chunks_exact(3)
        .map(|b| [b[0], b[1], b[2]])
        .collect();
    Ok(Inputs {
        gaussians: g,
        cameras: cams,
        backgrounds: bgs,
        target: tensor(&st, "target")?,
    })
}

/// One step's GPU time per kernel (GPU timestamps around every pass), after a warm-up step.
fn profile_step(
    ctx: &GpuContext,
    g: &Gaussians,
    cams: &[Camera],
    bg: [f32; 3],
    target: &[f32],
    settings: &StepSettings,
) -> Result<gems_gpu::KernelTimes, String> {
    let ctx = ctx.with_profiler().map_err(|e| e.to_string())?;
    let mut r = GpuRenderer::new(&ctx);
    let mut step = ResidentStep::new(&ctx, g, None).map_err(|e| e.to_string())?;
    for _ in 0..2 {
        let _ = ctx.kernel_times();
        step.step(&mut r, 0, target, cams, bg, settings)
            .map_err(|e| e.to_string())?;
    }
    ctx.kernel_times()
        .expect("a profiled context")
        .map_err(|e| e.to_string())
}

/// Median milliseconds of `iters` calls of `f` after `warmup`.
fn median_ms(warmup: usize, iters: usize, mut f: impl FnMut()) -> f64 {
    for _ in 0..warmup {
        f();
    }
    let mut ms: Vec<f64> = (0..iters)
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    ms.sort_by(f64::total_cmp);
    ms[ms.len() / 2]
}

fn run(dir: &Path, sizes: &[usize], out: &Path, iters: usize, warmup: usize) -> Result<(), String> {
    let ctx: GpuContext = gems_gpu::select(DeviceChoice::Gpu)
        .map_err(|e| e.to_string())?
        .ok_or("no GPU adapter")?;
    println!("{}", ctx.adapter);
    let settings = settings();
    let s = RenderSettings::default();
    let mut rows = Vec::new();
    for &n in sizes {
        let Inputs {
            gaussians: g,
            cameras: cams,
            backgrounds: bgs,
            target,
        } = read(&inputs(dir, n))?;
        let mut r = GpuRenderer::new(&ctx);
        let mut step = ResidentStep::new(&ctx, &g, None).map_err(|e| e.to_string())?;
        let d_rgb = buffers::upload(
            &ctx,
            "dL/dRGB",
            &vec![1e-3f32; CAMERAS * (WIDTH * HEIGHT * 3) as usize],
        )
        .map_err(|e| e.to_string())?;
        let idle = |ctx: &GpuContext| buffers::wait_idle(ctx).expect("the GPU finishes");
        let forward = median_ms(warmup, iters, || {
            step.render(&mut r, &cams, &bgs, &s).expect("render");
            idle(&ctx);
        });
        let forward_backward = median_ms(warmup, iters, || {
            step.render(&mut r, &cams, &bgs, &s).expect("render");
            step.backpropagate(&mut r, &cams, &bgs, &d_rgb, &s)
                .expect("backward");
            idle(&ctx);
        });
        let bg = bgs[0];
        let step_ms = median_ms(warmup, iters, || {
            step.step(&mut r, 0, &target, &cams, bg, &settings)
                .expect("step");
        });
        let kernels = if ctx.timestamps {
            let times = profile_step(&ctx, &g, &cams, bg, &target, &settings)?;
            println!("{n} Gaussians, one step's kernels:\n{}", times.table());
            times
                .kernels
                .iter()
                .map(|k| serde_json::json!({"kernel": k.kernel, "dispatches": k.dispatches, "ms": k.seconds * 1e3}))
                .collect()
        } else {
            Vec::new()
        };
        let row = serde_json::json!({
            "n": n,
            "forward_ms": forward,
            "forward_backward_ms": forward_backward,
            "step_ms": step_ms,
            "cameras_per_call": step.max_cameras_per_call().min(CAMERAS),
            "gpu_mib": (r.allocated_bytes() + step.allocated_bytes()) >> 20,
            "step_kernels": kernels,
        });
        println!("{row}");
        rows.push(row);
    }
    let json = serde_json::json!({
        "engine": "gems",
        "adapter": ctx.adapter.to_string(),
        "cameras": CAMERAS,
        "width": WIDTH,
        "height": HEIGHT,
        "iters": iters,
        "results": rows,
    });
    std::fs::write(out, serde_json::to_string_pretty(&json).expect("JSON"))
        .map_err(|e| format!("{}: {e}", out.display()))?;
    println!("wrote {}", out.display());
    Ok(())
}
