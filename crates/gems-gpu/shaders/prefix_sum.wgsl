// Exclusive prefix sum of u32, in blocks of 256: `scan_blocks` scans each block in workgroup
// memory and writes the block's total; the host scans those totals the same way (recursively)
// and `add_offsets` adds each block's scanned total back.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read_write> data: array<u32>;
@group(0) @binding(2) var<storage, read_write> block_sums: array<u32>;

var<workgroup> tmp: array<u32, 256>;

@compute @workgroup_size(256)
fn scan_blocks(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
               @builtin(local_invocation_index) lid: u32) {
    let block = group_index(wid, nwg);
    if block >= params.num_blocks {
        return;
    }
    let idx = block * 256u + lid;
    var v = 0u;
    if idx < params.n {
        v = data[idx];
    }
    tmp[lid] = v;
    // Hillis–Steele inclusive scan.
    for (var off = 1u; off < 256u; off <<= 1u) {
        workgroupBarrier();
        var add = 0u;
        if lid >= off {
            add = tmp[lid - off];
        }
        workgroupBarrier();
        tmp[lid] += add;
    }
    workgroupBarrier();
    if idx < params.n {
        data[idx] = tmp[lid] - v;
    }
    if lid == 255u {
        block_sums[block] = tmp[255];
    }
}

@compute @workgroup_size(256)
fn add_offsets(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
               @builtin(local_invocation_index) lid: u32) {
    let block = group_index(wid, nwg);
    let idx = block * 256u + lid;
    if idx < params.n {
        data[idx] += block_sums[block];
    }
}
