// Zeroes the grid (momentum and mass of every node).
#import lib/structs.wgsl

@group(0) @binding(0) var<uniform> c: StepConsts;
@group(0) @binding(1) var<storage, read_write> nodes: array<vec4<f32>>;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 256u;
    if i < arrayLength(&nodes) {
        nodes[i] = vec4<f32>(0.0);
    }
}
