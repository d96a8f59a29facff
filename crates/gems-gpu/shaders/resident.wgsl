// Between the resident training state (gems-gpu `params`: one flat array per group) and the
// renderer's packed layout (GP floats per Gaussian, see common.wgsl): `pack_gaussians` gathers
// the groups into the packed parameter buffer, `unpack_grads` scatters the packed gradients into
// per-group gradient buffers. One invocation per (Gaussian, float); pure copies, so bit-exact.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read_write> means: array<f32>;
@group(0) @binding(2) var<storage, read_write> quats: array<f32>;
@group(0) @binding(3) var<storage, read_write> log_scales: array<f32>;
@group(0) @binding(4) var<storage, read_write> opacity_logits: array<f32>;
@group(0) @binding(5) var<storage, read_write> sh: array<f32>;
@group(0) @binding(6) var<storage, read_write> packed: array<f32>;

@compute @workgroup_size(256)
fn pack_gaussians(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let idx = group_index(wid, nwg) * 256u + lid;
    if idx >= params.n {
        return;
    }
    let i = idx / GP;
    let k = idx % GP;
    var v: f32;
    if k < 3u {
        v = means[3u * i + k];
    } else if k < 7u {
        v = quats[4u * i + k - 3u];
    } else if k < 10u {
        v = log_scales[3u * i + k - 7u];
    } else if k == 10u {
        v = opacity_logits[i];
    } else {
        v = sh[48u * i + k - 11u];
    }
    packed[idx] = v;
}

@compute @workgroup_size(256)
fn unpack_grads(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let idx = group_index(wid, nwg) * 256u + lid;
    if idx >= params.n {
        return;
    }
    let i = idx / GP;
    let k = idx % GP;
    let v = packed[idx];
    if k < 3u {
        means[3u * i + k] = v;
    } else if k < 7u {
        quats[4u * i + k - 3u] = v;
    } else if k < 10u {
        log_scales[3u * i + k - 7u] = v;
    } else if k == 10u {
        opacity_logits[i] = v;
    } else {
        sh[48u * i + k - 11u] = v;
    }
}
