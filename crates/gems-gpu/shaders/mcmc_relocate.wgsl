// 3DGS-MCMC relocation and growth (Kheradmand et al. 2024, Eq. 9; gsplat MCMCStrategy), applied
// to resident Gaussians once the CPU has drawn which rows to copy:
//   split_sources  each distinct source row with copy count n (its draws + 1, clamped to
//                  [1, 51]): o' = 1 − (1 − o)^(1/n), s' = s·o/D with
//                  D = Σ_{i=1..n} Σ_{k=0..i−1} C(i−1,k) (−1)^k o'^(k+1) / sqrt(k+1)
//                  (the binomial table), then o' clamped to [min_opacity, 1 − ε_f32] (gsplat
//                  ≤ 1.5.3 clamps after s'). As gems-train's compute_relocation but in f32, as
//                  gsplat's CUDA relocation kernel; o' uses expm1/log1p forms (series near
//                  zero) to stay accurate for small o.
//   copy_rows      parameter row src → dst for (dst, src) pairs; optionally zeroes dst moments
//   zero_rows      zeroes the Adam moments of the listed rows

struct SplitUniform {
    count: u32,
    pad0: u32,
    min_opacity: f32,
    one_minus_eps: f32,
}

struct RowsUniform {
    count: u32,
    width: u32,
    zero_dst: u32,
    pad0: u32,
}

@group(0) @binding(0) var<uniform> su: SplitUniform;
@group(0) @binding(1) var<storage, read> rows: array<u32>;
@group(0) @binding(2) var<storage, read> counts: array<u32>;
@group(0) @binding(3) var<storage, read> binoms: array<f32>;
@group(0) @binding(4) var<storage, read_write> opacity_logits: array<f32>;
@group(0) @binding(5) var<storage, read_write> log_scales: array<f32>;

@group(0) @binding(6) var<uniform> ru: RowsUniform;
@group(0) @binding(7) var<storage, read> pairs: array<u32>;
@group(0) @binding(8) var<storage, read_write> param: array<f32>;
@group(0) @binding(9) var<storage, read_write> m1: array<f32>;
@group(0) @binding(10) var<storage, read_write> m2: array<f32>;

const N_MAX: u32 = 51u;

// log(1 + x) and exp(y) − 1 to a few ulps of the result on any Vulkan driver. The tricks that
// correct log(1 + x) and exp(y) − 1 with one more log (Goldberg 1991; Kahan) need a log whose
// error is relative, but Vulkan bounds log only to an absolute 2^−21 on [0.5, 2] (Vulkan spec,
// "Precision and Operation of SPIR-V Instructions"): for 1 + x near 1 that is a relative error
// of 2^−21/|x|, 1e-4 at x = −0.005 (the smallest opacity), seen on an NVIDIA H100. Near zero
// both functions are therefore their series, which only add and multiply; elsewhere the result
// is far enough from zero for log and exp to be accurate.

// log(1 + x) = 2·atanh(z), z = x/(2 + x); for x in [−0.5, 1], |z| ≤ 1/3 and the odd series
// Σ z^(2k+1)/(2k+1) to k = 9 leaves (1/9)^10/21 < 1e-10 relative.
fn log1p_acc(x: f32) -> f32 {
    if x < -0.5 || x > 1.0 {
        // 1 + x is exact for x in [−1, −0.5] (Sterbenz) and lies outside [0.5, 2].
        return log(1.0 + x);
    }
    let z = x / (2.0 + x);
    let z2 = z * z;
    var s = 1.0 / 19.0;
    for (var k = 8; k >= 0; k--) {
        s = s * z2 + 1.0 / f32(2 * k + 1);
    }
    return 2.0 * z * s;
}

// exp(y) − 1: for |y| ≤ 0.5 the Taylor series to y^11/11! (remainder < 0.5^12/12! < 1e-10
// relative), else exp(y) − 1, which is at least 0.39 in magnitude there.
fn expm1_acc(y: f32) -> f32 {
    if abs(y) > 0.5 {
        return exp(y) - 1.0;
    }
    var s = 1.0;
    for (var k = 11; k >= 2; k--) {
        s = 1.0 + s * y / f32(k);
    }
    return y * s;
}

@compute @workgroup_size(256)
fn split_sources(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let j = flat_index(wg, nwg, lid);
    if j >= su.count {
        return;
    }
    let row = rows[j];
    let n = clamp(counts[j], 1u, N_MAX);
    let o = 1.0 / (1.0 + exp(-opacity_logits[row]));
    let o_new = -expm1_acc(log1p_acc(-o) / f32(n));
    var denom = 0.0;
    for (var i = 1u; i <= n; i++) {
        var p = o_new;
        for (var k = 0u; k < i; k++) {
            let sgn = select(-1.0, 1.0, k % 2u == 0u);
            denom += binoms[(i - 1u) * N_MAX + k] * sgn * p / sqrt(f32(k + 1u));
            p *= o_new;
        }
    }
    let ratio = o / denom;
    for (var a = 0u; a < 3u; a++) {
        log_scales[3u * row + a] = log(exp(log_scales[3u * row + a]) * ratio);
    }
    let oc = clamp(o_new, su.min_opacity, su.one_minus_eps);
    opacity_logits[row] = log(oc / (1.0 - oc));
}

@compute @workgroup_size(256)
fn copy_rows(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    // One invocation per (pair, column).
    let t = flat_index(wg, nwg, lid);
    if t >= ru.count * ru.width {
        return;
    }
    let pair = t / ru.width;
    let col = t % ru.width;
    let dst = pairs[2u * pair] * ru.width + col;
    let src = pairs[2u * pair + 1u] * ru.width + col;
    param[dst] = param[src];
    if ru.zero_dst != 0u {
        m1[dst] = 0.0;
        m2[dst] = 0.0;
    }
}

@compute @workgroup_size(256)
fn zero_rows(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let t = flat_index(wg, nwg, lid);
    if t >= ru.count * ru.width {
        return;
    }
    let i = pairs[t / ru.width] * ru.width + t % ru.width;
    m1[i] = 0.0;
    m2[i] = 0.0;
}
