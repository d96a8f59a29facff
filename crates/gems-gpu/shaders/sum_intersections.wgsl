// Per (camera, Gaussian): the sum of its tile entries' screen-space gradients, in tile order
// (the order the CPU engine sums them in).

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> offsets: array<u32>;
@group(0) @binding(2) var<storage, read> sorted_pos: array<u32>;
@group(0) @binding(3) var<storage, read> entry_grads: array<f32>;
@group(0) @binding(4) var<storage, read_write> splat_grads: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let idx = group_index(wid, nwg) * 256u + lid;
    if idx >= params.n {
        return;
    }
    var acc: array<f32, SG>;
    for (var o = offsets[idx]; o < offsets[idx + 1u]; o++) {
        let k = sorted_pos[o] * SG;
        for (var q = 0u; q < SG; q++) {
            acc[q] += entry_grads[k + q];
        }
    }
    for (var q = 0u; q < SG; q++) {
        splat_grads[idx * SG + q] = acc[q];
    }
}
