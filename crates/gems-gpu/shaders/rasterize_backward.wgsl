// Per (camera, tile) workgroup, one pixel per invocation: replays the tile's list back to
// front from the last entry any pixel used, restoring each pixel's transmittance and the colour
// behind it, exactly as the forward composited. Each list entry's screen-space gradient is
// summed over the tile's pixels in workgroup memory (rows, then the 16 row sums) and written
// once to its own slot: no atomics, a fixed summation order, hence reproducible results.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> splats: array<Splat>;
@group(0) @binding(2) var<storage, read> sorted_splat: array<u32>;
@group(0) @binding(3) var<storage, read> ranges: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read> cams: array<f32>;
@group(0) @binding(5) var<storage, read> aux: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read> d_rgb: array<f32>;
@group(0) @binding(7) var<storage, read> d_alpha: array<f32>;
@group(0) @binding(8) var<storage, read_write> entry_grads: array<f32>;

const BATCH: u32 = 64u;
var<workgroup> batch: array<Splat, BATCH>;
var<workgroup> red: array<array<f32, 256>, SG>;
var<workgroup> rows: array<array<f32, 16>, SG>;
var<workgroup> max_last: atomic<u32>;
var<workgroup> max_last_copy: u32;

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
        atomicStore(&max_last, 0u);
    }
    workgroupBarrier();

    var v = vec3<f32>(0.0);
    var v_final = 0.0;
    var t = 0.0;
    var last = 0u;
    if tp.inside {
        let pix = (c * params.height + tp.py) * params.width + tp.px;
        v = vec3<f32>(d_rgb[pix * 3u], d_rgb[pix * 3u + 1u], d_rgb[pix * 3u + 2u]);
        var va = 0.0;
        if params.has_d_alpha != 0u {
            va = d_alpha[pix];
        }
        let bg = vec3<f32>(cams[c * CAMF + 16u], cams[c * CAMF + 17u], cams[c * CAMF + 18u]);
        let px_aux = aux[pix];
        t = px_aux.z;
        last = bitcast<u32>(px_aux.w);
        // The part of dL/dα common to every splat of the pixel (alpha output and background).
        v_final = t * (va - dot(v, bg));
        atomicMax(&max_last, last);
    }
    workgroupBarrier();
    if lid == 0u {
        max_last_copy = atomicLoad(&max_last);
    }
    let used = workgroupUniformLoad(&max_last_copy);
    let range = ranges[gt];
    var behind = vec3<f32>(0.0);
    var end = used;
    while end > 0u {
        let start = max(end, BATCH) - BATCH;
        workgroupBarrier();
        if lid < end - start {
            batch[lid] = splats[sorted_splat[range.x + start + lid]];
        }
        workgroupBarrier();
        for (var j = end; j > start; j--) {
            let jj = j - 1u - start;
            var g: array<f32, SG>;
            let box = batch[jj].pbox;
            if j - 1u < last && tp.pxi >= box.x && tp.pxi <= box.y && tp.pyi >= box.z && tp.pyi <= box.w {
                let s = batch[jj].xyod;
                let cn = batch[jj].conic;
                let col = batch[jj].color.xyz;
                let dx = s.x - tp.pcx;
                let dy = s.y - tp.pcy;
                let sigma = 0.5 * (cn.x * dx * dx + cn.z * dy * dy) + cn.y * dx * dy;
                let gauss = exp(-sigma);
                let raw = s.z * gauss;
                let alpha = min(params.alpha_max, raw);
                if sigma >= 0.0 && alpha >= params.alpha_min {
                    let ra = 1.0 / (1.0 - alpha);
                    let tk = t * ra;
                    t = tk;
                    let wgt = alpha * tk;
                    let v_alpha = v_final * ra + dot(v, col * tk - behind * ra);
                    g[6] = wgt * v.x;
                    g[7] = wgt * v.y;
                    g[8] = wgt * v.z;
                    behind += col * wgt;
                    if raw <= params.alpha_max {
                        let v_sigma = -raw * v_alpha;
                        g[0] = v_sigma * (cn.x * dx + cn.y * dy);
                        g[1] = v_sigma * (cn.y * dx + cn.z * dy);
                        g[2] = 0.5 * v_sigma * dx * dx;
                        g[3] = v_sigma * dx * dy;
                        g[4] = 0.5 * v_sigma * dy * dy;
                        g[5] = gauss * v_alpha;
                    }
                }
            }
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
