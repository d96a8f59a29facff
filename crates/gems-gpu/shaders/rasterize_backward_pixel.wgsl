// Shared by the two backward rasterizers (rasterize_backward.wgsl, which sums each tile entry's
// gradient over the tile's pixels in workgroup memory, and rasterize_backward_subgroup.wgsl,
// which sums it with subgroup adds): the bindings, the staging of the tile list in batches from
// the last entry any pixel used, and one pixel's replay of that list back to front, restoring
// its transmittance and the colour behind it exactly as the forward composited them.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> splats: array<Splat>;
@group(0) @binding(2) var<storage, read> sorted_splat: array<u32>;
@group(0) @binding(3) var<storage, read> ranges: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read> cams: array<f32>;
@group(0) @binding(5) var<storage, read> aux: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read> d_rgb: array<f32>;
@group(0) @binding(7) var<storage, read> d_alpha: array<f32>;
@group(0) @binding(8) var<storage, read_write> entry_grads: array<f32>;

// Splats staged in workgroup memory per batch.
const BATCH: u32 = 64u;
var<workgroup> batch: array<Splat, BATCH>;
var<workgroup> max_last: atomic<u32>;
var<workgroup> max_last_copy: u32;

// How many entries of the tile list any pixel of the workgroup composited (`last` is this
// invocation's): the replay starts there. Workgroup-uniform.
fn entries_used(last: u32, lid: u32) -> u32 {
    if lid == 0u {
        atomicStore(&max_last, 0u);
    }
    workgroupBarrier();
    atomicMax(&max_last, last);
    workgroupBarrier();
    if lid == 0u {
        max_last_copy = atomicLoad(&max_last);
    }
    return workgroupUniformLoad(&max_last_copy);
}

// Stages the splats of tile-list entries start..end (list offset `first`) in `batch`, once
// every invocation is done with the previous batch.
fn stage_batch(first: u32, start: u32, end: u32, lid: u32) {
    workgroupBarrier();
    if lid < end - start {
        batch[lid] = splats[sorted_splat[first + start + lid]];
    }
    workgroupBarrier();
}

struct PixelReplay {
    // dL/dRGB of the pixel.
    v: vec3<f32>,
    // The part of dL/dα common to every splat of the pixel (alpha output and background).
    v_final: f32,
    // Transmittance in front of the entry being replayed.
    t: f32,
    // Entries of the tile list the forward composited for this pixel.
    last: u32,
    // Colour composited behind the entry being replayed.
    behind: vec3<f32>,
}

// The replay state before the pixel's last entry (all zero outside the image).
fn pixel_replay(tp: TilePixel) -> PixelReplay {
    var r = PixelReplay(vec3<f32>(0.0), 0.0, 0.0, 0u, vec3<f32>(0.0));
    if tp.inside {
        let c = tp.camera;
        let pix = (c * params.height + tp.py) * params.width + tp.px;
        r.v = vec3<f32>(d_rgb[pix * 3u], d_rgb[pix * 3u + 1u], d_rgb[pix * 3u + 2u]);
        var va = 0.0;
        if params.has_d_alpha != 0u {
            va = d_alpha[pix];
        }
        let bg = vec3<f32>(cams[c * CAMF + 16u], cams[c * CAMF + 17u], cams[c * CAMF + 18u]);
        let px_aux = aux[pix];
        r.t = px_aux.z;
        r.last = bitcast<u32>(px_aux.w);
        r.v_final = r.t * (va - dot(r.v, bg));
    }
    return r;
}

// The pixel's share of the screen-space gradient (mean2d 2, conic 3, opacity 1, colour 3) of
// entry `index` of its tile list, splat `sp`; advances the replay past it.
fn replay_entry(r: ptr<function, PixelReplay>, tp: TilePixel, index: u32, sp: Splat) -> array<f32, SG> {
    var g: array<f32, SG>;
    let box = sp.pbox;
    if index < (*r).last && tp.pxi >= box.x && tp.pxi <= box.y && tp.pyi >= box.z && tp.pyi <= box.w {
        let s = sp.xyod;
        let cn = sp.conic;
        let col = sp.color.xyz;
        let dx = s.x - tp.pcx;
        let dy = s.y - tp.pcy;
        let sigma = 0.5 * (cn.x * dx * dx + cn.z * dy * dy) + cn.y * dx * dy;
        let gauss = exp(-sigma);
        let raw = s.z * gauss;
        let alpha = min(params.alpha_max, raw);
        if sigma >= 0.0 && alpha >= params.alpha_min {
            let v = (*r).v;
            let ra = 1.0 / (1.0 - alpha);
            let tk = (*r).t * ra;
            (*r).t = tk;
            let wgt = alpha * tk;
            let v_alpha = (*r).v_final * ra + dot(v, col * tk - (*r).behind * ra);
            g[6] = wgt * v.x;
            g[7] = wgt * v.y;
            g[8] = wgt * v.z;
            (*r).behind += col * wgt;
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
    return g;
}
