// Host-shared records of the splatting kernels and the tile rule they share.
//
// `CameraConsts`, `Projected` and `ProjectedGrad` mirror the `#[repr(C)]` + Pod structs of
// `r4d_splat::kernels` / `r4d_splat::project`, `SplatProjectParams` the one of
// `r4d_gpu::splat`, field for field (a test compares the layouts naga reflects with
// the Rust ones). `Projected` and `ProjectedGrad` use scalar fields (a `vec3<f32>` would be
// 16-byte aligned), so they are 10 f32 + 2 u32 = 48 bytes and 9 f32 = 36 bytes, like
// `Projected<f32>` and `ProjectedGrad<f32>`.

struct CameraConsts {
    // World-to-camera rotation rows (w unused).
    rot0: vec4<f32>,
    rot1: vec4<f32>,
    rot2: vec4<f32>,
    trans: vec4<f32>,
    campos: vec4<f32>,
    background: vec4<f32>,
    // fx, fy, cx, cy (cy of the full image for a cropped camera).
    intrinsics: vec4<f32>,
    near_far: vec2<f32>,
    size: vec2<u32>,
    tiles: vec2<u32>,
    antialiased: u32,
    sh_degree: u32,
    // Frustum clamp of x/z and y/z: (x+, x-, y+, y-), the full image's for a cropped camera
    // (computed on the host, `CamParams::lims`).
    lims: vec4<f32>,
    // The rows `rasterize` and `rasterize_vjp` composite: rows.x .. rows.y of the `size.y`
    // rows (their images and dL/drgb hold those rows only); z, w unused.
    rows: vec4<u32>,
}

// The first row of tiles covering the composited rows (the dispatch's y = 0).
fn splat_first_tile_row(cam: CameraConsts) -> u32 {
    return cam.rows.x / SPLAT_TILE;
}

struct Projected {
    mean_x: f32,
    mean_y: f32,
    conic_a: f32,
    conic_b: f32,
    conic_c: f32,
    depth: f32,
    opacity: f32,
    color_r: f32,
    color_g: f32,
    color_b: f32,
    radius_x: u32,
    radius_y: u32,
}

// dL/d(a Projected); depth gets none.
struct ProjectedGrad {
    mean_x: f32,
    mean_y: f32,
    conic_a: f32,
    conic_b: f32,
    conic_c: f32,
    opacity: f32,
    color_r: f32,
    color_g: f32,
    color_b: f32,
}

// Offsets of the ProjectedGrad fields in f32 units (`rasterize_vjp` adds into a flat array).
const PG_MEAN: u32 = 0u;
const PG_CONIC: u32 = 2u;
const PG_OPACITY: u32 = 5u;
const PG_COLOR: u32 = 6u;
const PG_LEN: u32 = 9u;

// The per-Gaussian kernels' sizes (`project`, `project_vjp`, `project_vjp_sh`).
struct SplatProjectParams {
    n: u32,
    has_f: u32,
    sh_degree: u32,
    // SH values per Gaussian (K * 3).
    sh_len: u32,
}

// One (tile, Gaussian) intersection while it is sorted: the tile id, the depth as an
// order-preserving u32 and the Gaussian index.
struct SplatTileKey {
    tile: u32,
    depth: u32,
    id: u32,
}

const SPLAT_TILE: u32 = 16u;

// The depth as a u32 whose unsigned order is f32 `total_cmp` order (sign bit flipped for
// non-negative values, all bits flipped for negative ones).
fn splat_depth_key(z: f32) -> u32 {
    let b = bitcast<u32>(z);
    return select(b ^ 0x80000000u, ~b, (b & 0x80000000u) != 0u);
}

// `[floor((u - r) / 16), ceil((u + r) / 16))` clamped to `[0, n]`, computed exactly (the
// reference evaluates it in f64): with `u = i + f`, `i = floor(u)`, `0 <= f < 1` and `r` an
// integer, `floor((u - r) / 16) = floor((i - r) / 16)` and `ceil((u + r) / 16)` is
// `floor((i + r) / 16) + 1` when `f > 0`, else `ceil((i + r) / 16)`. NaN centres touch no
// tile (as in the reference); |u| and r are clamped at 2^29 (far outside any image).
fn splat_tile_span(u: f32, r: u32, n: u32) -> vec2<u32> {
    if (bitcast<u32>(u) & 0x7fffffffu) > 0x7f800000u {
        return vec2<u32>(0u, 0u);
    }
    let uc = clamp(u, -536870912.0, 536870912.0);
    let fl = floor(uc);
    let ui = i32(fl);
    let ri = i32(min(r, 536870912u));
    let lo = (ui - ri) >> 4u;
    let s = ui + ri;
    var hi = (s + 15) >> 4u;
    if uc > fl {
        hi = (s >> 4u) + 1;
    }
    let ni = i32(n);
    return vec2<u32>(u32(clamp(lo, 0, ni)), u32(clamp(hi, 0, ni)));
}

// The tile rectangle (x0, x1, y0, y1) of a projected Gaussian (`r4d_splat::raster::tile_rect`).
fn splat_tile_rect(p: Projected, tiles: vec2<u32>) -> vec4<u32> {
    let x = splat_tile_span(p.mean_x, p.radius_x, tiles.x);
    let y = splat_tile_span(p.mean_y, p.radius_y, tiles.y);
    return vec4<u32>(x.x, x.y, y.x, y.y);
}

fn splat_visible(p: Projected) -> bool {
    return p.radius_x != 0u || p.radius_y != 0u;
}

// The simulation link (`r4d_splat::kernels::LinkConsts`): particle `s < simulated` moves
// Gaussian `simulated[s]` to `A x + t` (rows `to_world[i] = [A_i0, A_i1, A_i2, t_i]`) with
// deformation gradient `R^T F R` (`rot` the rows of R).
struct LinkConsts {
    to_world: array<vec4<f32>, 3>,
    rot: array<vec4<f32>, 3>,
    inv_scale: f32,
    simulated: u32,
    particles: u32,
    _pad: u32,
}
