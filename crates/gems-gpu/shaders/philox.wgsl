// Philox4x32-10 (Salmon et al., "Parallel random numbers: as easy as 1, 2, 3", SC 2011): a
// counter-based generator, so every invocation draws its own numbers from (key, counter) with no
// state. Mirrored bit for bit by rng.rs (tested against the Random123 known-answer vectors).

// High and low 32 bits of a 32x32-bit product (WGSL has no mulhi): 16-bit limbs.
fn mul_hi_lo(a: u32, b: u32) -> vec2<u32> {
    let a_lo = a & 0xffffu;
    let a_hi = a >> 16u;
    let b_lo = b & 0xffffu;
    let b_hi = b >> 16u;
    let p0 = a_lo * b_lo;
    let p1 = a_lo * b_hi;
    let p2 = a_hi * b_lo;
    let p3 = a_hi * b_hi;
    let mid = (p0 >> 16u) + (p1 & 0xffffu) + (p2 & 0xffffu);
    let hi = p3 + (p1 >> 16u) + (p2 >> 16u) + (mid >> 16u);
    return vec2<u32>(hi, a * b);
}

fn philox4x32_10(counter: vec4<u32>, key: vec2<u32>) -> vec4<u32> {
    var c = counter;
    var k = key;
    for (var r = 0u; r < 10u; r++) {
        let p0 = mul_hi_lo(0xD2511F53u, c.x);
        let p1 = mul_hi_lo(0xCD9E8D57u, c.z);
        c = vec4<u32>(p1.x ^ c.y ^ k.x, p1.y, p0.x ^ c.w ^ k.y, p0.y);
        k = k + vec2<u32>(0x9E3779B9u, 0xBB67AE85u);
    }
    return c;
}

// Three standard normals from one Philox block by Box-Muller: u1 in (0, 1], u2 in [0, 1) from the
// top 24 bits of each word.
fn normal3(counter: vec4<u32>, key: vec2<u32>) -> vec3<f32> {
    let w = philox4x32_10(counter, key);
    let inv24 = 1.0 / 16777216.0;
    let u1 = f32((w.x >> 8u) + 1u) * inv24;
    let u2 = f32(w.y >> 8u) * inv24;
    let u3 = f32((w.z >> 8u) + 1u) * inv24;
    let u4 = f32(w.w >> 8u) * inv24;
    let two_pi = 6.283185307179586;
    let r1 = sqrt(-2.0 * log(u1));
    let r2 = sqrt(-2.0 * log(u3));
    return vec3<f32>(r1 * cos(two_pi * u2), r1 * sin(two_pi * u2), r2 * cos(two_pi * u4));
}
