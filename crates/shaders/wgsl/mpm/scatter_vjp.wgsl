// Reverse of the P2G scatter, one thread per particle, gathering from the node adjoints (no
// atomics): the adjoints of the particle's position, velocity (after the particle boundary
// conditions), damped C, mass and stress term go to its `sbar` record (layout in
// lib/transfer_vjp.wgsl), with the in-domain flag. Mirrors
// `r4d_mpm::adjoint::transfer_vjp::scatter_vjp`.
#import lib/transfer_vjp.wgsl

@group(0) @binding(0) var<uniform> c: StepConsts;
@group(0) @binding(1) var<uniform> counts: Counts;
@group(0) @binding(2) var<storage, read> x: array<f32>;
@group(0) @binding(3) var<storage, read> v1: array<f32>;
@group(0) @binding(4) var<storage, read> cm: array<f32>;
@group(0) @binding(5) var<storage, read> info: array<f32>;
@group(0) @binding(6) var<storage, read> stress: array<f32>;
@group(0) @binding(7) var<storage, read> grid_in_bar: array<vec4<f32>>;
@group(0) @binding(8) var<storage, read_write> sbar: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear_id(gid, nwg, 64u);
    if i >= counts.particles {
        return;
    }
    let n = counts.n_grid;
    let o = SBAR_STRIDE * i;
    let xp = vec3<f32>(x[3u * i], x[3u * i + 1u], x[3u * i + 2u]);
    if !in_domain(xp, c.inv_dx, n) {
        for (var e = 0u; e < SBAR_STRIDE; e++) {
            sbar[o + e] = 0.0;
        }
        return;
    }
    let st = stencil(xp, c.inv_dx);
    let m = info[INFO_STRIDE * i + 4u];
    let vel = vec3<f32>(v1[3u * i], v1[3u * i + 1u], v1[3u * i + 2u]);
    var r: array<f32, 9>;
    for (var e = 0u; e < 9u; e++) {
        r[e] = cm[9u * i + e];
    }
    let am = damped_affine(mat3_from_rows(r), c.rpic_damping);
    for (var e = 0u; e < 9u; e++) {
        r[e] = stress[9u * i + e];
    }
    let sm = mat3_from_rows(r);
    let mls = c.force_form == FORCE_MLS;
    var mc = am * m;
    if mls {
        mc = mc + sm;
    }
    let zero = mat3x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    var mc_bar = zero;
    var s_bar = zero;
    var f_bar = vec3<f32>(0.0);
    var v_bar = vec3<f32>(0.0);
    var m_bar_out = 0.0;
    for (var a = 0u; a < 3u; a++) {
        for (var b = 0u; b < 3u; b++) {
            for (var oo = 0u; oo < 3u; oo++) {
                let off = vec3<u32>(a, b, oo);
                let nb = grid_in_bar[vjp_node(st, off, n)];
                let mom_bar = nb.xyz;
                let m_bar = nb.w;
                let w = vjp_weight(st, off);
                let dw = vjp_weight_grad(st, off);
                let dpos = (vec3<f32>(off) - st.fx) * c.dx;
                let p = m * vel + mc * dpos;
                let p_dot = dot(p, mom_bar);
                v_bar = v_bar + w * m * mom_bar;
                m_bar_out += w * (dot(vel, mom_bar) + dot(am * dpos, mom_bar)) + w * m_bar;
                mc_bar = mc_bar + outer3(mom_bar, dpos) * w;
                for (var ax = 0u; ax < 3u; ax++) {
                    f_bar[ax] += dw[ax] * (p_dot + m * m_bar) - w * dot(mc[ax], mom_bar) * c.dx;
                }
                if !mls {
                    s_bar = s_bar + outer3(mom_bar, dw);
                    let h = vjp_weight_hessian(st, off);
                    for (var ax = 0u; ax < 3u; ax++) {
                        f_bar[ax] += dot(sm * h[ax], mom_bar);
                    }
                }
            }
        }
    }
    let a_bar = mc_bar * m;
    if mls {
        s_bar = s_bar + mc_bar;
    }
    let xb = f_bar * c.inv_dx;
    let ab = mat3_to_rows(a_bar);
    let sb = mat3_to_rows(s_bar);
    for (var q = 0u; q < 3u; q++) {
        sbar[o + q] = xb[q];
        sbar[o + 3u + q] = v_bar[q];
    }
    for (var e = 0u; e < 9u; e++) {
        sbar[o + 6u + e] = ab[e];
        sbar[o + 16u + e] = sb[e];
    }
    sbar[o + 15u] = m_bar_out;
    for (var e = SBAR_PARAMS; e < SBAR_STRIDE; e++) {
        sbar[o + e] = 0.0;
    }
    sbar[o + SBAR_FLAG] = 1.0;
}
