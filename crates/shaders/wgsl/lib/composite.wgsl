// The compositing rule of one pixel, written once for the forward rasterizer and its VJP:
// WGSL mirror of the per-Gaussian tests of `r4d_splat::raster::composite_pixel`. A Gaussian is
// skipped when its power `s` is negative or above its cut-off `ln(255 o) + 1e-3`, or when its
// alpha (capped at 0.999) is below 1/255; compositing stops, exclusively, before a Gaussian
// that would bring the transmittance to 1e-4 or below.
#import lib/splat_structs.wgsl

const ALPHA_MAX: f32 = 0.999;
const ALPHA_MIN: f32 = 1.0 / 255.0;
const T_MIN: f32 = 1e-4;

// What a tile stages per Gaussian: (u, v, opacity, cut-off exponent).
fn staged_geometry(p: Projected) -> vec4<f32> {
    return vec4<f32>(p.mean_x, p.mean_y, p.opacity, log(255.0 * p.opacity) + 1e-3);
}

// One staged Gaussian at a pixel centre.
struct Hit {
    // False: the Gaussian is skipped.
    hit: bool,
    // Alpha, capped at ALPHA_MAX.
    alpha: f32,
    // True when the cap applied (only the colour gets a gradient then).
    capped: bool,
    // exp(-s).
    g: f32,
    // Mean minus pixel centre.
    dx: f32,
    dy: f32,
}

// The Gaussian staged as `geo` (staged_geometry) with conic (a, b, c) at pixel (px, py).
fn composite_hit(geo: vec4<f32>, conic: vec3<f32>, px: f32, py: f32) -> Hit {
    var h: Hit;
    h.dx = geo.x - px;
    h.dy = geo.y - py;
    let s = 0.5 * (conic.x * h.dx * h.dx + conic.z * h.dy * h.dy) + conic.y * h.dx * h.dy;
    if s < 0.0 || s > geo.w {
        h.hit = false;
        return h;
    }
    h.g = exp(-s);
    let raw = geo.z * h.g;
    h.capped = raw > ALPHA_MAX;
    h.alpha = min(raw, ALPHA_MAX);
    h.hit = h.alpha >= ALPHA_MIN;
    return h;
}

// True when compositing stops before the Gaussian that would leave transmittance `t_next`.
fn composite_stops(t_next: f32) -> bool {
    return t_next <= T_MIN;
}
