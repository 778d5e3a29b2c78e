// Composites every pixel of rows `cam.rows` (the image holds those rows): one workgroup per
// 16x16 tile of the rows of tiles covering them (the dispatch's y counts from the first),
// one thread per pixel, the tile's Gaussians (front to back) loaded 256 at a time into
// workgroup memory; per pixel exactly `r4d_splat::raster::composite_pixel` (the per-Gaussian rule is lib/composite.wgsl, shared
// with the VJP); rgb + T * background, alpha = 1 - T, depth = D / max(1 - T, 1e-10), and the
// VJP's tape: the final T and one past the tile-list position of the last Gaussian
// composited (`PixelOut::last`).
// The workgroup stops loading once every pixel of the tile has stopped.
#import lib/composite.wgsl

@group(0) @binding(0) var<uniform> cam: CameraConsts;
@group(0) @binding(1) var<storage, read> proj: array<Projected>;
@group(0) @binding(2) var<storage, read> offsets: array<u32>;
@group(0) @binding(3) var<storage, read> ids: array<u32>;
@group(0) @binding(4) var<storage, read_write> out_rgb: array<f32>;
@group(0) @binding(5) var<storage, read_write> out_alpha: array<f32>;
@group(0) @binding(6) var<storage, read_write> out_depth: array<f32>;
@group(0) @binding(7) var<storage, read_write> out_t: array<f32>;
@group(0) @binding(8) var<storage, read_write> out_last: array<u32>;

const BATCH: u32 = 256u;

// (u, v, opacity, s_cut)
var<workgroup> s_geo: array<vec4<f32>, 256>;
// (a, b, c, depth)
var<workgroup> s_conic: array<vec4<f32>, 256>;
var<workgroup> s_color: array<vec4<f32>, 256>;
var<workgroup> s_range: vec2<u32>;
var<workgroup> s_done: atomic<u32>;
var<workgroup> s_done_copy: u32;

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
        atomicStore(&s_done, 0u);
    }
    let range = workgroupUniformLoad(&s_range);
    let i = wid.x * SPLAT_TILE + lid3.x;
    let j = ty * SPLAT_TILE + lid3.y;
    let inside = i < cam.size.x && j >= cam.rows.x && j < cam.rows.y;
    var done = !inside;
    if done {
        atomicAdd(&s_done, 1u);
    }
    let px = f32(i) + 0.5;
    let py = f32(j) + 0.5;
    var t = 1.0;
    var last = 0u;
    var rgb = vec3<f32>(0.0);
    var depth = 0.0;
    let total = select(0u, range.y - range.x, range.y > range.x);
    let batches = (total + BATCH - 1u) / BATCH;
    for (var b = 0u; b < batches; b++) {
        // Everyone is done with the previous batch (and has counted itself if it stopped).
        workgroupBarrier();
        if lid == 0u {
            s_done_copy = atomicLoad(&s_done);
        }
        if workgroupUniformLoad(&s_done_copy) >= 256u {
            break;
        }
        let start = b * BATCH;
        let k = range.x + start + lid;
        if k < range.y {
            let p = proj[ids[k]];
            s_geo[lid] = staged_geometry(p);
            s_conic[lid] = vec4<f32>(p.conic_a, p.conic_b, p.conic_c, p.depth);
            s_color[lid] = vec4<f32>(p.color_r, p.color_g, p.color_b, 0.0);
        }
        workgroupBarrier();
        if !done {
            let cnt = min(BATCH, total - start);
            for (var q = 0u; q < cnt; q++) {
                let con = s_conic[q];
                let h = composite_hit(s_geo[q], con.xyz, px, py);
                if !h.hit {
                    continue;
                }
                let t_next = t * (1.0 - h.alpha);
                if composite_stops(t_next) {
                    done = true;
                    break;
                }
                last = start + q + 1u;
                let wgt = h.alpha * t;
                let col = s_color[q];
                rgb.x += wgt * col.x;
                rgb.y += wgt * col.y;
                rgb.z += wgt * col.z;
                depth += wgt * con.w;
                t = t_next;
            }
            if done {
                atomicAdd(&s_done, 1u);
            }
        }
    }
    if inside {
        let pix = (j - cam.rows.x) * cam.size.x + i;
        out_rgb[3u * pix] = rgb.x + t * cam.background.x;
        out_rgb[3u * pix + 1u] = rgb.y + t * cam.background.y;
        out_rgb[3u * pix + 2u] = rgb.z + t * cam.background.z;
        let a = 1.0 - t;
        out_alpha[pix] = a;
        out_depth[pix] = depth / max(a, 1e-10);
        out_t[pix] = t;
        out_last[pix] = last;
    }
}
