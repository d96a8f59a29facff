// Shared declarations, prepended to every kernel by the Rust side (WGSL has no includes).

// One uniform block for every kernel; each kernel reads the fields it needs.
struct Params {
    num_gaussians: u32,
    num_cameras: u32,
    width: u32,
    height: u32,
    tiles_x: u32,
    tiles_y: u32,
    sh_degree: u32,
    antialiased: u32,
    eps2d: f32,
    near_plane: f32,
    far_plane: f32,
    alpha_max: f32,
    alpha_min: f32,
    t_min: f32,
    radius_extent: f32,
    has_d_alpha: u32,
    // Generic: element count, radix shift, which key word to sort by, block count,
    // segment length and width for the reductions.
    n: u32,
    shift: u32,
    use_hi: u32,
    num_blocks: u32,
    seg_len: u32,
    seg_width: u32,
    // project_backward: bit 0 loads the per-Gaussian accumulators of the previous camera chunk
    // from `carry`, bit 1 stores them there (see project_backward.wgsl).
    carry: u32,
    pad1: u32,
}

// Floats per Gaussian in the packed parameter buffer: mean 3, quat (wxyz) 4, log-scale 3,
// opacity logit 1, SH 16×3 (coefficient-major).
const GP: u32 = 59u;
// Floats per camera: fx fy cx cy, R row-major (9), t (3), background (3), padding (5).
const CAMF: u32 = 24u;
// Floats per screen-space gradient: mean2d 2, conic 3, opacity 1, colour 3.
const SG: u32 = 9u;

// A projected Gaussian in one camera.
struct Splat {
    // x, y (pixels), opacity used for compositing, camera depth.
    xyod: vec4<f32>,
    // conic a, b, c; unused.
    conic: vec4<f32>,
    // colour rgb; unused.
    color: vec4<f32>,
    // inclusive pixel range x0, x1, y0, y1 (x0 > x1 when empty).
    pbox: vec4<i32>,
}

// Linear workgroup index of a dispatch split over x and y (x is at most 65535).
fn group_index(wid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return wid.x + wid.y * nwg.x;
}

// The pixel that invocation `lid` of a (camera, tile) workgroup shades: the forward and the
// backward rasterizers share this layout (16×16 tiles, row-major, pixel centres at +0.5).
struct TilePixel {
    camera: u32,
    px: u32,
    py: u32,
    inside: bool,
    pxi: i32,
    pyi: i32,
    pcx: f32,
    pcy: f32,
}

// `gt` is the workgroup's (camera, tile) index, below num_cameras·tiles.
fn tile_pixel(p: Params, gt: u32, lid: u32) -> TilePixel {
    let tiles = p.tiles_x * p.tiles_y;
    let tile = gt % tiles;
    let px = (tile % p.tiles_x) * 16u + lid % 16u;
    let py = (tile / p.tiles_x) * 16u + lid / 16u;
    return TilePixel(
        gt / tiles,
        px,
        py,
        px < p.width && py < p.height,
        i32(px),
        i32(py),
        f32(px) + 0.5,
        f32(py) + 0.5,
    );
}

// Infinity and NaN have all exponent bits set; testing the bits does not depend on how the
// compiler treats NaN in comparisons.
fn finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}
