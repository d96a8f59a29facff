// The 3DGS-MCMC regularisers (Kheradmand et al. 2024, Sec. 4.2; gsplat's "mcmc" preset) as
// gems-train's trainer adds them to the loss:
//   R = opacity_reg · mean_i sigmoid(l_i) + scale_reg · mean_{i,a} exp(ls_ia)
// reg_grad adds dR/dl and dR/dls to the gradients in place (the CPU's f32 formulas) and writes
// per-workgroup partial sums; reg_final sums them in a fixed order into R.

struct RegUniform {
    n: u32,
    n_partials: u32,
    opacity_reg: f32,
    scale_reg: f32,
}

@group(0) @binding(0) var<uniform> u: RegUniform;
@group(0) @binding(1) var<storage, read> opacity_logits: array<f32>;
@group(0) @binding(2) var<storage, read> log_scales: array<f32>;
@group(0) @binding(3) var<storage, read_write> grad_opacity: array<f32>;
@group(0) @binding(4) var<storage, read_write> grad_log_scales: array<f32>;
@group(0) @binding(5) var<storage, read_write> partials: array<f32>;
@group(0) @binding(6) var<storage, read_write> value: array<f32>;

var<workgroup> red: array<vec2<f32>, 256>;

fn tree_sum(lid: u32) {
    for (var off = 128u; off > 0u; off >>= 1u) {
        if lid < off {
            red[lid] += red[lid + off];
        }
        workgroupBarrier();
    }
}

@compute @workgroup_size(256)
fn reg_grad(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let g = wg.y * nwg.x + wg.x;
    if g >= u.n_partials {
        return;
    }
    let i = g * 256u + lid;
    var s = vec2<f32>(0.0);
    if i < u.n {
        let n = f32(u.n);
        let o = 1.0 / (1.0 + exp(-opacity_logits[i]));
        grad_opacity[i] += u.opacity_reg * o * (1.0 - o) / n;
        s.x = u.opacity_reg * o;
        for (var a = 0u; a < 3u; a++) {
            let e = exp(log_scales[3u * i + a]);
            grad_log_scales[3u * i + a] += u.scale_reg * e / (3.0 * n);
            s.y += u.scale_reg * e;
        }
    }
    red[lid] = s;
    workgroupBarrier();
    tree_sum(lid);
    if lid == 0u {
        partials[2u * g] = red[0].x;
        partials[2u * g + 1u] = red[0].y;
    }
}

@compute @workgroup_size(256)
fn reg_final(@builtin(local_invocation_index) lid: u32) {
    var s = vec2<f32>(0.0);
    for (var k = lid; k < u.n_partials; k += 256u) {
        s += vec2<f32>(partials[2u * k], partials[2u * k + 1u]);
    }
    red[lid] = s;
    workgroupBarrier();
    tree_sum(lid);
    if lid == 0u {
        let n = f32(u.n);
        value[0] = red[0].x / n + red[0].y / (3.0 * n);
    }
}
