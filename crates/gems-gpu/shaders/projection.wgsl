// Projection math shared by project_forward.wgsl and project_backward.wgsl: the same EWA
// projection, SH basis and covariance as the CPU engine (gems-splat `project.rs`, `sh.rs`),
// in f32. Matrices are WGSL matrices in the mathematical sense (m[col][row]).

struct Cam {
    fx: f32,
    fy: f32,
    cx: f32,
    cy: f32,
    r: mat3x3<f32>,
    t: vec3<f32>,
    center: vec3<f32>,
}

fn make_cam(v: array<f32, 24>, width: f32, height: f32) -> Cam {
    // Row-major rows become the columns of the transpose.
    let rt = mat3x3<f32>(
        vec3<f32>(v[4], v[5], v[6]),
        vec3<f32>(v[7], v[8], v[9]),
        vec3<f32>(v[10], v[11], v[12]),
    );
    let r = transpose(rt);
    let t = vec3<f32>(v[13], v[14], v[15]);
    return Cam(v[0], v[1], v[2], v[3], r, t, -(rt * t));
}

fn quat_to_rot(q: vec4<f32>) -> mat3x3<f32> {
    let w = q.x;
    let x = q.y;
    let y = q.z;
    let z = q.w;
    // Columns of the rotation matrix.
    return mat3x3<f32>(
        vec3<f32>(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)),
        vec3<f32>(2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x)),
        vec3<f32>(2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)),
    );
}

// Camera-independent per-Gaussian quantities; `ok` is false when the Gaussian is culled
// everywhere (non-finite parameter or (near-)zero quaternion).
struct Prep {
    ok: bool,
    mean: vec3<f32>,
    quat: vec4<f32>,
    log_scale: vec3<f32>,
    cov: mat3x3<f32>,
    opacity: f32,
}

// Sloan's real SH basis up to degree 3 at unit direction d (gsplat's order and signs).
fn sh_basis(degree: u32, d: vec3<f32>) -> array<f32, 16> {
    var b: array<f32, 16>;
    let x = d.x;
    let y = d.y;
    let z = d.z;
    b[0] = 0.28209479177387814;
    if degree >= 1u {
        b[1] = -0.4886025119029199 * y;
        b[2] = 0.4886025119029199 * z;
        b[3] = -0.4886025119029199 * x;
    }
    if degree >= 2u {
        b[4] = 0.5462742152960395 * 2.0 * x * y;
        b[5] = -1.092548430592079 * z * y;
        b[6] = 0.9461746957575601 * z * z - 0.3153915652525201;
        b[7] = -1.092548430592079 * z * x;
        b[8] = 0.5462742152960395 * (x * x - y * y);
    }
    if degree >= 3u {
        let fc1 = x * x - y * y;
        let fs1 = 2.0 * x * y;
        let fc2 = x * fc1 - y * fs1;
        let fs2 = x * fs1 + y * fc1;
        let a = -2.285228997322329 * z * z + 0.4570457994644658;
        let bb = 1.445305721320277 * z;
        b[9] = -0.5900435899266435 * fs2;
        b[10] = bb * fs1;
        b[11] = a * y;
        b[12] = z * (1.865881662950577 * z * z - 1.119528997770346);
        b[13] = a * x;
        b[14] = bb * fc1;
        b[15] = -0.5900435899266435 * fc2;
    }
    return b;
}

// Derivatives of the basis w.r.t. the components of d (treated as independent).
fn sh_basis_deriv(degree: u32, d: vec3<f32>) -> array<vec3<f32>, 16> {
    var dd: array<vec3<f32>, 16>;
    let x = d.x;
    let y = d.y;
    let z = d.z;
    let c1 = 0.4886025119029199;
    if degree >= 1u {
        dd[1] = vec3<f32>(0.0, -c1, 0.0);
        dd[2] = vec3<f32>(0.0, 0.0, c1);
        dd[3] = vec3<f32>(-c1, 0.0, 0.0);
    }
    if degree >= 2u {
        let c20 = 0.5462742152960395;
        let c21 = -1.092548430592079;
        let c22 = 0.9461746957575601;
        dd[4] = vec3<f32>(c20 * 2.0 * y, c20 * 2.0 * x, 0.0);
        dd[5] = vec3<f32>(0.0, c21 * z, c21 * y);
        dd[6] = vec3<f32>(0.0, 0.0, 2.0 * c22 * z);
        dd[7] = vec3<f32>(c21 * z, 0.0, c21 * x);
        dd[8] = vec3<f32>(2.0 * c20 * x, -2.0 * c20 * y, 0.0);
    }
    if degree >= 3u {
        let k9 = -0.5900435899266435;
        let fc1 = x * x - y * y;
        let fs1 = 2.0 * x * y;
        let a = -2.285228997322329 * z * z + 0.4570457994644658;
        let bb = 1.445305721320277 * z;
        let d_fc1 = vec3<f32>(2.0 * x, -2.0 * y, 0.0);
        let d_fs1 = vec3<f32>(2.0 * y, 2.0 * x, 0.0);
        let d_fc2 = vec3<f32>(fc1 + x * d_fc1.x - y * d_fs1.x, x * d_fc1.y - fs1 - y * d_fs1.y, 0.0);
        let d_fs2 = vec3<f32>(fs1 + x * d_fs1.x + y * d_fc1.x, x * d_fs1.y + fc1 + y * d_fc1.y, 0.0);
        let d_a_z = -2.0 * 2.285228997322329 * z;
        let d_b_z = 1.445305721320277;
        dd[9] = k9 * d_fs2;
        dd[10] = vec3<f32>(bb * d_fs1.x, bb * d_fs1.y, d_b_z * fs1);
        dd[11] = vec3<f32>(0.0, a, d_a_z * y);
        dd[12] = vec3<f32>(0.0, 0.0, 3.0 * 1.865881662950577 * z * z - 1.119528997770346);
        dd[13] = vec3<f32>(a, 0.0, d_a_z * x);
        dd[14] = vec3<f32>(bb * d_fc1.x, bb * d_fc1.y, d_b_z * fc1);
        dd[15] = k9 * d_fc2;
    }
    return dd;
}

fn num_sh_coeffs(degree: u32) -> u32 {
    return (degree + 1u) * (degree + 1u);
}

fn safe_normalize(v: vec3<f32>) -> vec3<f32> {
    let n = length(v);
    if n > 0.0 {
        return v / n;
    }
    return vec3<f32>(0.0);
}

// Screen-space geometry of one Gaussian in one camera (the Jacobian uses the guard-band
// clamped x/z, y/z; the mean does not).
struct Geometry {
    pc: vec3<f32>,
    // Rows of the 2×3 Jacobian.
    j0: vec3<f32>,
    j1: vec3<f32>,
    cov_c: mat3x3<f32>,
    // Unfiltered 2D covariance xx, xy, yy.
    cov2d: vec3<f32>,
    clamped_x: bool,
    clamped_y: bool,
}

fn geometry(mean: vec3<f32>, cov: mat3x3<f32>, cam: Cam, width: f32, height: f32) -> Geometry {
    let pc = cam.r * mean + cam.t;
    let cov_c = cam.r * cov * transpose(cam.r);
    let z = pc.z;
    let tan_fovx = 0.5 * width / cam.fx;
    let tan_fovy = 0.5 * height / cam.fy;
    let lim_x_pos = (width - cam.cx) / cam.fx + 0.3 * tan_fovx;
    let lim_x_neg = cam.cx / cam.fx + 0.3 * tan_fovx;
    let lim_y_pos = (height - cam.cy) / cam.fy + 0.3 * tan_fovy;
    let lim_y_neg = cam.cy / cam.fy + 0.3 * tan_fovy;
    let rx = pc.x / z;
    let ry = pc.y / z;
    let cxr = clamp(rx, -lim_x_neg, lim_x_pos);
    let cyr = clamp(ry, -lim_y_neg, lim_y_pos);
    let tx = z * cxr;
    let ty = z * cyr;
    let j0 = vec3<f32>(cam.fx / z, 0.0, -cam.fx * tx / (z * z));
    let j1 = vec3<f32>(0.0, cam.fy / z, -cam.fy * ty / (z * z));
    let a = dot(j0, cov_c * j0);
    let b = 0.5 * (dot(j0, cov_c * j1) + dot(j1, cov_c * j0));
    let c = dot(j1, cov_c * j1);
    return Geometry(pc, j0, j1, cov_c, vec3<f32>(a, b, c), cxr != rx, cyr != ry);
}

// Needs module-scope `gaussians` (packed parameters) and `cams` (packed cameras) bindings.
fn load_prep(i: u32) -> Prep {
    let base = i * GP;
    var ok = true;
    for (var k = 0u; k < GP; k++) {
        ok = ok && finite(gaussians[base + k]);
    }
    let mean = vec3<f32>(gaussians[base], gaussians[base + 1u], gaussians[base + 2u]);
    let q = vec4<f32>(gaussians[base + 3u], gaussians[base + 4u], gaussians[base + 5u], gaussians[base + 6u]);
    let ls = vec3<f32>(gaussians[base + 7u], gaussians[base + 8u], gaussians[base + 9u]);
    let logit = gaussians[base + 10u];
    let qn2 = dot(q, q);
    // exp overflows f32 above 88.7.
    ok = ok && qn2 > 1e-24 && finite(qn2) && all(ls < vec3<f32>(88.0));
    var cov = mat3x3<f32>();
    if ok {
        let rq = quat_to_rot(q / sqrt(qn2));
        let s = exp(ls);
        let m = mat3x3<f32>(rq[0] * s.x, rq[1] * s.y, rq[2] * s.z);
        cov = m * transpose(m);
    }
    return Prep(ok, mean, q, ls, cov, 1.0 / (1.0 + exp(-logit)));
}

fn cam_values(c: u32) -> array<f32, 24> {
    var v: array<f32, 24>;
    for (var k = 0u; k < CAMF; k++) {
        v[k] = cams[c * CAMF + k];
    }
    return v;
}


// Camera depth r₂·mean + t₂ with error-free products and sums (fma TwoProduct, Knuth
// TwoSum): the result is the correctly rounded f32 of the exact value in all but rare ties, as
// the CPU engine's (computed in f64, then rounded). The depth orders the splats, and a 1-ulp
// difference could swap two nearly equidistant Gaussians.
fn exact_depth(cam: Cam, mean: vec3<f32>) -> f32 {
    var s = cam.t.z;
    var err = 0.0;
    for (var k = 0u; k < 3u; k++) {
        let a = cam.r[k].z;
        let p = a * mean[k];
        let pe = fma(a, mean[k], -p);
        let t = s + p;
        let bb = t - s;
        err += pe + ((s - (t - bb)) + (p - bb));
        s = t;
    }
    return s + err;
}
