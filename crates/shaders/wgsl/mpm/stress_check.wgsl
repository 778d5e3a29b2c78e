// Test-only kernel: runs `stress_update` (lib/constitutive.wgsl) on a batch of independent
// particles so crates/backend-wgpu/tests/constitutive.rs can compare it with the Rust
// reference `r4d_mpm::constitutive::stress_update::<f32>`.
//
// Bindings (group 0, bound by position):
//   0: uniform StressCheckParams { dt, n, _pad0, _pad1 }   (16 bytes)
//   1: f_trial   array<f32>   9 per particle, row-major (read)
//   2: plastic   array<f32>   2 per particle: [yield stress, J_p] (read)
//   3: grad_v    array<f32>   9 per particle, row-major (read)
//   4: part      array<u32>   1 per particle: index into `parts` (read)
//   5: parts     array<PartConsts> (read)
//   6: fe_out    array<f32>   9 per particle, row-major (write)
//   7: tau_out   array<f32>   9 per particle, row-major (write)
//   8: plastic_out array<f32> 2 per particle (write)
// One invocation per particle; dispatch n threads in workgroups of 64.
#import lib/structs.wgsl
#import lib/math.wgsl
#import lib/constitutive.wgsl

struct StressCheckParams {
    dt: f32,
    n: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: StressCheckParams;
@group(0) @binding(1) var<storage, read> f_trial: array<f32>;
@group(0) @binding(2) var<storage, read> plastic_in: array<f32>;
@group(0) @binding(3) var<storage, read> grad_v: array<f32>;
@group(0) @binding(4) var<storage, read> part: array<u32>;
@group(0) @binding(5) var<storage, read> parts: array<PartConsts>;
@group(0) @binding(6) var<storage, read_write> fe_out: array<f32>;
@group(0) @binding(7) var<storage, read_write> tau_out: array<f32>;
@group(0) @binding(8) var<storage, read_write> plastic_out: array<f32>;

fn load9_f(i: u32) -> mat3x3<f32> {
    var r: array<f32, 9>;
    for (var k = 0u; k < 9u; k++) {
        r[k] = f_trial[9u * i + k];
    }
    return mat3_from_rows(r);
}

fn load9_g(i: u32) -> mat3x3<f32> {
    var r: array<f32, 9>;
    for (var k = 0u; k < 9u; k++) {
        r[k] = grad_v[9u * i + k];
    }
    return mat3_from_rows(r);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 64u;
    if i >= params.n {
        return;
    }
    let pc = parts[part[i]];
    let st = vec2<f32>(plastic_in[2u * i], plastic_in[2u * i + 1u]);
    let out = stress_update(load9_f(i), pc, st, load9_g(i), params.dt);
    let fe = mat3_to_rows(out.fe);
    let tau = mat3_to_rows(out.tau);
    for (var k = 0u; k < 9u; k++) {
        fe_out[9u * i + k] = fe[k];
        tau_out[9u * i + k] = tau[k];
    }
    plastic_out[2u * i] = out.plastic.x;
    plastic_out[2u * i + 1u] = out.plastic.y;
}
