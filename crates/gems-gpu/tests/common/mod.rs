//! Shared by the GPU kernel tests: one device per test binary, deterministic test data.
#![allow(dead_code)]

use std::sync::OnceLock;

use gems_gpu::GpuContext;

/// The device every test of the binary runs on. There is no silent skip: without an adapter
/// the tests fail and say what to install.
pub fn ctx() -> &'static GpuContext {
    static CTX: OnceLock<GpuContext> = OnceLock::new();
    CTX.get_or_init(|| {
        let ctx = GpuContext::new().unwrap_or_else(|e| {
            panic!(
                "no GPU adapter for the GPU tests ({e}); install mesa-vulkan-drivers (lavapipe) \
                 and run with WGPU_BACKEND=vulkan"
            )
        });
        eprintln!("GPU tests on {}", ctx.adapter);
        ctx
    })
}

/// `count` values in [lo, hi) from a 64-bit LCG keyed by `seed`.
pub fn values(count: usize, seed: u64, lo: f32, hi: f32) -> Vec<f32> {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15).wrapping_add(1);
    (0..count)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            lo + (hi - lo) * ((s >> 40) as f32 / (1u64 << 24) as f32)
        })
        .collect()
}

/// A smooth image pattern plus noise in [0, 1], `[H,W,3]`, like a real render/target pair.
pub fn image(h: usize, w: usize, seed: u64) -> Vec<f32> {
    let noise = values(h * w * 3, seed, -0.1, 0.1);
    (0..h * w * 3)
        .map(|i| {
            let base = 0.5 + 0.3 * ((i / 3) as f32 * 0.07 + seed as f32).sin();
            (base + noise[i]).clamp(0.0, 1.0)
        })
        .collect()
}

/// Largest |a − b| over two equal-length slices.
pub fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()))
}

pub fn max_abs(a: &[f32]) -> f32 {
    a.iter().fold(0.0f32, |m, x| m.max(x.abs()))
}

/// The reference pairs of testdata/metrics (repository root).
pub const PAIRS: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../testdata/metrics/metrics_pairs.safetensors"
);

pub struct Pair {
    pub height: usize,
    pub width: usize,
    pub render: Vec<f32>,
    pub target: Vec<f32>,
    pub grad_ssim_valid: Vec<f64>,
    pub ssim_valid: f64,
}

/// Pair `name` ("small", "wide") with its SSIM-valid value and gradient.
pub fn load_pair(name: &str) -> Pair {
    let bytes = std::fs::read(PAIRS).unwrap();
    let (_, meta) = safetensors::SafeTensors::read_metadata(&bytes).unwrap();
    let ssim_valid = meta.metadata().as_ref().unwrap()[&format!("{name}_ssim_valid")]
        .parse()
        .unwrap();
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let get = |k: &str| -> (Vec<usize>, Vec<f64>) {
        let t = st.tensor(&format!("{name}_{k}")).unwrap();
        assert_eq!(t.dtype(), safetensors::Dtype::F64);
        let v = t
            .data()
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect();
        (t.shape().to_vec(), v)
    };
    let (shape, render) = get("render");
    let to32 = |v: Vec<f64>| v.into_iter().map(|x| x as f32).collect();
    Pair {
        height: shape[0],
        width: shape[1],
        render: to32(render),
        target: to32(get("target").1),
        grad_ssim_valid: get("grad_ssim_valid_wrt_render").1,
        ssim_valid,
    }
}

/// `n` random Gaussians (degree 3) with opacities spread over (sigmoid(−7), sigmoid(4)).
pub fn gaussians(n: usize, seed: u64) -> gems_splat::Gaussians {
    let v = values(n * 59, seed, 0.0, 1.0);
    let mut g = gems_splat::Gaussians::with_degree(3);
    for r in v.chunks_exact(59) {
        let sh: [[f32; 3]; 16] =
            std::array::from_fn(|k| std::array::from_fn(|c| r[11 + 3 * k + c] - 0.5));
        g.push(
            [r[0] * 4.0 - 2.0, r[1] * 4.0 - 2.0, r[2] * 4.0 + 1.0],
            [r[3] + 0.1, r[4] - 0.5, r[5] - 0.5, r[6] - 0.5],
            [r[7] * 3.0 - 5.0, r[8] * 3.0 - 5.0, r[9] * 3.0 - 5.0],
            r[10] * 11.0 - 7.0,
            sh,
        );
    }
    g
}

/// Largest |a − b| in units of f32 rounding of each element's own scale: max |a_i − b_i| /
/// (ε_f32 · scale_i), 0 where the two are equal and infinite where they differ on a zero scale.
///
/// Units in the last place of the results would be the wrong yardstick for a GPU: Vulkan lets
/// a driver fuse `a·b + c` into one FMA (naga marks no SPIR-V `NoContraction`) and bounds
/// division to 2.5 ulp and `inversesqrt` to 2 ulp (Vulkan spec, "Precision and Operation of
/// SPIR-V Instructions"), so the rounding of each step moves by a few ulps of the *terms*; a
/// result that cancels to near zero (p − update, β1·m + (1 − β1)·g) then sits arbitrarily many
/// of its own ulps away although both computations are equally right. lavapipe rounds every
/// operation correctly and never fuses, which hid this until the tests ran on an NVIDIA H100.
pub fn max_rounding_err(a: &[f32], b: &[f32], scale: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len());
    assert_eq!(a.len(), scale.len());
    a.iter()
        .zip(b)
        .zip(scale)
        .map(|((&x, &y), &s)| {
            let d = (f64::from(x) - f64::from(y)).abs();
            if d == 0.0 {
                0.0
            } else {
                d / (f64::from(f32::EPSILON) * f64::from(s))
            }
        })
        .fold(0.0, f64::max)
}
