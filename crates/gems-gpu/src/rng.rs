//! The counter-based random numbers of the GPU kernels, mirrored on the CPU.
//!
//! Philox4x32-10 (Salmon, Moraes, Dror, Shaw, "Parallel random numbers: as easy as 1, 2, 3",
//! SC 2011; the Random123 library): a block of four u32 is a pure function of a 128-bit counter
//! and a 64-bit key, so each GPU invocation draws its own numbers without shared state, and the
//! result does not depend on the dispatch. [`philox4x32_10`] is bit-identical to the WGSL in
//! `shaders/philox.wgsl`; [`normal3`] performs the same Box–Muller transform with the CPU's
//! `ln`/`cos`/`sin`, which differ from a GPU's by a few ulps.

/// Stream tag of the MCMC position noise (the counter's last word: "NOIS").
pub const NOISE_STREAM: u32 = 0x4E4F_4953;

const M0: u32 = 0xD251_1F53;
const M1: u32 = 0xCD9E_8D57;
const W0: u32 = 0x9E37_79B9;
const W1: u32 = 0xBB67_AE85;

/// Philox4x32 with 10 rounds.
pub fn philox4x32_10(counter: [u32; 4], key: [u32; 2]) -> [u32; 4] {
    let mut c = counter;
    let mut k = key;
    for _ in 0..10 {
        let p0 = u64::from(M0) * u64::from(c[0]);
        let p1 = u64::from(M1) * u64::from(c[2]);
        c = [
            (p1 >> 32) as u32 ^ c[1] ^ k[0],
            p1 as u32,
            (p0 >> 32) as u32 ^ c[3] ^ k[1],
            p0 as u32,
        ];
        k = [k[0].wrapping_add(W0), k[1].wrapping_add(W1)];
    }
    c
}

/// The key of a 64-bit seed.
pub fn key_of(seed: u64) -> [u32; 2] {
    [seed as u32, (seed >> 32) as u32]
}

/// The counter of row `index` at training step `step` in stream `stream`.
pub fn counter_of(index: u32, step: u64, stream: u32) -> [u32; 4] {
    [index, step as u32, (step >> 32) as u32, stream]
}

/// Three standard normals from one Philox block by Box–Muller (u1 ∈ (0, 1] and u2 ∈ [0, 1)
/// from the top 24 bits of each word), as the GPU computes them.
pub fn normal3(counter: [u32; 4], key: [u32; 2]) -> [f32; 3] {
    let w = philox4x32_10(counter, key);
    let inv24 = 1.0 / 16_777_216.0f32;
    let u1 = ((w[0] >> 8) + 1) as f32 * inv24;
    let u2 = (w[1] >> 8) as f32 * inv24;
    let u3 = ((w[2] >> 8) + 1) as f32 * inv24;
    let u4 = (w[3] >> 8) as f32 * inv24;
    let two_pi = std::f32::consts::TAU;
    let r1 = (-2.0 * u1.ln()).sqrt();
    let r2 = (-2.0 * u3.ln()).sqrt();
    [
        r1 * (two_pi * u2).cos(),
        r1 * (two_pi * u2).sin(),
        r2 * (two_pi * u4).cos(),
    ]
}
