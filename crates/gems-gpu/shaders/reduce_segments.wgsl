// Sums `params.num_blocks` segments of `params.seg_len` rows of `params.seg_width` (≤ 14)
// floats: one workgroup per segment, a fixed strided assignment of rows to invocations and a
// fixed tree, so the result does not depend on scheduling. Used for the per-camera pose
// and focal gradients (rows = Gaussians).

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> rows_in: array<f32>;
@group(0) @binding(2) var<storage, read_write> sums: array<f32>;

var<workgroup> part: array<array<f32, 256>, 14>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let seg = group_index(wid, nwg);
    if seg >= params.num_blocks {
        return;
    }
    let width = params.seg_width;
    var acc: array<f32, 14>;
    for (var r = lid; r < params.seg_len; r += 256u) {
        let base = (seg * params.seg_len + r) * width;
        for (var q = 0u; q < width; q++) {
            acc[q] += rows_in[base + q];
        }
    }
    for (var q = 0u; q < 14u; q++) {
        part[q][lid] = acc[q];
    }
    for (var half = 128u; half > 0u; half >>= 1u) {
        workgroupBarrier();
        if lid < half {
            for (var q = 0u; q < 14u; q++) {
                part[q][lid] += part[q][lid + half];
            }
        }
    }
    workgroupBarrier();
    if lid < width {
        sums[seg * width + lid] = part[lid][0];
    }
}
