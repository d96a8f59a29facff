// Backward half of the fused training loss: the adjoint of the two separable window passes
// (the window is symmetric, so its adjoint is itself with zero padding), then
//   dL/d(blurred) = (1 - lambda) * sign(blurred - target) / len - lambda * dSSIM/d(blurred)
//   dL/d(render_k) = dL/d(blurred) / n   for each of the n virtual renders (GeMS Eq. 1).
// Same summation order as gems-metrics' CPU backward. back is [ch][row][3][kept col].

@group(0) @binding(2) var<storage, read> tgt: array<f32>;
@group(0) @binding(3) var<storage, read> blurred: array<f32>;
@group(0) @binding(5) var<storage, read> dmap: array<f32>;
@group(0) @binding(7) var<storage, read_write> back: array<f32>;
@group(0) @binding(8) var<storage, read_write> d_blurred: array<f32>;
@group(0) @binding(9) var<storage, read_write> d_renders: array<f32>;

@compute @workgroup_size(256)
fn ssim_back_vert(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let t = flat_index(wg, nwg, lid);
    let per_ch = dims.h * dims.wi;
    if t >= 3u * per_ch {
        return;
    }
    let ch = t / per_ch;
    let q = (t % per_ch) / dims.wi;
    let c = t % dims.wi;
    let wi = dims.wi;
    // Kept row p (full row p + 5) saw input row q with tap q - p.
    let p_lo = select(0u, q - 10u, q >= 10u);
    let p_hi = min(q, dims.hi - 1u);
    var a0 = 0.0;
    var a1 = 0.0;
    var a2 = 0.0;
    for (var p = p_lo; p <= p_hi; p++) {
        let gk = GWIN[q - p];
        let base = (ch * dims.hi + p) * 3u * wi + c;
        a0 += gk * dmap[base];
        a1 += gk * dmap[base + wi];
        a2 += gk * dmap[base + 2u * wi];
    }
    let out = (ch * dims.h + q) * 3u * wi + c;
    back[out] = a0;
    back[out + wi] = a1;
    back[out + 2u * wi] = a2;
}

@compute @workgroup_size(256)
fn loss_grad(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let i = flat_index(wg, nwg, lid);
    if i >= dims.len {
        return;
    }
    let ch = i % 3u;
    let pix = i / 3u;
    let q = pix / dims.w;
    let c = pix % dims.w;
    let wi = dims.wi;
    // Kept column c - k saw input column c with tap k.
    var a0 = 0.0;
    var a1 = 0.0;
    var a2 = 0.0;
    let row = (ch * dims.h + q) * 3u * wi;
    for (var k = 0u; k < 11u; k++) {
        if c >= k && c - k < wi {
            let gk = GWIN[k];
            let base = row + c - k;
            a0 += gk * back[base];
            a1 += gk * back[base + wi];
            a2 += gk * back[base + 2u * wi];
        }
    }
    let x = blurred[i];
    let y = tgt[i];
    let gs = a0 + 2.0 * x * a1 + y * a2;
    let diff = x - y;
    // torch.sign(0) = 0: no L1 push where render and target are equal.
    let sgn = select(select(0.0, -1.0, diff < 0.0), 1.0, diff > 0.0);
    let lam = dims.lambda;
    let dl = (1.0 - lam) * sgn * dims.inv_len - lam * gs;
    d_blurred[i] = dl;
    let dr = dl * dims.inv_views;
    for (var k = 0u; k < dims.views; k++) {
        d_renders[k * dims.len + i] = dr;
    }
}
