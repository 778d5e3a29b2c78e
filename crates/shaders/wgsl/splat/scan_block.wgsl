// Exclusive prefix sum, first level: each workgroup scans a block of 1024 u32 (4 per
// thread, then a Hillis-Steele scan of the 256 thread sums), writes the block's exclusive
// prefix sums in place and its total to `sums[block]`. The host scans `sums` recursively and
// adds them back with `scan_add`.

struct SplatScanParams {
    n: u32,
    blocks: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> sp: SplatScanParams;
@group(0) @binding(1) var<storage, read_write> data: array<u32>;
@group(0) @binding(2) var<storage, read_write> sums: array<u32>;

var<workgroup> tmp: array<u32, 256>;

@compute @workgroup_size(256)
fn main(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let block = wid.x + wid.y * nwg.x;
    if block >= sp.blocks {
        return;
    }
    let base = block * 1024u + lid * 4u;
    var part: array<u32, 4>;
    var s = 0u;
    for (var k = 0u; k < 4u; k++) {
        let i = base + k;
        part[k] = s;
        if i < sp.n {
            s += data[i];
        }
    }
    tmp[lid] = s;
    for (var off = 1u; off < 256u; off = off << 1u) {
        workgroupBarrier();
        var add = 0u;
        if lid >= off {
            add = tmp[lid - off];
        }
        workgroupBarrier();
        tmp[lid] += add;
    }
    workgroupBarrier();
    let excl = tmp[lid] - s;
    for (var k = 0u; k < 4u; k++) {
        let i = base + k;
        if i < sp.n {
            data[i] = excl + part[k];
        }
    }
    if lid == 255u {
        sums[block] = tmp[255];
    }
}
