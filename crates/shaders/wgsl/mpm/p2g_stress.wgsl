// The particle stage of P2G: return mapping and Kirchhoff stress per particle; F_trial becomes
// F_elastic, the plastic state is updated, and the scatter's stress term
// `sym(tau) * stress_scale` is stored. Mirrors `r4d_mpm::transfer::particle_stress`.
#import lib/transfer.wgsl
#import lib/constitutive.wgsl

@group(0) @binding(0) var<uniform> c: StepConsts;
@group(0) @binding(1) var<uniform> counts: Counts;
@group(0) @binding(2) var<storage, read> parts: array<PartConsts>;
@group(0) @binding(3) var<storage, read> part: array<u32>;
@group(0) @binding(4) var<storage, read> vol0: array<f32>;
@group(0) @binding(5) var<storage, read> cm: array<f32>;
@group(0) @binding(6) var<storage, read_write> f: array<f32>;
@group(0) @binding(7) var<storage, read_write> plastic: array<f32>;
@group(0) @binding(8) var<storage, read_write> stress: array<f32>;

fn load9(b: u32, which: u32) -> mat3x3<f32> {
    var r: array<f32, 9>;
    for (var e = 0u; e < 9u; e++) {
        if which == 0u {
            r[e] = f[b + e];
        } else {
            r[e] = cm[b + e];
        }
    }
    return mat3_from_rows(r);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear_id(gid, nwg, 64u);
    if i >= counts.particles {
        return;
    }
    let pc = parts[part[i]];
    let out = stress_update(load9(9u * i, 0u), pc, vec2<f32>(plastic[2u * i], plastic[2u * i + 1u]), load9(9u * i, 1u), c.dt);
    let tau = (out.tau + transpose(out.tau)) * (0.5 * stress_scale(vol0[i], c));
    let fe = mat3_to_rows(out.fe);
    let s = mat3_to_rows(tau);
    for (var e = 0u; e < 9u; e++) {
        f[9u * i + e] = fe[e];
        stress[9u * i + e] = s[e];
    }
    plastic[2u * i] = out.plastic.x;
    plastic[2u * i + 1u] = out.plastic.y;
}
