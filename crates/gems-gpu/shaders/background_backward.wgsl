// dL/d background per camera: Σ over pixels of dL/dRGB · T_final; one workgroup per camera,
// fixed strided assignment and tree.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> d_rgb: array<f32>;
@group(0) @binding(2) var<storage, read> aux: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> bg_grads: array<f32>;

var<workgroup> part: array<vec3<f32>, 256>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let c = wid.x;
    let hw = params.width * params.height;
    var acc = vec3<f32>(0.0);
    for (var p = lid; p < hw; p += 256u) {
        let pix = c * hw + p;
        let v = vec3<f32>(d_rgb[pix * 3u], d_rgb[pix * 3u + 1u], d_rgb[pix * 3u + 2u]);
        acc += v * aux[pix].z;
    }
    part[lid] = acc;
    for (var half = 128u; half > 0u; half >>= 1u) {
        workgroupBarrier();
        if lid < half {
            part[lid] += part[lid + half];
        }
    }
    workgroupBarrier();
    if lid == 0u {
        bg_grads[c * 3u] = part[0].x;
        bg_grads[c * 3u + 1u] = part[0].y;
        bg_grads[c * 3u + 2u] = part[0].z;
    }
}
