// Blur mean (GeMS Eq. 1) and the forward half of the fused training loss
// (1 - lambda) * L1 + lambda * (1 - SSIM_valid), mirroring gems-metrics' separable f32 SSIM
// pass by pass and in the same summation order:
//   blur_mean    blurred = mean of the n virtual renders
//   ssim_horiz   5 moments (x, y, x², y², xy) of the 11-tap window along rows
//   ssim_map     the same along columns, the SSIM of each kept pixel and dS/d(mu_x, Sxx, Sxy)
//   reduce_*     L1, squared clamped error (PSNR) and SSIM sums: fixed-order workgroup trees,
//                so the scalars are the same from run to run on one device.
// Planar scratch layouts: horiz [ch][row][moment][kept col], dmap [ch][kept row][3][kept col].

@group(0) @binding(1) var<storage, read> renders: array<f32>;
@group(0) @binding(2) var<storage, read> tgt: array<f32>;
@group(0) @binding(3) var<storage, read_write> blurred: array<f32>;
@group(0) @binding(4) var<storage, read_write> horiz: array<f32>;
@group(0) @binding(5) var<storage, read_write> dmap: array<f32>;
@group(0) @binding(6) var<storage, read_write> ssim_map: array<f32>;
@group(0) @binding(10) var<storage, read_write> partials: array<f32>;
@group(0) @binding(11) var<storage, read_write> scalars: array<f32>;

@compute @workgroup_size(256)
fn blur_mean(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let i = flat_index(wg, nwg, lid);
    if i >= dims.len {
        return;
    }
    var acc = 0.0;
    for (var k = 0u; k < dims.views; k++) {
        acc += renders[k * dims.len + i] * dims.inv_views;
    }
    blurred[i] = acc;
}

@compute @workgroup_size(256)
fn ssim_horiz(
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
    let r = (t % per_ch) / dims.wi;
    let c = t % dims.wi;
    var o0 = 0.0;
    var o1 = 0.0;
    var o2 = 0.0;
    var o3 = 0.0;
    var o4 = 0.0;
    for (var k = 0u; k < 11u; k++) {
        let i = (r * dims.w + c + k) * 3u + ch;
        let xv = blurred[i];
        let yv = tgt[i];
        let gk = GWIN[k];
        let gx = gk * xv;
        let gy = gk * yv;
        o0 += gx;
        o1 += gy;
        o2 += gx * xv;
        o3 += gy * yv;
        o4 += gx * yv;
    }
    let base = (ch * dims.h + r) * 5u * dims.wi + c;
    horiz[base] = o0;
    horiz[base + dims.wi] = o1;
    horiz[base + 2u * dims.wi] = o2;
    horiz[base + 3u * dims.wi] = o3;
    horiz[base + 4u * dims.wi] = o4;
}

@compute @workgroup_size(256)
fn ssim_map_pass(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let t = flat_index(wg, nwg, lid);
    let per_ch = dims.hi * dims.wi;
    if t >= 3u * per_ch {
        return;
    }
    let ch = t / per_ch;
    let r = (t % per_ch) / dims.wi;
    let c = t % dims.wi;
    let wi = dims.wi;
    var mx = 0.0;
    var my = 0.0;
    var sxx = 0.0;
    var syy = 0.0;
    var sxy = 0.0;
    for (var k = 0u; k < 11u; k++) {
        let gk = GWIN[k];
        let base = (ch * dims.h + r + k) * 5u * wi + c;
        mx += gk * horiz[base];
        my += gk * horiz[base + wi];
        sxx += gk * horiz[base + 2u * wi];
        syy += gk * horiz[base + 3u * wi];
        sxy += gk * horiz[base + 4u * wi];
    }
    let a = 2.0 * mx * my + C1;
    let b = 2.0 * (sxy - mx * my) + C2;
    let cc = mx * mx + my * my + C1;
    let d = (sxx - mx * mx) + (syy - my * my) + C2;
    let cd = cc * d;
    let s = a * b / cd;
    ssim_map[t] = s;
    let scale = dims.ssim_scale;
    let out = (ch * dims.hi + r) * 3u * wi + c;
    dmap[out] = scale * (2.0 * my * (b - a) / cd - 2.0 * mx * s * (1.0 / cc - 1.0 / d));
    dmap[out + wi] = scale * (-s / d);
    dmap[out + 2u * wi] = scale * (2.0 * a / cd);
}

// Values summed per thread before the workgroup tree (2048 per workgroup).
const ITEMS: u32 = 8u;

var<workgroup> red: array<vec3<f32>, 256>;

fn tree_sum(lid: u32) {
    for (var off = 128u; off > 0u; off >>= 1u) {
        if lid < off {
            red[lid] += red[lid + off];
        }
        workgroupBarrier();
    }
}

@compute @workgroup_size(256)
fn reduce_partial(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let g = wg.y * nwg.x + wg.x;
    if g >= dims.n_partials {
        return;
    }
    let start = g * 256u * ITEMS;
    var s = vec3<f32>(0.0);
    for (var j = 0u; j < ITEMS; j++) {
        let i = start + j * 256u + lid;
        if i < dims.len {
            let b = blurred[i];
            let y = tgt[i];
            s.x += abs(b - y);
            let dc = clamp(b, 0.0, 1.0) - clamp(y, 0.0, 1.0);
            s.y += dc * dc;
        }
        if i < dims.ssim_len {
            s.z += ssim_map[i];
        }
    }
    red[lid] = s;
    workgroupBarrier();
    tree_sum(lid);
    if lid == 0u {
        partials[3u * g] = red[0].x;
        partials[3u * g + 1u] = red[0].y;
        partials[3u * g + 2u] = red[0].z;
    }
}

@compute @workgroup_size(256)
fn reduce_final(@builtin(local_invocation_index) lid: u32) {
    var s = vec3<f32>(0.0);
    for (var i = lid; i < dims.n_partials; i += 256u) {
        s += vec3<f32>(partials[3u * i], partials[3u * i + 1u], partials[3u * i + 2u]);
    }
    red[lid] = s;
    workgroupBarrier();
    tree_sum(lid);
    if lid == 0u {
        let l1 = red[0].x / f32(dims.len);
        let ssim = red[0].z / f32(dims.ssim_len);
        let mse = red[0].y / f32(dims.len);
        scalars[0] = (1.0 - dims.lambda) * l1 + dims.lambda * (1.0 - ssim);
        scalars[1] = l1;
        scalars[2] = ssim;
        // PSNR with data range 1: -10 log10(mse), log10 x = log2 x * log10 2.
        scalars[3] = -10.0 * log2(max(mse, 1e-20)) * 0.30102999566398120;
    }
}
