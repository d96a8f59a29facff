// Radix sort, pass 1 of 2: per block of 256 keys, the count of each 8-bit digit, stored
// digit-major (`counts[digit · blocks + block]`) so that one exclusive prefix sum over it gives
// every block's first output slot per digit.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> keys: array<u32>;
@group(0) @binding(2) var<storage, read_write> counts: array<u32>;

var<workgroup> hist: array<atomic<u32>, 256>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let block = group_index(wid, nwg);
    if block >= params.num_blocks {
        return;
    }
    atomicStore(&hist[lid], 0u);
    workgroupBarrier();
    let idx = block * 256u + lid;
    if idx < params.n {
        atomicAdd(&hist[(keys[idx] >> params.shift) & 255u], 1u);
    }
    workgroupBarrier();
    counts[lid * params.num_blocks + block] = atomicLoad(&hist[lid]);
}
