// Projection of every (camera, Gaussian) pair: screen-space splat, radii and the number of
// 16×16 tiles it overlaps (0 when culled or when it can draw nothing).

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> gaussians: array<f32>;
@group(0) @binding(2) var<storage, read> cams: array<f32>;
@group(0) @binding(3) var<storage, read_write> splats: array<Splat>;
@group(0) @binding(4) var<storage, read_write> radii: array<vec2<i32>>;
@group(0) @binding(5) var<storage, read_write> tile_counts: array<u32>;

// First and last pixel index in [0, n) whose centre lies within `extent` of `mean`;
// x > y when there is none.
fn pixel_span(mean: f32, extent: f32, n: u32) -> vec2<i32> {
    let lo = ceil(mean - extent - 0.5);
    let hi = floor(mean + extent - 0.5);
    if !(hi >= 0.0 && lo <= f32(n - 1u) && lo <= hi) {
        return vec2<i32>(1, 0);
    }
    return vec2<i32>(i32(max(lo, 0.0)), min(i32(hi), i32(n) - 1));
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let idx = group_index(wid, nwg) * 256u + lid;
    let n = params.num_gaussians;
    let total = n * params.num_cameras;
    if idx >= total {
        if idx == total {
            // The extra slot makes the exclusive prefix sum end with the total.
            tile_counts[idx] = 0u;
        }
        return;
    }
    let c = idx / n;
    let i = idx % n;
    var sp: Splat;
    sp.pbox = vec4<i32>(1, 0, 1, 0);
    splats[idx] = sp;
    radii[idx] = vec2<i32>(0, 0);
    tile_counts[idx] = 0u;

    let prep = load_prep(i);
    if !prep.ok {
        return;
    }
    let w = f32(params.width);
    let h = f32(params.height);
    let cam = make_cam(cam_values(c), w, h);
    let geo = geometry(prep.mean, prep.cov, cam, w, h);
    let z = exact_depth(cam, prep.mean);
    if !(z > params.near_plane && z < params.far_plane) {
        return;
    }
    let a0 = geo.cov2d.x;
    let b0 = geo.cov2d.y;
    let c0 = geo.cov2d.z;
    let a = a0 + params.eps2d;
    let b = b0;
    let cc = c0 + params.eps2d;
    let det = a * cc - b * b;
    if !(det > 0.0 && finite(det)) {
        return;
    }
    let conic = vec3<f32>(cc / det, -b / det, a / det);
    let mean2d = vec2<f32>(cam.fx * geo.pc.x / z + cam.cx, cam.fy * geo.pc.y / z + cam.cy);
    let rx = ceil(params.radius_extent * sqrt(a));
    let ry = ceil(params.radius_extent * sqrt(cc));
    let inside = mean2d.x + rx > 0.0 && mean2d.x - rx < w && mean2d.y + ry > 0.0 && mean2d.y - ry < h;
    if !(inside && rx > 0.0 && ry > 0.0) {
        return;
    }
    var comp = 1.0;
    if params.antialiased != 0u {
        comp = sqrt(max((a0 * c0 - b0 * b0) / det, 0.0));
    }
    let dir = prep.mean - cam.center;
    let basis = sh_basis(params.sh_degree, safe_normalize(dir));
    var raw = vec3<f32>(0.5);
    let nk = num_sh_coeffs(params.sh_degree);
    let base = i * GP + 11u;
    for (var k = 0u; k < nk; k++) {
        raw += basis[k] * vec3<f32>(gaussians[base + 3u * k], gaussians[base + 3u * k + 1u], gaussians[base + 3u * k + 2u]);
    }
    let opacity = prep.opacity * comp;
    // The box where α can reach alpha_min (1% margin), capped by the radius: outside it a
    // pixel would skip this Gaussian anyway.
    var extent = vec2<f32>(rx, ry);
    if params.alpha_min > 0.0 {
        let thr = log(opacity / params.alpha_min) * 1.01 + 1e-3;
        if thr > 0.0 {
            extent = min(vec2<f32>(sqrt(2.0 * thr * a), sqrt(2.0 * thr * cc)), extent);
        } else {
            extent = vec2<f32>(0.0);
        }
    }
    // The largest f32 below 2³¹: radii saturate like the CPU engine's.
    let big = 2147483520.0;
    radii[idx] = vec2<i32>(i32(min(rx, big)), i32(min(ry, big)));
    sp.xyod = vec4<f32>(mean2d, opacity, z);
    sp.conic = vec4<f32>(conic, 0.0);
    sp.color = vec4<f32>(max(raw, vec3<f32>(0.0)), 0.0);
    let sx = pixel_span(mean2d.x, extent.x, params.width);
    let sy = pixel_span(mean2d.y, extent.y, params.height);
    if sx.x <= sx.y && sy.x <= sy.y {
        sp.pbox = vec4<i32>(sx.x, sx.y, sy.x, sy.y);
    }
    splats[idx] = sp;
    // Below the α cut-off a Gaussian draws nothing: it gets no tile entries.
    if opacity >= params.alpha_min && sp.pbox.x <= sp.pbox.y {
        let tx = u32(sp.pbox.y) / 16u - u32(sp.pbox.x) / 16u + 1u;
        let ty = u32(sp.pbox.w) / 16u - u32(sp.pbox.z) / 16u + 1u;
        tile_counts[idx] = tx * ty;
    }
}
