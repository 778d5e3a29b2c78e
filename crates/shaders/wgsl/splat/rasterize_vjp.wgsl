// VJP of `rasterize.wgsl` for dL/drgb of rows `cam.rows` (laid out as those rows), added to
// the gradients in `grid_atomic`: one workgroup per 16x16 tile of the rows of tiles covering
// them, one thread per pixel, per pixel exactly `r4d_splat::raster::trace_back` then
// `composite_pixel_vjp` (the per-Gaussian rule is lib/composite.wgsl, shared with the
// forward).
//
// 1. The forward's tape: each pixel reads its final transmittance T and `last`, one past the
//    tile-list position of the last Gaussian it composited (written by `rasterize.wgsl`), so
//    nothing is composited again. Pixels outside the rows or with dL/drgb = 0 take no part.
// 2. Back to front: from the workgroup's largest `last` down, the tile's Gaussians are staged
//    BATCH at a time in workgroup memory; each pixel walks them in reverse, skips those past
//    its `last` or that fail the same tests as the forward, recovers the transmittance in front
//    of each composited Gaussian as `T / (1 - alpha)` and accumulates, as the reference does,
//    `behind` (the background's and later Gaussians' share of dL/drgb . colour) and the
//    Gaussian's gradients of colour, opacity, mean2d and conic (none but colour when alpha hit
//    the 0.999 cap).
// 3. Reduction: pixels add their contributions to a workgroup accumulator per staged Gaussian
//    (compare-exchange on the f32 bits in workgroup memory: float atomics on workgroup memory
//    are not a wgpu feature), and after each batch the workgroup adds the nonzero sums to the
//    global `ProjectedGrad` array with one float atomic each (`#import atomic`: native
//    `atomic<f32>` or a compare-exchange loop).
#import lib/composite.wgsl
#import atomic

@group(0) @binding(0) var<uniform> cam: CameraConsts;
@group(0) @binding(1) var<storage, read> proj: array<Projected>;
@group(0) @binding(2) var<storage, read> offsets: array<u32>;
@group(0) @binding(3) var<storage, read> ids: array<u32>;
@group(0) @binding(4) var<storage, read> t_final: array<f32>;
@group(0) @binding(5) var<storage, read> last_of: array<u32>;
@group(0) @binding(6) var<storage, read> d_rgb: array<f32>;
// `ProjectedGrad` records as 9 f32 each: the kernel adds to them (the host zeroes them once
// per projection, so that several bands of rows sum into them).
@group(0) @binding(7) var<storage, read_write> grid_atomic: array<AtomicF32>;

const BATCH: u32 = 128u;
const THREADS: u32 = 256u;

// (u, v, opacity, s_cut)
var<workgroup> s_geo: array<vec4<f32>, BATCH>;
// (a, b, c, unused)
var<workgroup> s_conic: array<vec4<f32>, BATCH>;
// (r, g, b, unused)
var<workgroup> s_color: array<vec4<f32>, BATCH>;
var<workgroup> s_id: array<u32, BATCH>;
// Per staged Gaussian, its 9 gradient sums (f32 bits).
var<workgroup> s_grad: array<atomic<u32>, BATCH * PG_LEN>;
var<workgroup> s_range: vec2<u32>;
var<workgroup> s_last: atomic<u32>;
var<workgroup> s_last_copy: u32;

fn wg_add(i: u32, v: f32) {
    var old = atomicLoad(&s_grad[i]);
    loop {
        let r = atomicCompareExchangeWeak(&s_grad[i], old, bitcast<u32>(bitcast<f32>(old) + v));
        if r.exchanged {
            break;
        }
        old = r.old_value;
    }
}

// Stages tile-list positions `start ..` (up to `end`) of the tile starting at `base`.
fn stage(lid: u32, base: u32, start: u32, end: u32) {
    let k = start + lid;
    if lid < BATCH && k < end {
        let id = ids[base + k];
        let p = proj[id];
        s_geo[lid] = staged_geometry(p);
        s_conic[lid] = vec4<f32>(p.conic_a, p.conic_b, p.conic_c, 0.0);
        s_color[lid] = vec4<f32>(p.color_r, p.color_g, p.color_b, 0.0);
        s_id[lid] = id;
    }
}

@compute @workgroup_size(16, 16)
fn main(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(local_invocation_id) lid3: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let ty = wid.y + splat_first_tile_row(cam);
    let tile = wid.x + ty * cam.tiles.x;
    if lid == 0u {
        s_range = vec2<u32>(offsets[tile], offsets[tile + 1u]);
        atomicStore(&s_last, 0u);
    }
    for (var e = lid; e < BATCH * PG_LEN; e += THREADS) {
        atomicStore(&s_grad[e], 0u);
    }
    let range = workgroupUniformLoad(&s_range);
    let total = select(0u, range.y - range.x, range.y > range.x);
    let i = wid.x * SPLAT_TILE + lid3.x;
    let j = ty * SPLAT_TILE + lid3.y;
    let inside = i < cam.size.x && j >= cam.rows.x && j < cam.rows.y;
    var d = vec3<f32>(0.0);
    if inside {
        let pix = (j - cam.rows.x) * cam.size.x + i;
        d = vec3<f32>(d_rgb[3u * pix], d_rgb[3u * pix + 1u], d_rgb[3u * pix + 2u]);
    }
    // 1. The forward's tape.
    var t = 1.0;
    var last = 0u;
    if inside && any(d != vec3<f32>(0.0)) {
        let pix = (j - cam.rows.x) * cam.size.x + i;
        t = t_final[pix];
        last = min(last_of[pix], total);
    }
    let px = f32(i) + 0.5;
    let py = f32(j) + 0.5;
    atomicMax(&s_last, last);
    workgroupBarrier();
    if lid == 0u {
        s_last_copy = atomicLoad(&s_last);
    }
    let wg_last = workgroupUniformLoad(&s_last_copy);

    // 2. Back to front.
    var behind = t * dot(d, cam.background.xyz);
    let back_batches = (wg_last + BATCH - 1u) / BATCH;
    for (var bb = back_batches; bb > 0u; bb--) {
        let start = (bb - 1u) * BATCH;
        // The previous batch's flush is done with the staging arrays.
        workgroupBarrier();
        stage(lid, range.x, start, wg_last);
        workgroupBarrier();
        let hi = min(BATCH, select(0u, last - start, last > start));
        for (var qq = hi; qq > 0u; qq--) {
            let q = qq - 1u;
            let con = s_conic[q];
            let h = composite_hit(s_geo[q], con.xyz, px, py);
            if !h.hit {
                continue;
            }
            let alpha = h.alpha;
            let g = h.g;
            let capped = h.capped;
            let dx = h.dx;
            let dy = h.dy;
            let one_minus = 1.0 - alpha;
            // Transmittance in front of this Gaussian.
            let t_front = t / one_minus;
            let w = alpha * t_front;
            let col = s_color[q].xyz;
            let gc = dot(d, col);
            let d_alpha = t_front * gc - behind / one_minus;
            behind += w * gc;
            t = t_front;
            let o = q * PG_LEN;
            wg_add(o + PG_COLOR, d.x * w);
            wg_add(o + PG_COLOR + 1u, d.y * w);
            wg_add(o + PG_COLOR + 2u, d.z * w);
            if !capped {
                wg_add(o + PG_OPACITY, d_alpha * g);
                let d_s = -d_alpha * alpha;
                wg_add(o + PG_MEAN, d_s * (con.x * dx + con.y * dy));
                wg_add(o + PG_MEAN + 1u, d_s * (con.z * dy + con.y * dx));
                wg_add(o + PG_CONIC, d_s * 0.5 * dx * dx);
                wg_add(o + PG_CONIC + 1u, d_s * dx * dy);
                wg_add(o + PG_CONIC + 2u, d_s * 0.5 * dy * dy);
            }
        }
        workgroupBarrier();
        // 3. The batch's sums to the global gradients.
        let cnt = min(BATCH, wg_last - start);
        for (var e = lid; e < cnt * PG_LEN; e += THREADS) {
            let v = bitcast<f32>(atomicLoad(&s_grad[e]));
            if v != 0.0 {
                grid_add(s_id[e / PG_LEN] * PG_LEN + e % PG_LEN, v);
            }
            atomicStore(&s_grad[e], 0u);
        }
    }
}
