// Reverse of the particle stress stage (return mapping and Kirchhoff stress), one thread per
// particle. `adj_f` holds the adjoint of F_elastic on entry and that of F_trial on return,
// `adj_plastic` that of the plastic state after the substep on entry and before it on return;
// the particle's adjoints of mu, lambda, plastic viscosity, alpha and the hardening
// coefficient go to `sbar` (reduced per slot by particle_vjp).
//
// Jelly (fixed corotated, F_e = F_trial, plastic state untouched) has a closed form:
//   tau = 2 mu (F F^T - R F^T) + lambda J (J - 1) I,   R = U V^T, R F^T = U diag(s) U^T,
// whose VJP needs the polar rotation's: with M = U^T Rbar V,
//   Fbar += U G V^T,   G_ij = (M_ij - M_ji) / (s_i + s_j)   (i != j).
//
// The other isotropic models mirror `r4d_mpm::adjoint::constitutive_vjp::stress_update_vjp`:
// the scalar part's Jacobian from dual numbers (lib/dual_model.wgsl), the matrix part by the
// derivative of isotropic matrix functions with the same regularisation of repeated singular
// values, in f32 (the CPU evaluates it in f64 with the threshold 4 sqrt(eps) = 6e-8).
#import lib/transfer_vjp.wgsl
#import lib/svd.wgsl
#import lib/dual_model.wgsl

@group(0) @binding(0) var<uniform> c: StepConsts;
@group(0) @binding(1) var<uniform> counts: Counts;
@group(0) @binding(2) var<storage, read> parts: array<PartConsts>;
@group(0) @binding(3) var<storage, read> info: array<f32>;
@group(0) @binding(4) var<storage, read> f_trial: array<f32>;
@group(0) @binding(5) var<storage, read> plastic_in: array<f32>;
@group(0) @binding(6) var<storage, read_write> sbar: array<f32>;
@group(0) @binding(7) var<storage, read_write> adj_f: array<f32>;
@group(0) @binding(8) var<storage, read_write> adj_plastic: array<f32>;
@group(0) @binding(9) var<storage, read> c_in: array<f32>;
@group(0) @binding(10) var<storage, read_write> adj_c: array<f32>;

fn cofactor(m: mat3x3<f32>) -> mat3x3<f32> {
    return mat3x3<f32>(cross(m[1], m[2]), cross(m[2], m[0]), cross(m[0], m[1]));
}

fn frob(a: mat3x3<f32>, b: mat3x3<f32>) -> f32 {
    return dot(a[0], b[0]) + dot(a[1], b[1]) + dot(a[2], b[2]);
}

struct StressBar {
    f: mat3x3<f32>,
    state: vec2<f32>,
    // mu, lambda, eta, alpha
    params: vec4<f32>,
    // hardening coefficient
    h: f32,
}

// Jelly, closed form (`fe_bar` passes through: F_e = F_trial).
fn jelly_vjp(f: mat3x3<f32>, pc: PartConsts, tb: mat3x3<f32>, fe_bar: mat3x3<f32>, state_bar: vec2<f32>) -> StressBar {
    let svd = svd3(f);
    let u = svd.u;
    let s = svd.sigma;
    let vv = svd.v;
    let rot = u * transpose(vv);
    let usu = mat3x3<f32>(u[0] * s.x, u[1] * s.y, u[2] * s.z) * transpose(u);
    let j = s.x * s.y * s.z;
    let trb = tb[0][0] + tb[1][1] + tb[2][2];
    let mu_bar = 2.0 * frob(tb, f * transpose(f) - usu);
    let lambda_bar = trb * j * (j - 1.0);
    // Polar rotation VJP of Rbar = tb F.
    let mm = transpose(u) * (tb * f) * vv;
    var g = mat3x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    for (var a = 0u; a < 3u; a++) {
        for (var b = 0u; b < 3u; b++) {
            if a != b {
                // Element (row a, column b) is m[b][a].
                g[b][a] = (mm[b][a] - mm[a][b]) / (s[a] + s[b]);
            }
        }
    }
    let polar_bar = u * g * transpose(vv);
    let fbar = (tb * f * 2.0 - tb * rot - polar_bar) * (2.0 * pc.mu) + cofactor(f) * (pc.lambda * trb * (2.0 * j - 1.0));
    return StressBar(fe_bar + fbar, state_bar, vec4<f32>(mu_bar, lambda_bar, 0.0, 0.0), 0.0);
}

// The fluid (Rust `fluid_vjp`): tau = eta J (C + C^T) + K J (J - 1) I, K = lambda + 2 mu / 3,
// F_e = cbrt(J) I. Returns the F_trial and constants' adjoints; C's goes to `c_bar`.
fn fluid_vjp(f: mat3x3<f32>, pc: PartConsts, cm: mat3x3<f32>, tb: mat3x3<f32>, fe_bar: mat3x3<f32>, state_bar: vec2<f32>, c_bar: ptr<function, mat3x3<f32>>) -> StressBar {
    let j = determinant(f);
    let k = pc.lambda + (2.0 / 3.0) * pc.mu;
    let eta = pc.plastic_viscosity;
    let contract = frob(tb, cm + transpose(cm));
    let tr_tb = tb[0][0] + tb[1][1] + tb[2][2];
    let tr_fe = fe_bar[0][0] + fe_bar[1][1] + fe_bar[2][2];
    var dc = 0.0;
    if j != 0.0 {
        let cb = pow(abs(j), 1.0 / 3.0) * select(1.0, -1.0, j < 0.0);
        dc = cb / (3.0 * j);
    }
    let j_bar = tr_fe * dc + eta * contract + k * (2.0 * j - 1.0) * tr_tb;
    *c_bar = (tb + transpose(tb)) * (eta * j);
    let k_bar = j * (j - 1.0) * tr_tb;
    return StressBar(cofactor(f) * j_bar, state_bar, vec4<f32>((2.0 / 3.0) * k_bar, k_bar, j * contract, 0.0), 0.0);
}

// 4 sqrt(f32 epsilon).
const REG_EPS: f32 = 1e-5;

// Stable divided difference (g_i - g_j) / (s_i - s_j) (Rust `divided`).
fn divided(g: array<Dual, 3>, s: vec3<f32>, i: u32, j: u32) -> f32 {
    var gg = g;
    let gap = s[i] - s[j];
    let scale = max(max(1.0, abs(s[i])), abs(s[j]));
    if abs(gap) > REG_EPS * scale {
        return (gg[i].v - gg[j].v) / gap;
    }
    return 0.5 * (gg[i].d[i] - gg[i].d[j] + gg[j].d[j] - gg[j].d[i]);
}

fn away_from_zero(x: f32) -> f32 {
    if abs(x) >= REG_EPS {
        return x;
    }
    return select(REG_EPS, -REG_EPS, x < 0.0);
}

// Every isotropic model through duals (Rust `stress_update_vjp_inner`).
fn general_vjp(f: mat3x3<f32>, pc: PartConsts, state: vec2<f32>, tb: mat3x3<f32>, fe_bar: mat3x3<f32>, state_bar: vec2<f32>) -> StressBar {
    let svd = svd3(f);
    let s = svd.sigma;
    let sig = array<Dual, 3>(dvar(s.x, 0u), dvar(s.y, 1u), dvar(s.z, 2u));
    let st = array<Dual, 2>(dvar(state.x, 3u), dvar(state.y, 4u));
    var out = dual_scalar_model(pc, sig, st, dvar(pc.mu, 5u), dvar(pc.lambda, 6u), dvar(pc.plastic_viscosity, 7u), dvar(pc.dp_alpha, 8u), dvar(hardening_coeff(pc), 9u), c.dt);
    let u = svd.u;
    let v = svd.v;
    let g_hat = transpose(u) * fe_bar * v;
    let t_hat = transpose(u) * tb * u;
    var d_bar: array<f32, 10>;
    for (var i = 0u; i < 3u; i++) {
        for (var e = 0u; e < DIRS; e++) {
            d_bar[e] += t_hat[i][i] * out.t[i].d[e];
            if !out.unchanged {
                d_bar[e] += g_hat[i][i] * out.sigma_e[i].d[e];
            }
        }
    }
    for (var k = 0u; k < 2u; k++) {
        for (var e = 0u; e < DIRS; e++) {
            d_bar[e] += state_bar[k] * out.state[k].d[e];
        }
    }
    var f_hat = mat3_diag(vec3<f32>(d_bar[0], d_bar[1], d_bar[2]));
    for (var i = 0u; i < 3u; i++) {
        for (var j = i + 1u; j < 3u; j++) {
            let sum = away_from_zero(s[i] + s[j]);
            // Element (row i, column j) is m[j][i].
            if !out.unchanged {
                let dm = divided(out.sigma_e, s, i, j);
                let dp = (out.sigma_e[i].v + out.sigma_e[j].v) / sum;
                let a = 0.5 * (dm + dp);
                let b = 0.5 * (dm - dp);
                let gij = g_hat[j][i];
                let gji = g_hat[i][j];
                f_hat[j][i] += a * gij + b * gji;
                f_hat[i][j] += b * gij + a * gji;
            }
            let cc = divided(out.t, s, i, j) / sum * (t_hat[j][i] + t_hat[i][j]);
            f_hat[j][i] += cc * s[j];
            f_hat[i][j] += cc * s[i];
        }
    }
    var f_bar = u * f_hat * transpose(v);
    if out.unchanged {
        f_bar = f_bar + fe_bar;
    }
    return StressBar(f_bar, vec2<f32>(d_bar[3], d_bar[4]), vec4<f32>(d_bar[5], d_bar[6], d_bar[7], d_bar[8]), d_bar[9]);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear_id(gid, nwg, 64u);
    if i >= counts.particles {
        return;
    }
    let o = SBAR_STRIDE * i;
    if sbar[o + SBAR_FLAG] == 0.0 {
        for (var e = 0u; e < 9u; e++) {
            adj_f[9u * i + e] = 0.0;
        }
        return;
    }
    let slot = bitcast<u32>(info[INFO_STRIDE * i + 5u]);
    let pc = parts[slot];
    let vol0 = info[INFO_STRIDE * i + 3u];
    var r: array<f32, 9>;
    for (var e = 0u; e < 9u; e++) {
        r[e] = sbar[o + 16u + e];
    }
    let sb = mat3_from_rows(r);
    let tb = (sb + transpose(sb)) * (0.5 * stress_scale(vol0, c));
    for (var e = 0u; e < 9u; e++) {
        r[e] = f_trial[9u * i + e];
    }
    let f = mat3_from_rows(r);
    for (var e = 0u; e < 9u; e++) {
        r[e] = adj_f[9u * i + e];
    }
    let fe_bar = mat3_from_rows(r);
    let state_bar = vec2<f32>(adj_plastic[2u * i], adj_plastic[2u * i + 1u]);
    var res: StressBar;
    // The adjoint of C before the substep from the stress (the fluid's viscous term; 0
    // otherwise): particle_vjp adds the scatter's to it.
    var c_bar = mat3x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    if pc.material == MAT_FLUID {
        for (var e = 0u; e < 9u; e++) {
            r[e] = c_in[9u * i + e];
        }
        res = fluid_vjp(f, pc, mat3_from_rows(r), tb, fe_bar, state_bar, &c_bar);
    } else if pc.material == MAT_JELLY {
        res = jelly_vjp(f, pc, tb, fe_bar, state_bar);
    } else {
        res = general_vjp(f, pc, vec2<f32>(plastic_in[2u * i], plastic_in[2u * i + 1u]), tb, fe_bar, state_bar);
    }
    let fb = mat3_to_rows(res.f);
    let cbr = mat3_to_rows(c_bar);
    for (var e = 0u; e < 9u; e++) {
        adj_f[9u * i + e] = fb[e];
        adj_c[9u * i + e] = cbr[e];
    }
    adj_plastic[2u * i] = res.state.x;
    adj_plastic[2u * i + 1u] = res.state.y;
    for (var e = 0u; e < 4u; e++) {
        sbar[o + SBAR_PARAMS + e] = res.params[e];
    }
    sbar[o + SBAR_HARDENING] = res.h;
}
