// Reverse of G2P (gather, advection, F update), one thread per particle: from the adjoints of
// the new x, v, C, F it scatters the adjoints of the grid node velocities with float atomics
// and turns `adj_x` into the adjoint of the old position and `adj_f` into that of F_elastic
// (both in place). Mirrors `r4d_mpm::adjoint::transfer_vjp::g2p_vjp`. A particle outside the
// grid is left alone (the particle-stage kernels zero its adjoint, as the CPU does).
#import lib/transfer_vjp.wgsl
#import atomic

@group(0) @binding(0) var<uniform> c: StepConsts;
@group(0) @binding(1) var<uniform> counts: Counts;
@group(0) @binding(2) var<storage, read> nodes: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> x: array<f32>;
@group(0) @binding(4) var<storage, read> fe: array<f32>;
@group(0) @binding(5) var<storage, read_write> adj_x: array<f32>;
@group(0) @binding(6) var<storage, read> adj_v: array<f32>;
@group(0) @binding(7) var<storage, read> adj_c: array<f32>;
@group(0) @binding(8) var<storage, read_write> adj_f: array<f32>;
@group(0) @binding(9) var<storage, read_write> grid_atomic: array<AtomicF32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear_id(gid, nwg, 64u);
    if i >= counts.particles {
        return;
    }
    let n = counts.n_grid;
    let xp = vec3<f32>(x[3u * i], x[3u * i + 1u], x[3u * i + 2u]);
    if !in_domain(xp, c.inv_dx, n) {
        return;
    }
    let st = stencil(xp, c.inv_dx);
    let mls = c.force_form == FORCE_MLS;
    // The forward velocity gradient.
    var gv = mat3x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    for (var a = 0u; a < 3u; a++) {
        for (var b = 0u; b < 3u; b++) {
            for (var o = 0u; o < 3u; o++) {
                let off = vec3<u32>(a, b, o);
                let nv = nodes[vjp_node(st, off, n)].xyz;
                if mls {
                    gv = gv + outer3(vjp_weight(st, off) * nv, vec3<f32>(off) - st.fx);
                } else {
                    gv = gv + outer3(nv, vjp_weight_grad(st, off));
                }
            }
        }
    }
    if mls {
        gv = gv * (4.0 * c.inv_dx);
    } else {
        gv = gv * c.inv_dx;
    }
    var r: array<f32, 9>;
    for (var e = 0u; e < 9u; e++) {
        r[e] = fe[9u * i + e];
    }
    let fem = mat3_from_rows(r);
    for (var e = 0u; e < 9u; e++) {
        r[e] = adj_f[9u * i + e];
    }
    let fb = mat3_from_rows(r);
    for (var e = 0u; e < 9u; e++) {
        r[e] = adj_c[9u * i + e];
    }
    var cm_bar = mat3_from_rows(r);
    let l = mat3_identity() + gv * c.dt;
    let fe_bar = transpose(l) * fb;
    let g_bar = (fb * transpose(fem)) * c.dt;
    if mls {
        cm_bar = cm_bar + g_bar;
    }
    let x_bar = vec3<f32>(adj_x[3u * i], adj_x[3u * i + 1u], adj_x[3u * i + 2u]);
    let v_bar = vec3<f32>(adj_v[3u * i], adj_v[3u * i + 1u], adj_v[3u * i + 2u]);
    let vp_bar = v_bar + c.dt * x_bar;
    let kc = 4.0 * c.inv_dx;
    var f_pos_bar = vec3<f32>(0.0);
    for (var a = 0u; a < 3u; a++) {
        for (var b = 0u; b < 3u; b++) {
            for (var o = 0u; o < 3u; o++) {
                let off = vec3<u32>(a, b, o);
                let idx = vjp_node(st, off, n);
                let vi = nodes[idx].xyz;
                let w = vjp_weight(st, off);
                let dw = vjp_weight_grad(st, off);
                let d = vec3<f32>(off) - st.fx;
                let cd = cm_bar * d;
                let vcd = dot(vi, cd);
                let vvp = dot(vi, vp_bar);
                var nb = w * vp_bar + kc * w * cd;
                for (var ax = 0u; ax < 3u; ax++) {
                    let vcol = dot(vi, cm_bar[ax]);
                    f_pos_bar[ax] += dw[ax] * (vvp + kc * vcd) - kc * w * vcol;
                }
                if !mls {
                    let gb = g_bar * dw;
                    nb = nb + c.inv_dx * gb;
                    let h = vjp_weight_hessian(st, off);
                    for (var ax = 0u; ax < 3u; ax++) {
                        f_pos_bar[ax] += c.inv_dx * dot(vi, g_bar * h[ax]);
                    }
                }
                grid_add(4u * idx, nb.x);
                grid_add(4u * idx + 1u, nb.y);
                grid_add(4u * idx + 2u, nb.z);
            }
        }
    }
    let xo = x_bar + f_pos_bar * c.inv_dx;
    adj_x[3u * i] = xo.x;
    adj_x[3u * i + 1u] = xo.y;
    adj_x[3u * i + 2u] = xo.z;
    let fo = mat3_to_rows(fe_bar);
    for (var e = 0u; e < 9u; e++) {
        adj_f[9u * i + e] = fo[e];
    }
}
