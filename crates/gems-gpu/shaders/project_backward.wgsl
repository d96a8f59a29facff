// Per Gaussian, over every camera that did not cull it: the backward of the projection, SH
// colour and opacity (as gems-splat `project.rs`), then of the covariance to the raw
// quaternion and the log-scales. Writes the Gaussian's gradients (packed like its parameters),
// its densification statistics, and each camera's share of the pose and focal gradient
// (`pose_parts[c·N + i]`: dL/dR row-major, dL/dt, dL/dfx, dL/dfy; POSE_FLOATS = 14 floats),
// which reduce_segments sums per camera.
//
// Camera chunks: a batch too large for the adapter's bindings runs as consecutive calls over
// chunks of its cameras. The per-Gaussian sums over cameras (mean, covariance, opacity, SH,
// statistics) then continue across calls through `carry` (CARRY floats per Gaussian):
// `params.carry` bit 0 starts from the previous chunk's sums, bit 1 stores the sums reached.
// The additions happen in the same order as in one call over all cameras, so the chunked
// result is bit-identical to the unchunked one.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> gaussians: array<f32>;
@group(0) @binding(2) var<storage, read> cams: array<f32>;
@group(0) @binding(3) var<storage, read> radii: array<vec2<i32>>;
@group(0) @binding(4) var<storage, read> splat_grads: array<f32>;
@group(0) @binding(5) var<storage, read_write> grads_out: array<f32>;
@group(0) @binding(6) var<storage, read_write> stats: array<vec2<f32>>;
@group(0) @binding(7) var<storage, read_write> pose_parts: array<f32>;
@group(0) @binding(8) var<storage, read_write> carry: array<f32>;

// Accumulators carried between camera chunks: mean 3, covariance 9, opacity logit 1, SH 48,
// mean2d-gradient norm 1, visible count 1 (bits).
const CARRY: u32 = 63u;

// Element (row a, column b) of a WGSL (column-major) matrix.
fn el(m: mat3x3<f32>, a: u32, b: u32) -> f32 {
    return m[b][a];
}

fn outer(u: vec3<f32>, v: vec3<f32>) -> mat3x3<f32> {
    return mat3x3<f32>(u * v.x, u * v.y, u * v.z);
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = group_index(wid, nwg) * 256u + lid;
    let n = params.num_gaussians;
    if i >= n {
        return;
    }
    let prep = load_prep(i);
    let w = f32(params.width);
    let h = f32(params.height);
    let eps = params.eps2d;
    let nk = num_sh_coeffs(params.sh_degree);
    var coeffs: array<vec3<f32>, 16>;
    for (var k = 0u; k < nk; k++) {
        let base = i * GP + 11u + 3u * k;
        coeffs[k] = vec3<f32>(gaussians[base], gaussians[base + 1u], gaussians[base + 2u]);
    }
    var v_mean_acc = vec3<f32>(0.0);
    var v_cov_acc = mat3x3<f32>();
    var v_logit = 0.0;
    var v_sh: array<vec3<f32>, 16>;
    var norm = 0.0;
    var count = 0u;
    let cb = i * CARRY;
    if (params.carry & 1u) != 0u {
        v_mean_acc = vec3<f32>(carry[cb], carry[cb + 1u], carry[cb + 2u]);
        for (var col = 0u; col < 3u; col++) {
            v_cov_acc[col] = vec3<f32>(carry[cb + 3u + 3u * col], carry[cb + 4u + 3u * col], carry[cb + 5u + 3u * col]);
        }
        v_logit = carry[cb + 12u];
        for (var k = 0u; k < 16u; k++) {
            v_sh[k] = vec3<f32>(carry[cb + 13u + 3u * k], carry[cb + 14u + 3u * k], carry[cb + 15u + 3u * k]);
        }
        norm = carry[cb + 61u];
        count = bitcast<u32>(carry[cb + 62u]);
    }
    for (var c = 0u; c < params.num_cameras; c++) {
        let ci = c * n + i;
        var v_r = mat3x3<f32>();
        var v_t = vec3<f32>(0.0);
        var v_f = vec2<f32>(0.0);
        if prep.ok && radii[ci].x > 0 {
            let sgb = ci * SG;
            let vm = vec2<f32>(splat_grads[sgb], splat_grads[sgb + 1u]);
            let vconic = vec3<f32>(splat_grads[sgb + 2u], splat_grads[sgb + 3u], splat_grads[sgb + 4u]);
            let vop = splat_grads[sgb + 5u];
            let vcol = vec3<f32>(splat_grads[sgb + 6u], splat_grads[sgb + 7u], splat_grads[sgb + 8u]);
            count += 1u;
            norm += length(vm);

            let cam = make_cam(cam_values(c), w, h);
            let geo = geometry(prep.mean, prep.cov, cam, w, h);
            let x = geo.pc.x;
            let y = geo.pc.y;
            let z = geo.pc.z;
            let a0 = geo.cov2d.x;
            let b0 = geo.cov2d.y;
            let c0 = geo.cov2d.z;
            let a = a0 + eps;
            let b = b0;
            let cc = c0 + eps;
            let det = a * cc - b * b;
            var comp = 1.0;
            if params.antialiased != 0u {
                comp = sqrt(max((a0 * c0 - b0 * b0) / det, 0.0));
            }
            let sig = prep.opacity;
            v_logit += vop * comp * sig * (1.0 - sig);

            // Colour through SH and the view direction (mean − centre, centre = −Rᵀt).
            let dir = prep.mean - cam.center;
            let dn = length(dir);
            let d = safe_normalize(dir);
            let basis = sh_basis(params.sh_degree, d);
            let dbasis = sh_basis_deriv(params.sh_degree, d);
            var raw = vec3<f32>(0.5);
            for (var k = 0u; k < nk; k++) {
                raw += basis[k] * coeffs[k];
            }
            // The clamp at 0 passes gradient only where the raw colour is positive.
            let v_raw = select(vec3<f32>(0.0), vcol, raw > vec3<f32>(0.0));
            var v_d = vec3<f32>(0.0);
            for (var k = 0u; k < nk; k++) {
                v_sh[k] += basis[k] * v_raw;
                v_d += dot(coeffs[k], v_raw) * dbasis[k];
            }
            var v_dir = vec3<f32>(0.0);
            if dn > 0.0 && params.sh_degree > 0u {
                v_dir = (v_d - dot(v_d, d) * d) / dn;
            }
            var v_mean = v_dir;
            // centre = −Rᵀ t: dL/dR += t v_dirᵀ, dL/dt += R v_dir.
            v_r += outer(cam.t, v_dir);
            v_t += cam.r * v_dir;

            // Conic (inverse of the filtered covariance) → filtered covariance. 1/det − ac/det²
            // is written −b²/det² to avoid the cancellation in f32.
            let d2 = det * det;
            var g_xx = vconic.x * (-cc * cc / d2) + vconic.y * (b * cc / d2) + vconic.z * (-b * b / d2);
            var g_yy = vconic.x * (-b * b / d2) + vconic.y * (a * b / d2) + vconic.z * (-a * a / d2);
            var g_xy = vconic.x * (2.0 * b * cc / d2) + vconic.y * (-1.0 / det - 2.0 * b * b / d2)
                + vconic.z * (2.0 * a * b / d2);
            if params.antialiased != 0u && comp > 0.0 {
                // comp² = det0/det; the differences of products are expanded in closed form
                // (eps·(…)) for f32.
                let k = vop * sig / (2.0 * comp);
                g_xx += k * eps * (c0 * cc + b * b) / d2;
                g_yy += k * eps * (a0 * a + b * b) / d2;
                g_xy += k * (-2.0 * b * eps * (a0 + c0 + eps)) / d2;
            }
            let j0 = geo.j0;
            let j1 = geo.j1;
            let v_cov_c = g_xx * outer(j0, j0) + 0.5 * g_xy * (outer(j0, j1) + outer(j1, j0))
                + g_yy * outer(j1, j1);
            let cj0 = geo.cov_c * j0;
            let cj1 = geo.cov_c * j1;
            let vj0 = 2.0 * (g_xx * cj0 + 0.5 * g_xy * cj1);
            let vj1 = 2.0 * (0.5 * g_xy * cj0 + g_yy * cj1);
            let fx = cam.fx;
            let fy = cam.fy;
            let tx = -j0.z * z * z / fx;
            let ty = -j1.z * z * z / fy;
            let z2 = z * z;
            let z3 = z2 * z;
            var v_pc = vec3<f32>(0.0);
            v_pc.z += -fx / z2 * vj0.x - fy / z2 * vj1.y + 2.0 * fx * tx / z3 * vj0.z
                + 2.0 * fy * ty / z3 * vj1.z;
            let v_tx = -fx / z2 * vj0.z;
            let v_ty = -fy / z2 * vj1.z;
            if geo.clamped_x {
                v_pc.z += v_tx * (tx / z);
            } else {
                v_pc.x += v_tx;
            }
            if geo.clamped_y {
                v_pc.z += v_ty * (ty / z);
            } else {
                v_pc.y += v_ty;
            }
            // Focal lengths: each row of J is its focal times a focal-free row, except the last
            // entry of a clamped coordinate (there f·t is focal-free).
            v_f.x = (vj0.x * j0.x + select(vj0.z * j0.z, 0.0, geo.clamped_x)) / fx + vm.x * x / z;
            v_f.y = (vj1.y * j1.y + select(vj1.z * j1.z, 0.0, geo.clamped_y)) / fy + vm.y * y / z;
            v_pc.x += fx / z * vm.x;
            v_pc.y += fy / z * vm.y;
            v_pc.z += -fx * x / z2 * vm.x - fy * y / z2 * vm.y;

            // Camera frame → world and pose.
            v_mean += transpose(cam.r) * v_pc;
            v_t += v_pc;
            v_r += outer(v_pc, prep.mean);
            // Σc = R Σ Rᵀ: dL/dR += 2 dL/dΣc R Σ; dL/dΣ = Rᵀ dL/dΣc R.
            v_r += 2.0 * (v_cov_c * (cam.r * prep.cov));
            v_cov_acc += transpose(cam.r) * v_cov_c * cam.r;
            v_mean_acc += v_mean;
        }
        let pb = ci * 14u;
        for (var a = 0u; a < 3u; a++) {
            for (var bb = 0u; bb < 3u; bb++) {
                pose_parts[pb + a * 3u + bb] = el(v_r, a, bb);
            }
            pose_parts[pb + 9u + a] = v_t[a];
        }
        pose_parts[pb + 12u] = v_f.x;
        pose_parts[pb + 13u] = v_f.y;
    }

    if (params.carry & 2u) != 0u {
        for (var a = 0u; a < 3u; a++) {
            carry[cb + a] = v_mean_acc[a];
        }
        for (var col = 0u; col < 3u; col++) {
            for (var a = 0u; a < 3u; a++) {
                carry[cb + 3u + 3u * col + a] = v_cov_acc[col][a];
            }
        }
        carry[cb + 12u] = v_logit;
        for (var k = 0u; k < 16u; k++) {
            for (var ch = 0u; ch < 3u; ch++) {
                carry[cb + 13u + 3u * k + ch] = v_sh[k][ch];
            }
        }
        carry[cb + 61u] = norm;
        carry[cb + 62u] = bitcast<f32>(count);
    }

    // Covariance → raw quaternion and log-scales (Σ = M Mᵀ, M = Rq S).
    var v_q = vec4<f32>(0.0);
    var v_ls = vec3<f32>(0.0);
    if count > 0u {
        let q = prep.quat;
        let qlen = length(q);
        let qn = q / qlen;
        let rq = quat_to_rot(qn);
        let s = exp(prep.log_scale);
        let m = mat3x3<f32>(rq[0] * s.x, rq[1] * s.y, rq[2] * s.z);
        let v_m = (v_cov_acc + transpose(v_cov_acc)) * m;
        // Column k of v_rq is column k of v_m times s_k.
        let vr = mat3x3<f32>(v_m[0] * s.x, v_m[1] * s.y, v_m[2] * s.z);
        v_ls = vec3<f32>(dot(rq[0], v_m[0]) * s.x, dot(rq[1], v_m[1]) * s.y, dot(rq[2], v_m[2]) * s.z);
        let qw = qn.x;
        let qx = qn.y;
        let qy = qn.z;
        let qz = qn.w;
        let v_w = 2.0 * (-qz * el(vr, 0u, 1u) + qy * el(vr, 0u, 2u) + qz * el(vr, 1u, 0u)
            - qx * el(vr, 1u, 2u) - qy * el(vr, 2u, 0u) + qx * el(vr, 2u, 1u));
        let v_x = 2.0 * (qy * el(vr, 0u, 1u) + qz * el(vr, 0u, 2u) + qy * el(vr, 1u, 0u)
            - 2.0 * qx * el(vr, 1u, 1u) - qw * el(vr, 1u, 2u) + qz * el(vr, 2u, 0u)
            + qw * el(vr, 2u, 1u) - 2.0 * qx * el(vr, 2u, 2u));
        let v_y = 2.0 * (-2.0 * qy * el(vr, 0u, 0u) + qx * el(vr, 0u, 1u) + qw * el(vr, 0u, 2u)
            + qx * el(vr, 1u, 0u) + qz * el(vr, 1u, 2u) - qw * el(vr, 2u, 0u)
            + qz * el(vr, 2u, 1u) - 2.0 * qy * el(vr, 2u, 2u));
        let v_z = 2.0 * (-2.0 * qz * el(vr, 0u, 0u) - qw * el(vr, 0u, 1u) + qx * el(vr, 0u, 2u)
            + qw * el(vr, 1u, 0u) - 2.0 * qz * el(vr, 1u, 1u) + qy * el(vr, 1u, 2u)
            + qx * el(vr, 2u, 0u) + qy * el(vr, 2u, 1u));
        let v_qn = vec4<f32>(v_w, v_x, v_y, v_z);
        v_q = (v_qn - dot(v_qn, qn) * qn) / qlen;
    }
    let gb = i * GP;
    for (var a = 0u; a < 3u; a++) {
        grads_out[gb + a] = v_mean_acc[a];
        grads_out[gb + 7u + a] = v_ls[a];
    }
    for (var a = 0u; a < 4u; a++) {
        grads_out[gb + 3u + a] = v_q[a];
    }
    grads_out[gb + 10u] = v_logit;
    for (var k = 0u; k < 16u; k++) {
        for (var ch = 0u; ch < 3u; ch++) {
            grads_out[gb + 11u + 3u * k + ch] = v_sh[k][ch];
        }
    }
    stats[i] = vec2<f32>(norm, bitcast<f32>(count));
}
