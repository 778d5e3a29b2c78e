// Stable LSD radix sort, step 2: each workgroup re-reads its block of 1024 records (4
// consecutive ones per thread) and moves each to `hist[digit * blocks + block]` (scanned)
// plus its rank among the block's earlier records with the same digit. The ranks come from
// an inclusive Hillis-Steele scan over the threads of 16 per-digit counters packed as 16-bit
// fields into two vec4<u32> (a block holds at most 1024 records, so no field overflows), then
// a walk over the thread's own records in order: the pass is stable.
#import lib/splat_structs.wgsl

struct SplatRadixParams {
    m: u32,
    shift: u32,
    key_sel: u32,
    blocks: u32,
}

@group(0) @binding(0) var<uniform> rp: SplatRadixParams;
@group(0) @binding(1) var<storage, read> src: array<SplatTileKey>;
@group(0) @binding(2) var<storage, read> hist: array<u32>;
@group(0) @binding(3) var<storage, read_write> dst: array<SplatTileKey>;

var<workgroup> scan_lo: array<vec4<u32>, 256>;
var<workgroup> scan_hi: array<vec4<u32>, 256>;

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
    let base = block * 1024u + lid * 4u;
    var ents: array<SplatTileKey, 4>;
    var digits = array<u32, 4>(16u, 16u, 16u, 16u);
    // Digits 0..7 in `lo`, 8..15 in `hi`; digit d in word (d >> 1) % 4, bits 16 * (d & 1).
    var lo = vec4<u32>(0u);
    var hi = vec4<u32>(0u);
    for (var k = 0u; k < 4u; k++) {
        let i = base + k;
        if i < rp.m {
            let e = src[i];
            ents[k] = e;
            let key = select(e.depth, e.tile, rp.key_sel == 1u);
            let d = (key >> rp.shift) & 15u;
            digits[k] = d;
            let inc = 1u << ((d & 1u) * 16u);
            let w = d >> 1u;
            if w < 4u {
                lo[w] += inc;
            } else {
                hi[w - 4u] += inc;
            }
        }
    }
    scan_lo[lid] = lo;
    scan_hi[lid] = hi;
    for (var off = 1u; off < 256u; off = off << 1u) {
        workgroupBarrier();
        var add_lo = vec4<u32>(0u);
        var add_hi = vec4<u32>(0u);
        if lid >= off {
            add_lo = scan_lo[lid - off];
            add_hi = scan_hi[lid - off];
        }
        workgroupBarrier();
        scan_lo[lid] += add_lo;
        scan_hi[lid] += add_hi;
    }
    workgroupBarrier();
    // Exclusive per-digit ranks of this thread's first record.
    var rank_lo = scan_lo[lid] - lo;
    var rank_hi = scan_hi[lid] - hi;
    for (var k = 0u; k < 4u; k++) {
        let d = digits[k];
        if d < 16u {
            let w = d >> 1u;
            let sh = (d & 1u) * 16u;
            var word = 0u;
            if w < 4u {
                word = rank_lo[w];
                rank_lo[w] += 1u << sh;
            } else {
                word = rank_hi[w - 4u];
                rank_hi[w - 4u] += 1u << sh;
            }
            let rank = (word >> sh) & 0xffffu;
            dst[hist[d * rp.blocks + block] + rank] = ents[k];
        }
    }
}
