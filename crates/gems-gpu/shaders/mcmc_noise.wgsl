// 3DGS-MCMC SGLD position noise (Kheradmand et al. 2024, Eq. 11; gsplat MCMCStrategy), the
// deterministic formula of gems-train's mcmc::apply_noise in the same f32 order:
//   mu += R S² Rᵀ eps · sigmoid(−100 (o − min_opacity)) · scale,   eps ~ N(0, I3)
// noise_philox draws eps from Philox keyed by (seed) at counter (row, step, stream tag), so the
// noise of a row depends only on (seed, step, row); noise_from_buffer takes eps from a buffer
// (tests feed it the CPU's samples).

struct NoiseUniform {
    len: u32,
    seed_lo: u32,
    seed_hi: u32,
    step_lo: u32,
    step_hi: u32,
    pad0: u32,
    scale: f32,
    min_opacity: f32,
}

@group(0) @binding(0) var<uniform> u: NoiseUniform;
@group(0) @binding(1) var<storage, read_write> means: array<f32>;
@group(0) @binding(2) var<storage, read> quats: array<f32>;
@group(0) @binding(3) var<storage, read> log_scales: array<f32>;
@group(0) @binding(4) var<storage, read> opacity_logits: array<f32>;
@group(0) @binding(5) var<storage, read> eps_in: array<f32>;

// "NOIS": separates this stream from any other use of the same seed.
const NOISE_STREAM: u32 = 0x4E4F4953u;

fn sigmoid(x: f32) -> f32 {
    return 1.0 / (1.0 + exp(-x));
}

fn apply(i: u32, eps: vec3<f32>) {
    let o = sigmoid(opacity_logits[i]);
    let gate = sigmoid(-100.0 * (o - u.min_opacity)) * u.scale;
    let q = vec4<f32>(quats[4u * i], quats[4u * i + 1u], quats[4u * i + 2u], quats[4u * i + 3u]);
    let qn = max(sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w), 1e-12);
    let w = q.x / qn;
    let x = q.y / qn;
    let y = q.z / qn;
    let z = q.w / qn;
    // Rows of R (gems-train's quat_to_rotation).
    let r0 = vec3<f32>(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y));
    let r1 = vec3<f32>(2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x));
    let r2 = vec3<f32>(2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y));
    let s2 = vec3<f32>(
        exp(2.0 * log_scales[3u * i]),
        exp(2.0 * log_scales[3u * i + 1u]),
        exp(2.0 * log_scales[3u * i + 2u]),
    );
    // Rᵀ eps, summed left to right as the CPU does.
    let rt = vec3<f32>(
        r0.x * eps.x + r1.x * eps.y + r2.x * eps.z,
        r0.y * eps.x + r1.y * eps.y + r2.y * eps.z,
        r0.z * eps.x + r1.z * eps.y + r2.z * eps.z,
    );
    let sc = s2 * rt;
    let d = vec3<f32>(
        r0.x * sc.x + r0.y * sc.y + r0.z * sc.z,
        r1.x * sc.x + r1.y * sc.y + r1.z * sc.z,
        r2.x * sc.x + r2.y * sc.y + r2.z * sc.z,
    );
    means[3u * i] += gate * d.x;
    means[3u * i + 1u] += gate * d.y;
    means[3u * i + 2u] += gate * d.z;
}

@compute @workgroup_size(256)
fn noise_philox(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let i = flat_index(wg, nwg, lid);
    if i >= u.len {
        return;
    }
    let eps = normal3(vec4<u32>(i, u.step_lo, u.step_hi, NOISE_STREAM), vec2<u32>(u.seed_lo, u.seed_hi));
    apply(i, eps);
}

@compute @workgroup_size(256)
fn noise_from_buffer(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let i = flat_index(wg, nwg, lid);
    if i >= u.len {
        return;
    }
    apply(i, vec3<f32>(eps_in[3u * i], eps_in[3u * i + 1u], eps_in[3u * i + 2u]));
}
