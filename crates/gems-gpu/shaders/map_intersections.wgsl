// One sort entry per (camera, Gaussian, overlapped tile), written at the Gaussian's prefix-sum
// offset in tile order (row by row): key = (camera·tiles + tile, depth bits), value = the
// entry's own index, and the (camera, Gaussian) it belongs to.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> splats: array<Splat>;
@group(0) @binding(2) var<storage, read> offsets: array<u32>;
@group(0) @binding(3) var<storage, read_write> key_lo: array<u32>;
@group(0) @binding(4) var<storage, read_write> key_hi: array<u32>;
@group(0) @binding(5) var<storage, read_write> vals: array<u32>;
@group(0) @binding(6) var<storage, read_write> owner: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let idx = group_index(wid, nwg) * 256u + lid;
    if idx >= params.n {
        return;
    }
    var o = offsets[idx];
    let end = offsets[idx + 1u];
    if o == end {
        return;
    }
    let sp = splats[idx];
    let c = idx / params.num_gaussians;
    let tiles = params.tiles_x * params.tiles_y;
    // Depth > near plane > 0: the bit pattern orders like the value.
    let depth_bits = bitcast<u32>(sp.xyod.w);
    let tx0 = u32(sp.pbox.x) / 16u;
    let tx1 = u32(sp.pbox.y) / 16u;
    let ty0 = u32(sp.pbox.z) / 16u;
    let ty1 = u32(sp.pbox.w) / 16u;
    for (var ty = ty0; ty <= ty1; ty++) {
        for (var tx = tx0; tx <= tx1; tx++) {
            key_lo[o] = depth_bits;
            key_hi[o] = c * tiles + ty * params.tiles_x + tx;
            vals[o] = o;
            owner[o] = idx;
            o++;
        }
    }
}
