// Stable LSD radix sort of the intersection records, one 4-bit digit per pass, step 1: each
// workgroup counts the digits of its block of 1024 records and writes the 16 counts
// digit-major (`hist[digit * blocks + block]`), so one exclusive scan of `hist` gives every
// (digit, block) its first output slot.
#import lib/splat_structs.wgsl

struct SplatRadixParams {
    // Number of records.
    m: u32,
    // Bit offset of the digit.
    shift: u32,
    // 0: sort by the depth key, 1: by the tile id.
    key_sel: u32,
    // Blocks of 1024 records.
    blocks: u32,
}

@group(0) @binding(0) var<uniform> rp: SplatRadixParams;
@group(0) @binding(1) var<storage, read> src: array<SplatTileKey>;
@group(0) @binding(2) var<storage, read_write> hist: array<u32>;

var<workgroup> counts: array<atomic<u32>, 16>;

@compute @workgroup_size(256)
fn main(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let block = wid.x + wid.y * nwg.x;
    if block >= rp.blocks {
        return;
    }
    if lid < 16u {
        atomicStore(&counts[lid], 0u);
    }
    workgroupBarrier();
    let base = block * 1024u + lid * 4u;
    for (var k = 0u; k < 4u; k++) {
        let i = base + k;
        if i < rp.m {
            let e = src[i];
            let key = select(e.depth, e.tile, rp.key_sel == 1u);
            atomicAdd(&counts[(key >> rp.shift) & 15u], 1u);
        }
    }
    workgroupBarrier();
    if lid < 16u {
        hist[lid * rp.blocks + block] = atomicLoad(&counts[lid]);
    }
}
