// Per (camera, tile) workgroup, one pixel per invocation: composites the tile's depth-sorted
// splats front to back, staging them in workgroup memory in batches. Writes RGB over the
// background ([C,H,W,3]) and per pixel (alpha, expected depth, final T, entries used), which
// the backward replays.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> splats: array<Splat>;
@group(0) @binding(2) var<storage, read> sorted_splat: array<u32>;
@group(0) @binding(3) var<storage, read> ranges: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read> cams: array<f32>;
@group(0) @binding(5) var<storage, read_write> rgb_out: array<f32>;
@group(0) @binding(6) var<storage, read_write> aux_out: array<vec4<f32>>;

const BATCH: u32 = 128u;
var<workgroup> batch: array<Splat, BATCH>;
var<workgroup> n_done: atomic<u32>;
var<workgroup> n_done_copy: u32;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    // One workgroup per (camera, tile); the dispatch may round up.
    let gt = group_index(wid, nwg);
    if gt >= params.num_cameras * params.tiles_x * params.tiles_y {
        return;
    }
    let tp = tile_pixel(params, gt, lid);
    let c = tp.camera;
    if lid == 0u {
        atomicStore(&n_done, 0u);
    }
    workgroupBarrier();
    var done = !tp.inside;
    if done {
        atomicAdd(&n_done, 1u);
    }
    var t = 1.0;
    var col = vec3<f32>(0.0);
    var dz = 0.0;
    var last = 0u;
    let range = ranges[gt];
    for (var b = range.x; b < range.y; b += BATCH) {
        workgroupBarrier();
        if lid < BATCH && b + lid < range.y {
            batch[lid] = splats[sorted_splat[b + lid]];
        }
        workgroupBarrier();
        let m = min(BATCH, range.y - b);
        if !done {
            for (var j = 0u; j < m; j++) {
                let box = batch[j].pbox;
                if tp.pxi < box.x || tp.pxi > box.y || tp.pyi < box.z || tp.pyi > box.w {
                    continue;
                }
                let s = batch[j].xyod;
                let cn = batch[j].conic;
                let dx = s.x - tp.pcx;
                let dy = s.y - tp.pcy;
                let sigma = 0.5 * (cn.x * dx * dx + cn.z * dy * dy) + cn.y * dx * dy;
                let alpha = min(params.alpha_max, s.z * exp(-sigma));
                if !(sigma >= 0.0 && alpha >= params.alpha_min) {
                    continue;
                }
                let next_t = t * (1.0 - alpha);
                if next_t <= params.t_min {
                    done = true;
                    atomicAdd(&n_done, 1u);
                    break;
                }
                let w = alpha * t;
                col += batch[j].color.xyz * w;
                dz += s.w * w;
                t = next_t;
                last = b - range.x + j + 1u;
            }
        }
        workgroupBarrier();
        if lid == 0u {
            n_done_copy = atomicLoad(&n_done);
        }
        if workgroupUniformLoad(&n_done_copy) == 256u {
            break;
        }
    }
    if !tp.inside {
        return;
    }
    let pix = (c * params.height + tp.py) * params.width + tp.px;
    let bg = vec3<f32>(cams[c * CAMF + 16u], cams[c * CAMF + 17u], cams[c * CAMF + 18u]);
    let out = col + t * bg;
    rgb_out[pix * 3u] = out.x;
    rgb_out[pix * 3u + 1u] = out.y;
    rgb_out[pix * 3u + 2u] = out.z;
    let a = 1.0 - t;
    var depth = 0.0;
    if a > 0.0 {
        depth = dz / a;
    }
    aux_out[pix] = vec4<f32>(a, depth, t, bitcast<f32>(last));
}
