// Sums the per-particle parameter adjoints `pgrad` (6 floats per particle) into their slots'
// accumulators `grad` (6 floats per slot): in workgroup memory first (one tree reduction per
// slot present in the workgroup; particles of a part are contiguous, so usually one or two),
// then one float atomic per slot and field. Mirrors
// `r4d_mpm::reference::reduce_slots_in_order` up to the summation order.
#import lib/structs.wgsl
#import atomic

@group(0) @binding(0) var<uniform> counts: Counts;
@group(0) @binding(1) var<storage, read> pgrad: array<f32>;
@group(0) @binding(2) var<storage, read> slot_of: array<u32>;
@group(0) @binding(3) var<storage, read_write> grid_atomic: array<AtomicF32>;

const NO_SLOT: u32 = 0xffffffffu;

var<workgroup> s_red: array<vec4<f32>, 64>;
var<workgroup> s_red_d: array<vec2<f32>, 64>;
var<workgroup> s_lo: atomic<u32>;
var<workgroup> s_hi: atomic<u32>;
var<workgroup> s_lo_copy: u32;
var<workgroup> s_hi_copy: u32;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = linear_id(gid, nwg, 64u);
    if lid == 0u {
        atomicStore(&s_lo, NO_SLOT);
        atomicStore(&s_hi, 0u);
    }
    workgroupBarrier();
    var val = vec4<f32>(0.0);
    // density, hardening coefficient
    var dens = vec2<f32>(0.0);
    var slot = NO_SLOT;
    if i < counts.particles {
        let o = PGRAD_STRIDE * i;
        val = vec4<f32>(pgrad[o], pgrad[o + 1u], pgrad[o + 2u], pgrad[o + 3u]);
        dens = vec2<f32>(pgrad[o + 4u], pgrad[o + 5u]);
        slot = slot_of[i];
        atomicMin(&s_lo, slot);
        atomicMax(&s_hi, slot);
    }
    workgroupBarrier();
    if lid == 0u {
        s_lo_copy = atomicLoad(&s_lo);
        s_hi_copy = atomicLoad(&s_hi);
    }
    let lo = workgroupUniformLoad(&s_lo_copy);
    let hi = workgroupUniformLoad(&s_hi_copy);
    if lo == NO_SLOT {
        return;
    }
    for (var s = lo; s <= hi; s++) {
        s_red[lid] = select(vec4<f32>(0.0), val, slot == s);
        s_red_d[lid] = select(vec2<f32>(0.0), dens, slot == s);
        workgroupBarrier();
        for (var stride = 32u; stride > 0u; stride = stride / 2u) {
            if lid < stride {
                s_red[lid] = s_red[lid] + s_red[lid + stride];
                s_red_d[lid] = s_red_d[lid] + s_red_d[lid + stride];
            }
            workgroupBarrier();
        }
        if lid == 0u {
            let t = s_red[0];
            let b = PGRAD_STRIDE * s;
            grid_add(b, t.x);
            grid_add(b + 1u, t.y);
            grid_add(b + 2u, t.z);
            grid_add(b + 3u, t.w);
            grid_add(b + 4u, s_red_d[0].x);
            grid_add(b + 5u, s_red_d[0].y);
        }
        workgroupBarrier();
    }
}
