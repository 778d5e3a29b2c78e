// Binning, step 2: each visible Gaussian writes a (tile, depth key, index) record for every
// tile of its rectangle, from its scanned offset. Records are laid out by ascending Gaussian
// index, so the stable radix sort keeps equal (tile, depth) keys in index order, as the
// reference's (depth, index) sort does.
#import lib/splat_structs.wgsl

struct SplatBinParams {
    n: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> cam: CameraConsts;
@group(0) @binding(1) var<uniform> bp: SplatBinParams;
@group(0) @binding(2) var<storage, read> proj: array<Projected>;
@group(0) @binding(3) var<storage, read> offsets: array<u32>;
@group(0) @binding(4) var<storage, read_write> keys: array<SplatTileKey>;

const WG: u32 = 256u;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let g = gid.x + gid.y * nwg.x * WG;
    if g >= bp.n {
        return;
    }
    let p = proj[g];
    if !splat_visible(p) {
        return;
    }
    let r = splat_tile_rect(p, cam.tiles);
    let dk = splat_depth_key(p.depth);
    var pos = offsets[g];
    for (var ty = r.z; ty < r.w; ty++) {
        for (var tx = r.x; tx < r.y; tx++) {
            keys[pos] = SplatTileKey(ty * cam.tiles.x + tx, dk, g);
            pos += 1u;
        }
    }
}
