// The end of a substep's reverse sweep, one thread per particle: reverse of the particle
// boundary conditions (impulses, velocity overrides, in reverse order) and of the RPIC
// damping, the particle's adjoint state before the substep (in place: `adj_x` holds the G2P
// position adjoint on entry), and its parameter adjoints [mu, lambda, plastic viscosity,
// Drucker-Prager alpha, density, hardening coefficient] (`pgrad`, 6 floats per particle,
// `r4d_mpm::params::PARAM_ADJOINTS`; `reduce_slots` sums them per slot). Mirrors the end of `r4d_mpm::adjoint::particle_vjp::particle_stage_vjp`.
#import lib/transfer_vjp.wgsl

@group(0) @binding(0) var<uniform> c: StepConsts;
@group(0) @binding(1) var<uniform> counts: Counts;
@group(0) @binding(2) var<storage, read> sbar: array<f32>;
@group(0) @binding(3) var<storage, read> info: array<f32>;
@group(0) @binding(4) var<storage, read> pbcs: array<ParticleBc>;
@group(0) @binding(5) var<storage, read_write> adj_x: array<f32>;
@group(0) @binding(6) var<storage, read_write> adj_v: array<f32>;
@group(0) @binding(7) var<storage, read_write> adj_c: array<f32>;
@group(0) @binding(8) var<storage, read_write> adj_plastic: array<f32>;
@group(0) @binding(9) var<storage, read_write> pgrad: array<f32>;

// Returns [mu, lambda, eta, alpha] adjoints; the density adjoint goes to `dens`, the
// hardening coefficient's to `hard`.
fn finish(i: u32, dens: ptr<function, f32>, hard: ptr<function, f32>) -> vec4<f32> {
    let o = SBAR_STRIDE * i;
    if sbar[o + SBAR_FLAG] == 0.0 {
        for (var q = 0u; q < 3u; q++) {
            adj_x[3u * i + q] = 0.0;
            adj_v[3u * i + q] = 0.0;
        }
        for (var e = 0u; e < 9u; e++) {
            adj_c[9u * i + e] = 0.0;
        }
        adj_plastic[2u * i] = 0.0;
        adj_plastic[2u * i + 1u] = 0.0;
        *dens = 0.0;
        *hard = 0.0;
        return vec4<f32>(0.0);
    }
    let ib = INFO_STRIDE * i;
    let p0 = vec3<f32>(info[ib], info[ib + 1u], info[ib + 2u]);
    let vol0 = info[ib + 3u];
    let m = info[ib + 4u];
    var v_bar = vec3<f32>(sbar[o + 3u], sbar[o + 4u], sbar[o + 5u]);
    var m_bar = sbar[o + 15u];
    for (var bb = c.n_particle_bcs; bb > 0u; bb--) {
        let bc = pbcs[bb - 1u];
        let d = abs(p0 - bc.point);
        if !(window_active(bc.start, bc.end, c.time) && d.x < bc.size.x && d.y < bc.size.y && d.z < bc.size.z) {
            continue;
        }
        if bc.kind == PBC_IMPULSE {
            m_bar = m_bar - dot(bc.vector, v_bar) * c.dt / (m * m);
        } else if bc.kind == PBC_VELOCITY {
            v_bar = vec3<f32>(0.0);
        }
    }
    for (var q = 0u; q < 3u; q++) {
        adj_x[3u * i + q] = adj_x[3u * i + q] + sbar[o + q];
        adj_v[3u * i + q] = v_bar[q];
    }
    var r: array<f32, 9>;
    for (var e = 0u; e < 9u; e++) {
        r[e] = sbar[o + 6u + e];
    }
    // The damping map is linear and its transpose has the same form.
    let cb = mat3_to_rows(damped_affine(mat3_from_rows(r), c.rpic_damping));
    // stress_vjp left the stress's share of C's adjoint here (the fluid's; 0 otherwise).
    for (var e = 0u; e < 9u; e++) {
        adj_c[9u * i + e] = adj_c[9u * i + e] + cb[e];
    }
    *dens = m_bar * vol0;
    *hard = sbar[o + SBAR_HARDENING];
    let q = o + SBAR_PARAMS;
    return vec4<f32>(sbar[q], sbar[q + 1u], sbar[q + 2u], sbar[q + 3u]);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear_id(gid, nwg, 64u);
    if i >= counts.particles {
        return;
    }
    var dens = 0.0;
    var hard = 0.0;
    let val = finish(i, &dens, &hard);
    pgrad[PGRAD_STRIDE * i] = val.x;
    pgrad[PGRAD_STRIDE * i + 1u] = val.y;
    pgrad[PGRAD_STRIDE * i + 2u] = val.z;
    pgrad[PGRAD_STRIDE * i + 3u] = val.w;
    pgrad[PGRAD_STRIDE * i + 4u] = dens;
    pgrad[PGRAD_STRIDE * i + 5u] = hard;
}
