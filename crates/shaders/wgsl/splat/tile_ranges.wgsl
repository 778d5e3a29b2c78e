// Binning, last step: from the records sorted by (tile, depth, index), the Gaussian ids and
// each tile's start (`offsets[t]` = first record of tile >= t; `offsets[tiles]` = m), as
// `r4d_splat::raster::bin_tiles` lays them out.
#import lib/splat_structs.wgsl

struct SplatRangeParams {
    m: u32,
    tiles: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> rp: SplatRangeParams;
@group(0) @binding(1) var<storage, read> sorted: array<SplatTileKey>;
@group(0) @binding(2) var<storage, read_write> offsets: array<u32>;
@group(0) @binding(3) var<storage, read_write> ids: array<u32>;

const WG: u32 = 256u;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let k = gid.x + gid.y * nwg.x * WG;
    if k >= rp.m {
        return;
    }
    let e = sorted[k];
    ids[k] = e.id;
    let t = min(e.tile, rp.tiles);
    var first = 0u;
    if k > 0u {
        first = min(sorted[k - 1u].tile, rp.tiles) + 1u;
    }
    for (var tt = first; tt <= t; tt++) {
        offsets[tt] = k;
    }
    if k + 1u == rp.m {
        for (var tt = t + 1u; tt <= rp.tiles; tt++) {
            offsets[tt] = rp.m;
        }
    }
}
