// Packs the per-particle constants the reverse kernels read into one record per particle
// (`info`, INFO_STRIDE floats: x0, vol0, mass, slot bits; layout in lib/transfer_vjp.wgsl),
// one thread per particle, at the start of each reverse particle stage (the masses follow the
// fitted densities).
#import lib/transfer_vjp.wgsl

@group(0) @binding(0) var<uniform> counts: Counts;
@group(0) @binding(1) var<storage, read> x0: array<f32>;
@group(0) @binding(2) var<storage, read> vol0: array<f32>;
@group(0) @binding(3) var<storage, read> mass: array<f32>;
@group(0) @binding(4) var<storage, read> slot_of: array<u32>;
@group(0) @binding(5) var<storage, read_write> info: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear_id(gid, nwg, 64u);
    if i >= counts.particles {
        return;
    }
    let o = INFO_STRIDE * i;
    info[o] = x0[3u * i];
    info[o + 1u] = x0[3u * i + 1u];
    info[o + 2u] = x0[3u * i + 2u];
    info[o + 3u] = vol0[i];
    info[o + 4u] = mass[i];
    info[o + 5u] = bitcast<f32>(slot_of[i]);
    info[o + 6u] = 0.0;
    info[o + 7u] = 0.0;
}
