// After the sort: each (camera, tile)'s run [start, end) in the sorted entries, the splat of
// each sorted entry, and where each unsorted entry went (for the backward's per-Gaussian sums).

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> key_hi: array<u32>;
@group(0) @binding(2) var<storage, read> vals: array<u32>;
@group(0) @binding(3) var<storage, read> owner: array<u32>;
@group(0) @binding(4) var<storage, read_write> ranges: array<vec2<u32>>;
@group(0) @binding(5) var<storage, read_write> sorted_splat: array<u32>;
@group(0) @binding(6) var<storage, read_write> sorted_pos: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let k = group_index(wid, nwg) * 256u + lid;
    let total = params.n;
    if k >= total {
        return;
    }
    let t = key_hi[k];
    if k == 0u || key_hi[k - 1u] != t {
        ranges[t].x = k;
    }
    if k + 1u == total || key_hi[k + 1u] != t {
        ranges[t].y = k + 1u;
    }
    let o = vals[k];
    sorted_splat[k] = owner[o];
    sorted_pos[o] = k;
}
