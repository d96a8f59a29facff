// Radix sort, pass 2 of 2: each key moves to its digit's slot for its block plus its rank
// among the earlier keys of the block with the same digit, so the sort is stable (an LSD radix
// sort needs that: later passes keep the order of the earlier ones among equal digits).

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> lo_in: array<u32>;
@group(0) @binding(2) var<storage, read> hi_in: array<u32>;
@group(0) @binding(3) var<storage, read> vals_in: array<u32>;
@group(0) @binding(4) var<storage, read_write> lo_out: array<u32>;
@group(0) @binding(5) var<storage, read_write> hi_out: array<u32>;
@group(0) @binding(6) var<storage, read_write> vals_out: array<u32>;
@group(0) @binding(7) var<storage, read> slots: array<u32>;

var<workgroup> digits: array<u32, 256>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let block = group_index(wid, nwg);
    if block >= params.num_blocks {
        return;
    }
    let idx = block * 256u + lid;
    let live = idx < params.n;
    var lo = 0u;
    var hi = 0u;
    // 256 never matches a digit: out-of-range slots rank nothing.
    var d = 256u;
    if live {
        lo = lo_in[idx];
        hi = hi_in[idx];
        var key = lo;
        if params.use_hi != 0u {
            key = hi;
        }
        d = (key >> params.shift) & 255u;
    }
    digits[lid] = d;
    workgroupBarrier();
    if !live {
        return;
    }
    var rank = 0u;
    for (var j = 0u; j < lid; j++) {
        rank += select(0u, 1u, digits[j] == d);
    }
    let dst = slots[d * params.num_blocks + block] + rank;
    lo_out[dst] = lo;
    hi_out[dst] = hi;
    vals_out[dst] = vals_in[idx];
}
