// One torch-Adam update of a flat parameter group, the formula of gems-train's
// AdamState::step_by_column with the same f32 operations in the same order:
//   g' = g + wd·p;  m = β1·m + (1−β1)·g';  v = β2·v + (1−β2)·g'·g'
//   p -= (lr·inv_bc1) · m / (sqrt(v)·inv_sqrt_bc2 + eps)
// inv_bc1 = 1/(1−β1^t) and inv_sqrt_bc2 = 1/sqrt(1−β2^t) are computed on the CPU in f64 and
// rounded to f32, as the CPU does. lr is lr_lo for columns < split_col of each row, lr_hi
// otherwise (SH: dc and rest share one array). Elementwise: bit-reproducible run to run.

struct AdamUniform {
    len: u32,
    width: u32,
    split_col: u32,
    pad: u32,
    lr_lo: f32,
    lr_hi: f32,
    beta1: f32,
    beta2: f32,
    eps: f32,
    weight_decay: f32,
    inv_bc1: f32,
    inv_sqrt_bc2: f32,
}

@group(0) @binding(0) var<uniform> u: AdamUniform;
@group(0) @binding(1) var<storage, read_write> param: array<f32>;
@group(0) @binding(2) var<storage, read> grad: array<f32>;
@group(0) @binding(3) var<storage, read_write> m1: array<f32>;
@group(0) @binding(4) var<storage, read_write> m2: array<f32>;

@compute @workgroup_size(256)
fn adam_update(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let i = flat_index(wg, nwg, lid);
    if i >= u.len {
        return;
    }
    let p = param[i];
    let g = grad[i] + u.weight_decay * p;
    let m = u.beta1 * m1[i] + (1.0 - u.beta1) * g;
    let v = u.beta2 * m2[i] + (1.0 - u.beta2) * g * g;
    m1[i] = m;
    m2[i] = v;
    let lr = select(u.lr_hi, u.lr_lo, i % u.width < u.split_col);
    let step_size = lr * u.inv_bc1;
    param[i] = p - step_size * m / (sqrt(v) * u.inv_sqrt_bc2 + u.eps);
}
