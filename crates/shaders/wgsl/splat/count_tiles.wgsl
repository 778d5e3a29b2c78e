// Binning, step 1: the number of 16x16 tiles each Gaussian touches (0 when culled), per
// `r4d_splat::raster::tile_rect`. The host scans these counts into each Gaussian's first
// slot in the intersection list (entry n of the n + 1 counts stays 0 and becomes the total).
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
@group(0) @binding(3) var<storage, read_write> counts: array<u32>;

const WG: u32 = 256u;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let g = gid.x + gid.y * nwg.x * WG;
    if g >= bp.n {
        return;
    }
    let p = proj[g];
    var c = 0u;
    if splat_visible(p) {
        let r = splat_tile_rect(p, cam.tiles);
        if r.y > r.x && r.w > r.z {
            c = (r.y - r.x) * (r.w - r.z);
        }
    }
    counts[g] = c;
}
