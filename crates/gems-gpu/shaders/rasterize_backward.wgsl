// Per (camera, tile) workgroup, one pixel per invocation: replays the tile's list back to
// front from the last entry any pixel used (rasterize_backward_pixel.wgsl). Each list entry's
// screen-space gradient is summed over the tile's pixels in workgroup memory (rows, then the 16
// row sums) and written once to its own slot: no atomics, a fixed summation order, hence
// reproducible results. Three barriers per entry: the path for adapters without subgroup
// operations (rasterize_backward_subgroup.wgsl is the fast one).

var<workgroup> red: array<array<f32, 256>, SG>;
var<workgroup> rows: array<array<f32, 16>, SG>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
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
        for (var j = end; j > start; j--) {
            let g = replay_entry(&replay, tp, j - 1u, batch[j - 1u - start]);
            for (var q = 0u; q < SG; q++) {
                red[q][lid] = g[q];
            }
            workgroupBarrier();
            if lid < 16u {
                for (var q = 0u; q < SG; q++) {
                    var acc = 0.0;
                    for (var x = 0u; x < 16u; x++) {
                        acc += red[q][lid * 16u + x];
                    }
                    rows[q][lid] = acc;
                }
            }
            workgroupBarrier();
            if lid == 0u {
                let dst = (range.x + j - 1u) * SG;
                for (var q = 0u; q < SG; q++) {
                    var acc = 0.0;
                    for (var y = 0u; y < 16u; y++) {
                        acc += rows[q][y];
                    }
                    entry_grads[dst + q] = acc;
                }
            }
        }
        end = start;
    }
}
