//! The opacity parameterisation (3DGS, gsplat): a Gaussian stores an unconstrained logit and its
//! opacity is `sigmoid(logit)`. Every crate converting between the two calls these, so the
//! training, the export, the viewer and the renderer agree to the bit.

/// `1 / (1 + e^(−x))`: the opacity of a stored logit.
#[inline]
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// [`sigmoid`] in f64, for the renderer's f64 projection and f64 reference values.
#[inline]
pub fn sigmoid_f64(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

/// `ln(p / (1 − p))`, the inverse of [`sigmoid`]: the logit stored for an opacity `p` in (0, 1).
#[inline]
pub fn logit(p: f32) -> f32 {
    (p / (1.0 - p)).ln()
}
