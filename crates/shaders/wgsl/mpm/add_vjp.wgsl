// dst += src over `counts.particles` floats: how a loss gradient enters an adjoint state on
// the device.
#import lib/structs.wgsl

@group(0) @binding(0) var<uniform> counts: Counts;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read_write> dst: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear_id(gid, nwg, 64u);
    if i < counts.particles {
        dst[i] = dst[i] + src[i];
    }
}
