// Per (camera, tile) workgroup, one pixel per invocation: the backward rasterizer of
// rasterize_backward.wgsl with the per-entry reduction done by subgroup adds. Each subgroup sums
// an entry's screen-space gradient over its pixels with `subgroupAdd`, and its first invocation
// parks the sum in workgroup memory; every FLUSH entries one barrier lets FLUSH·SG invocations
// add the subgroups' sums in subgroup order and write each entry's gradient once to its own
// slot. No atomics and a fixed order on a given adapter, hence reproducible results, with about
// 2/FLUSH barriers per entry instead of three (the workgroup-memory tree of
// rasterize_backward.wgsl serialises 2·16·SG adds per entry). gsplat likewise sums over each
// warp first (`warpSum` in gsplat/cuda/include/Utils.cuh, used by
// gsplat/cuda/csrc/RasterizeToPixels3DGSBwd.cu), then adds the warps' sums with atomics.
//
// Needs `Features::SUBGROUP` and subgroups of at least 256 / MAX_SUBGROUPS invocations
// (`GpuContext::subgroups`).

// Entries whose subgroup sums wait in workgroup memory before one barrier adds them up.
const FLUSH: u32 = 8u;
// Subgroups per workgroup of 256 with the smallest subgroup this kernel accepts (8).
const MAX_SUBGROUPS: u32 = 32u;

// [entry of the flush group][gradient component][subgroup]: 8·9·32·4 = 9216 bytes.
var<workgroup> parked: array<f32, 2304>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32,
        @builtin(subgroup_id) subgroup: u32,
        @builtin(num_subgroups) num_subgroups: u32,
        @builtin(subgroup_invocation_id) lane: u32) {
    // One workgroup per (camera, tile); the dispatch may round up.
    let gt = group_index(wid, nwg);
    if gt >= params.num_cameras * params.tiles_x * params.tiles_y {
        return;
    }
    let tp = tile_pixel(params, gt, lid);
    var replay = pixel_replay(tp);
    let range = ranges[gt];
    var end = entries_used(replay.last, lid);
    while end > 0u {
        let start = max(end, BATCH) - BATCH;
        stage_batch(range.x, start, end, lid);
        // Entries parked so far in this flush group: slot k holds entry j - 1 + pending - 1 - k
        // once entry j - 1 is parked (the replay goes back to front).
        var pending = 0u;
        for (var j = end; j > start; j--) {
            let g = replay_entry(&replay, tp, j - 1u, batch[j - 1u - start]);
            for (var q = 0u; q < SG; q++) {
                let sum = subgroupAdd(g[q]);
                if lane == 0u {
                    parked[(pending * SG + q) * MAX_SUBGROUPS + subgroup] = sum;
                }
            }
            pending += 1u;
            if pending == FLUSH || j - 1u == start {
                workgroupBarrier();
                if lid < pending * SG {
                    let k = lid / SG;
                    var acc = 0.0;
                    for (var s = 0u; s < num_subgroups; s++) {
                        acc += parked[lid * MAX_SUBGROUPS + s];
                    }
                    entry_grads[(range.x + j - 1u + pending - 1u - k) * SG + lid % SG] = acc;
                }
                workgroupBarrier();
                pending = 0u;
            }
        }
        end = start;
    }
}
