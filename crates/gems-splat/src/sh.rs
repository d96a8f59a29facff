//! Real spherical harmonics up to degree 3 (Sloan's "efficient SH" basis, gsplat's order and
//! signs), evaluated on a normalised direction, with the backward to the unnormalised direction.

/// The band-0 basis value 1/(2√π): a colour's SH dc coefficient is (rgb − 0.5) / C0.
pub const C0: f64 = 0.282_094_791_773_878_14;
const C1: f64 = 0.488_602_511_902_919_9;
const C2: [f64; 5] = [
    0.546_274_215_296_039_5,
    -1.092_548_430_592_079,
    0.946_174_695_757_560_1,
    -1.092_548_430_592_079,
    0.546_274_215_296_039_5,
];
const C2_OFFSET: f64 = -0.315_391_565_252_520_1;

/// Basis values for `k < (degree+1)²` at the unit direction `d` (the rest of `out` is zeroed),
/// and their derivatives w.r.t. the three components of `d` (treated as independent variables)
/// when `deriv` is given. The renderer's colour and gems-train's SH rotation both use it.
pub fn basis(degree: u32, d: [f64; 3], out: &mut [f64; 16], deriv: Option<&mut [[f64; 3]; 16]>) {
    let [x, y, z] = d;
    *out = [0.0; 16];
    out[0] = C0;
    let mut dd = [[0.0f64; 3]; 16];
    if degree >= 1 {
        out[1] = -C1 * y;
        out[2] = C1 * z;
        out[3] = -C1 * x;
        dd[1] = [0.0, -C1, 0.0];
        dd[2] = [0.0, 0.0, C1];
        dd[3] = [-C1, 0.0, 0.0];
    }
    if degree >= 2 {
        out[4] = C2[0] * 2.0 * x * y;
        out[5] = C2[1] * z * y;
        out[6] = C2[2] * z * z + C2_OFFSET;
        out[7] = C2[3] * z * x;
        out[8] = C2[4] * (x * x - y * y);
        dd[4] = [C2[0] * 2.0 * y, C2[0] * 2.0 * x, 0.0];
        dd[5] = [0.0, C2[1] * z, C2[1] * y];
        dd[6] = [0.0, 0.0, 2.0 * C2[2] * z];
        dd[7] = [C2[3] * z, 0.0, C2[3] * x];
        dd[8] = [2.0 * C2[4] * x, -2.0 * C2[4] * y, 0.0];
    }
    if degree >= 3 {
        let fc1 = x * x - y * y;
        let fs1 = 2.0 * x * y;
        let fc2 = x * fc1 - y * fs1;
        let fs2 = x * fs1 + y * fc1;
        let a = -2.285_228_997_322_329 * z * z + 0.457_045_799_464_465_8;
        let b = 1.445_305_721_320_277 * z;
        const K9: f64 = -0.590_043_589_926_643_5;
        const K12A: f64 = 1.865_881_662_950_577;
        const K12B: f64 = -1.119_528_997_770_346;
        out[9] = K9 * fs2;
        out[10] = b * fs1;
        out[11] = a * y;
        out[12] = z * (K12A * z * z + K12B);
        out[13] = a * x;
        out[14] = b * fc1;
        out[15] = K9 * fc2;
        // Partial derivatives of the helper polynomials.
        let d_fc1 = [2.0 * x, -2.0 * y, 0.0];
        let d_fs1 = [2.0 * y, 2.0 * x, 0.0];
        let d_fc2 = [
            fc1 + x * d_fc1[0] - y * d_fs1[0],
            x * d_fc1[1] - fs1 - y * d_fs1[1],
            0.0,
        ];
        let d_fs2 = [
            fs1 + x * d_fs1[0] + y * d_fc1[0],
            x * d_fs1[1] + fc1 + y * d_fc1[1],
            0.0,
        ];
        let d_a_z = -2.0 * 2.285_228_997_322_329 * z;
        let d_b_z = 1.445_305_721_320_277;
        dd[9] = d_fs2.map(|v| K9 * v);
        dd[10] = [b * d_fs1[0], b * d_fs1[1], d_b_z * fs1];
        dd[11] = [0.0, a, d_a_z * y];
        dd[12] = [0.0, 0.0, 3.0 * K12A * z * z + K12B];
        dd[13] = [a, 0.0, d_a_z * x];
        dd[14] = [b * d_fc1[0], b * d_fc1[1], d_b_z * fc1];
        dd[15] = d_fc2.map(|v| K9 * v);
    }
    if let Some(deriv) = deriv {
        *deriv = dd;
    }
}

/// Number of active coefficients for a degree.
pub(crate) fn num_coeffs(degree: u32) -> usize {
    ((degree + 1) * (degree + 1)) as usize
}

/// Colour `max(Σ_k basis_k · coeff_k + 0.5, 0)` for the direction `dir` (not normalised), and
/// the basis (kept by the caller for the backward).
pub(crate) fn color(degree: u32, coeffs: &[[f32; 3]; 16], dir: [f64; 3]) -> [f64; 3] {
    let d = normalize(dir);
    let mut b = [0.0; 16];
    basis(degree, d, &mut b, None);
    let mut raw = [0.5f64; 3];
    for k in 0..num_coeffs(degree) {
        for (ch, r) in raw.iter_mut().enumerate() {
            *r += b[k] * coeffs[k][ch] as f64;
        }
    }
    raw.map(|v| v.max(0.0))
}

/// Backward of [`color`]: given dL/dcolour, adds dL/dcoeff into `v_coeffs` and returns dL/ddir.
pub(crate) fn color_backward(
    degree: u32,
    coeffs: &[[f32; 3]; 16],
    dir: [f64; 3],
    v_color: [f64; 3],
    v_coeffs: &mut [[f64; 3]; 16],
) -> [f64; 3] {
    let d = normalize(dir);
    let mut b = [0.0; 16];
    let mut db = [[0.0; 3]; 16];
    basis(degree, d, &mut b, Some(&mut db));
    let nc = num_coeffs(degree);
    // The clamp at 0 passes gradient only where the raw colour is positive.
    let mut v_raw = [0.0f64; 3];
    for ch in 0..3 {
        let mut raw = 0.5;
        for k in 0..nc {
            raw += b[k] * coeffs[k][ch] as f64;
        }
        if raw > 0.0 {
            v_raw[ch] = v_color[ch];
        }
    }
    let mut v_d = [0.0f64; 3];
    for k in 0..nc {
        let mut s = 0.0;
        for ch in 0..3 {
            v_coeffs[k][ch] += b[k] * v_raw[ch];
            s += coeffs[k][ch] as f64 * v_raw[ch];
        }
        for j in 0..3 {
            v_d[j] += s * db[k][j];
        }
    }
    // Through the normalisation d = dir/|dir|: (v_d − (v_d·d) d) / |dir|.
    let n = norm(dir);
    if n <= 0.0 || degree == 0 {
        return [0.0; 3];
    }
    let dot = v_d[0] * d[0] + v_d[1] * d[1] + v_d[2] * d[2];
    [0, 1, 2].map(|j| (v_d[j] - dot * d[j]) / n)
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

fn normalize(v: [f64; 3]) -> [f64; 3] {
    let n = norm(v);
    if n > 0.0 { v.map(|x| x / n) } else { [0.0; 3] }
}
