#import lib/svd.wgsl
#import lib/structs.wgsl
#import lib/math.wgsl
// Constitutive models: a port of `stress_update` / `scalar_model` in
// crates/mpm/src/constitutive.rs (f32). Return mapping of the trial deformation gradient and
// the Kirchhoff stress of every material; the plastic state is `[yield stress, J_p]` (Rust
// `PlasticState`).
//
// Every isotropic model works on the singular values of F_trial = U diag(s) V^T:
// F_elastic = U diag(s_e) V^T (or F_trial itself, bit for bit, when the model leaves it
// unchanged) and tau = U diag(t) U^T. Formulas, branch order, clamps and epsilons follow the
// Rust code; the operation order of every product/sum is kept (left to right as in Rust).
//
// f64 in the Rust code, f32 here:
// * branch tests compare `x.re()` (the f32 value widened to f64): the same as comparing f32s.
// * snow's bounds `1 - theta_c`, `1 + theta_s` are computed in f64 and rounded to f32; here in
//   f32. Both are the correctly rounded exact difference/sum (the f64 result is exact), so the
//   values are identical.
// * foam's `sqrt(2/3)` is an f64 constant rounded to f32 (the literal below); its `dt` round
//   trips f32 -> f64 -> f32 exactly.
// * the fluid's `cbrt` (no WGSL builtin) is `pow(|J|, 1/3)` here: a few ulp of difference.

struct StressOut {
    fe: mat3x3<f32>,
    tau: mat3x3<f32>,
    plastic: vec2<f32>,
}

// The scalar part of a model (Rust `ModelOut`).
struct ScalarOut {
    sigma_e: vec3<f32>,
    t: vec3<f32>,
    state: vec2<f32>,
    unchanged: bool,
}

fn cm_norm3(v: vec3<f32>) -> f32 {
    return sqrt(v.x * v.x + v.y * v.y + v.z * v.z);
}

fn cm_ln3(v: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(log(v.x), log(v.y), log(v.z));
}

fn cm_exp3(v: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(exp(v.x), exp(v.y), exp(v.z));
}

// Principal Kirchhoff stresses of the fixed corotated model:
// t_i = 2 mu (s_i - 1) s_i + lambda J (J - 1).
fn fixed_corotated(s: vec3<f32>, mu: f32, lambda: f32) -> vec3<f32> {
    let j = s.x * s.y * s.z;
    let vol = lambda * j * (j - 1.0);
    return vec3<f32>(
        2.0 * mu * (s.x - 1.0) * s.x + vol,
        2.0 * mu * (s.y - 1.0) * s.y + vol,
        2.0 * mu * (s.z - 1.0) * s.z + vol,
    );
}

// Principal Kirchhoff stresses of StVK on the Hencky strain:
// t_i = (2 mu log s_i + lambda sum log s_j) s_i with the logs of max(s, 0.01).
fn stvk_hencky(s: vec3<f32>, mu: f32, lambda: f32) -> vec3<f32> {
    let l = cm_ln3(max(s, vec3<f32>(0.01)));
    let tr = l.x + l.y + l.z;
    return vec3<f32>(
        (2.0 * mu * l.x + lambda * tr) * s.x,
        (2.0 * mu * l.y + lambda * tr) * s.y,
        (2.0 * mu * l.z + lambda * tr) * s.z,
    );
}

// Sand's stress: 2 mu log|s| + lambda tr log|s| with the logs of max(|s|, 1e-14).
fn dp_stress(s: vec3<f32>, mu: f32, lambda: f32) -> vec3<f32> {
    let l = cm_ln3(max(abs(s), vec3<f32>(1e-14)));
    let tr = l.x + l.y + l.z;
    return vec3<f32>(2.0 * mu * l.x + lambda * tr, 2.0 * mu * l.y + lambda * tr, 2.0 * mu * l.z + lambda * tr);
}

fn cm_keep(sigma: vec3<f32>, t: vec3<f32>, state: vec2<f32>) -> ScalarOut {
    return ScalarOut(sigma, t, state, true);
}

// Rust `scalar_model` for the isotropic materials (0..=5, 7, 8; anything else: no stress).
fn scalar_model(pc: PartConsts, sigma: vec3<f32>, state: vec2<f32>, dt: f32) -> ScalarOut {
    let mu = pc.mu;
    let lambda = pc.lambda;
    let zero = vec3<f32>(0.0);
    switch pc.material {
        // Jelly: purely elastic, fixed corotated.
        case 0u: {
            return cm_keep(sigma, fixed_corotated(sigma, mu, lambda), state);
        }
        // Metal (1) and plasticine (5): von Mises on the Hencky strain.
        case 1u, 5u: {
            let plasticine = pc.material == MAT_PLASTICINE;
            let y = state.x;
            if plasticine && y <= 0.0 {
                // Fully softened: no stress for good.
                return cm_keep(sigma, zero, state);
            }
            let s = max(sigma, vec3<f32>(0.01));
            let eps = cm_ln3(s);
            let tr = eps.x + eps.y + eps.z;
            let t = vec3<f32>(2.0 * mu * eps.x + lambda * tr, 2.0 * mu * eps.y + lambda * tr, 2.0 * mu * eps.z + lambda * tr);
            let mt = (t.x + t.y + t.z) / 3.0;
            let d = t - vec3<f32>(mt);
            if cm_norm3(d) > y {
                let third = tr / 3.0;
                let eps_hat = eps - vec3<f32>(third);
                let nh = cm_norm3(eps_hat);
                let n = nh + 1e-6;
                let dgamma = n - y / (2.0 * mu);
                let kk = dgamma / n;
                let eps_new = eps - kk * eps_hat;
                let sigma_e = cm_exp3(eps_new);
                var st = state;
                var stress: vec3<f32>;
                if plasticine {
                    stress = fixed_corotated(sigma_e, mu, lambda);
                } else {
                    stress = stvk_hencky(sigma_e, mu, lambda);
                }
                if plasticine {
                    st.x = y - pc.softening * nh * abs(kk);
                    if st.x <= 0.0 {
                        stress = zero;
                    }
                } else if pc.hardening_xi != 0.0 {
                    st.x = y + 2.0 * mu * pc.hardening_xi * dgamma;
                }
                return ScalarOut(sigma_e, stress, st, false);
            } else if plasticine {
                return cm_keep(sigma, fixed_corotated(sigma, mu, lambda), state);
            } else {
                return cm_keep(sigma, stvk_hencky(sigma, mu, lambda), state);
            }
        }
        // Sand: Drucker-Prager (Klar et al. 2016).
        case 2u: {
            let eps = cm_ln3(max(abs(sigma), vec3<f32>(1e-14)));
            let tr = eps.x + eps.y + eps.z;
            let third = tr / 3.0;
            let eps_hat = eps - vec3<f32>(third);
            let n = cm_norm3(eps_hat);
            let dgamma = n + (3.0 * lambda + 2.0 * mu) / (2.0 * mu) * tr * pc.dp_alpha;
            if dgamma <= 0.0 {
                return cm_keep(sigma, dp_stress(sigma, mu, lambda), state);
            }
            var sigma_e = vec3<f32>(1.0);
            if !(tr > 0.0) {
                let kk = dgamma / n;
                sigma_e = cm_exp3(eps - kk * eps_hat);
            }
            return ScalarOut(sigma_e, dp_stress(sigma_e, mu, lambda), state, false);
        }
        // Foam (3) and PhysFlow's non_newtonian (7: no yield guard; equal singular values
        // take Warp's svd3(I) rounding, Rust `WARP_SVD3_IDENTITY`, its logs added as
        // constants).
        case 3u, 7u: {
            let paste = pc.material == 7u;
            let c = max(sigma, vec3<f32>(0.01));
            var s = c;
            var eps = cm_ln3(c);
            if paste && c.x == c.y && c.y == c.z {
                s = c * vec3<f32>(bitcast<f32>(0x3F7FFFFBu), bitcast<f32>(0x3F7FFFFCu), bitcast<f32>(0x3F7FFFFFu));
                eps = eps + vec3<f32>(-2.9802326828588295e-07, -2.3841860752327643e-07, -5.960464655174753e-08);
            }
            let b_tr = (s.x * s.x + s.y * s.y + s.z * s.z) / 3.0;
            let tr = eps.x + eps.y + eps.z;
            let third = tr / 3.0;
            let s_trial = 2.0 * mu * (eps - vec3<f32>(third));
            let s_norm = cm_norm3(s_trial);
            // sqrt(2/3), an f64 constant in Rust, rounded to f32.
            let y = s_norm - 0.816496580927726 * state.x;
            if paste || y > 0.0 {
                let mu_hat = mu * b_tr;
                let s_new_norm = s_norm - y / (1.0 + pc.plastic_viscosity / (2.0 * mu_hat * dt));
                let kk = s_new_norm / s_norm;
                let sigma_e = cm_exp3(kk * s_trial / (2.0 * mu) + vec3<f32>(third));
                return ScalarOut(sigma_e, stvk_hencky(sigma_e, mu, lambda), state, false);
            }
            return cm_keep(sigma, stvk_hencky(sigma, mu, lambda), state);
        }
        // PhysFlow's newtonian: compressible neo-Hookean (kirchoff_stress_herschel).
        case 8u: {
            let j = sigma.x * sigma.y * sigma.z;
            let bj = max(j * j, 1e-8);
            let f = exp(log(bj) * (-1.0 / 3.0));
            let b = vec3<f32>(f * sigma.x * sigma.x, f * sigma.y * sigma.y, f * sigma.z * sigma.z);
            let mb = (b.x + b.y + b.z) / 3.0;
            let p = (lambda / 2.0 + mu / 3.0) * (j * j - 1.0 + 1e-8);
            return cm_keep(sigma, vec3<f32>(p) + mu * (b - vec3<f32>(mb)), state);
        }
        // Snow: Stomakhin et al. 2013.
        case 4u: {
            let lo = 1.0 - pc.theta_c;
            let hi = 1.0 + pc.theta_s;
            let sigma_e = min(max(sigma, vec3<f32>(lo)), vec3<f32>(hi));
            let j_trial = sigma.x * sigma.y * sigma.z;
            let j_e = sigma_e.x * sigma_e.y * sigma_e.z;
            let jp = state.y * j_trial / j_e;
            let h = exp(pc.snow_xi * (1.0 - jp));
            // Within the elastic window F is kept as it is.
            let clamped = any(sigma_e != sigma);
            return ScalarOut(sigma_e, fixed_corotated(sigma_e, mu * h, lambda * h), vec2<f32>(state.x, jp), !clamped);
        }
        default: {
            return cm_keep(sigma, zero, state);
        }
    }
}

// The weakly compressible Newtonian fluid: F keeps only its volume change; pressure
// K J (J - 1), K = lambda + 2 mu / 3, viscous stress mu_v J (C + C^T). The plastic state is
// left as it is.
fn cm_fluid(svd: Svd3, pc: PartConsts, grad_v: mat3x3<f32>, plastic: vec2<f32>) -> StressOut {
    let j = svd.sigma.x * svd.sigma.y * svd.sigma.z;
    // Rust: cbrt(|J|) * signum(J); WGSL has no cbrt (pow of 0 avoided).
    var cb = 0.0;
    if abs(j) > 0.0 {
        cb = pow(abs(j), 1.0 / 3.0);
    }
    let c = cb * select(1.0, -1.0, j < 0.0);
    // Rust `fluid`: K = lambda + 2 mu / 3 from the slot's constants.
    let k = pc.lambda + (2.0 / 3.0) * pc.mu;
    let eta = pc.plastic_viscosity;
    let p = k * j * (j - 1.0);
    let visc = (grad_v + transpose(grad_v)) * (eta * j);
    return StressOut(mat3_diag(vec3<f32>(c)), visc + mat3_diag(vec3<f32>(p)), plastic);
}

// Return mapping and Kirchhoff stress of one particle (Rust `stress_update`): the elastic F,
// tau and the new plastic state. `grad_v` (the APIC matrix C) is used only by the fluid.
fn stress_update(f_trial: mat3x3<f32>, pc: PartConsts, plastic: vec2<f32>, grad_v: mat3x3<f32>, dt: f32) -> StressOut {
    let svd = svd3(f_trial);
    if pc.material == MAT_FLUID {
        return cm_fluid(svd, pc, grad_v, plastic);
    }
    let out = scalar_model(pc, svd.sigma, plastic, dt);
    var fe = f_trial;
    let u = svd.u;
    if !out.unchanged {
        let s = out.sigma_e;
        fe = mat3x3<f32>(u[0] * s.x, u[1] * s.y, u[2] * s.z) * transpose(svd.v);
    }
    let t = out.t;
    let tau = mat3x3<f32>(u[0] * t.x, u[1] * t.y, u[2] * t.z) * transpose(u);
    return StressOut(fe, tau, out.state);
}
