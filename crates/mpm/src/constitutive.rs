//! Constitutive models: the return mapping (plastic projection of the trial deformation
//! gradient) and the Kirchhoff stress of every [`Material`](crate::Material).
//!
//! These per-particle functions are the single source of truth for the material math: the
//! reference kernels, the CPU backend and (later) the shaders' tests all call or mirror them.
//! Formulas follow PhysGaussian's `mpm_utils.py` (Xie et al. 2024) where it has the model, with
//! these deliberate differences:
//!
//! * The SVD of the elastic F is reused for the stress instead of being recomputed (same
//!   numbers up to round-off).
//! * Sand's stress takes `log(max(|s|, 1e-14))` like its return mapping does, so an inverted
//!   element gives a finite stress instead of NaN.
//! * Snow is Stomakhin et al. 2013 (PhysGaussian's snow branch computes no stress).
//! * Fluid is our addition (weakly compressible Newtonian).

use crate::material::PartConsts;
use crate::math::{norm, svd3, Mat3, Real, Svd3, Vec3};

/// Per-particle plastic state carried between substeps: `[yield stress (Pa), J_p]`.
///
/// The yield stress starts at the part's value and changes under metal hardening and
/// plasticine softening; `J_p` (snow's plastic volume ratio) starts at 1.
pub type PlasticState<T> = [T; 2];

/// Result of the return mapping: the elastic deformation gradient, its SVD and the Lamé
/// parameters the stress uses (hardened or softened).
#[derive(Clone, Copy, Debug)]
pub struct Elastic<T> {
    /// Elastic deformation gradient (the projected F).
    pub f: Mat3<T>,
    /// SVD of `f`.
    pub svd: Svd3<T>,
    /// Effective shear modulus.
    pub mu: T,
    /// Effective first Lamé parameter.
    pub lambda: T,
}

#[inline(always)]
fn exp3<T: Real>(e: Vec3<T>) -> Vec3<T> {
    [e[0].exp(), e[1].exp(), e[2].exp()]
}

/// Projects the trial deformation gradient onto the material's elastic region, updating the
/// plastic state. `dt` is the substep length (foam's viscoplastic update depends on it).
pub fn return_mapping<T: Real>(
    f_trial: Mat3<T>,
    pc: &PartConsts,
    state: &mut PlasticState<T>,
    dt: T,
) -> Elastic<T> {
    let svd = svd3(f_trial);
    let mu = T::c(pc.mu as f64);
    let lambda = T::c(pc.lambda as f64);
    let elastic = |svd: Svd3<T>, sigma: Vec3<T>| {
        let s = Svd3 { sigma, ..svd };
        Elastic {
            f: s.compose(sigma),
            svd: s,
            mu,
            lambda,
        }
    };
    let unchanged = Elastic {
        f: f_trial,
        svd,
        mu,
        lambda,
    };
    match pc.material {
        // Jelly: purely elastic.
        0 => unchanged,
        // Metal (1) and plasticine (5): von Mises on the Hencky strain.
        1 | 5 => {
            let plasticine = pc.material == 5;
            let y = state[0];
            if plasticine && y <= T::zero() {
                // Fully softened: the particle carries no stress (mu = lambda = 0 for good).
                return Elastic {
                    mu: T::zero(),
                    lambda: T::zero(),
                    ..unchanged
                };
            }
            let floor = T::c(0.01);
            let s = svd.sigma.map(|x| x.max(floor));
            let eps = s.map(|x| x.ln());
            let tr = eps[0] + eps[1] + eps[2];
            let t = eps.map(|e| T::c(2.0) * mu * e + lambda * tr);
            let mt = (t[0] + t[1] + t[2]) / T::c(3.0);
            let d = t.map(|x| x - mt);
            if norm(d) > y {
                let third = tr / T::c(3.0);
                let eps_hat = eps.map(|e| e - third);
                let n = norm(eps_hat) + T::c(1e-6);
                let dgamma = n - y / (T::c(2.0) * mu);
                let k = dgamma / n;
                let eps_new = [
                    eps[0] - k * eps_hat[0],
                    eps[1] - k * eps_hat[1],
                    eps[2] - k * eps_hat[2],
                ];
                if plasticine {
                    let dp = norm(eps_hat) * k.abs();
                    state[0] = y - T::c(pc.softening as f64) * dp;
                } else if pc.hardening_xi != 0.0 {
                    state[0] = y + T::c(2.0) * mu * T::c(pc.hardening_xi as f64) * dgamma;
                }
                elastic(svd, exp3(eps_new))
            } else {
                unchanged
            }
        }
        // Sand: Drucker-Prager.
        2 => {
            let eps = svd.sigma.map(|x| x.abs().max(T::c(1e-14)).ln());
            let tr = eps[0] + eps[1] + eps[2];
            let third = tr / T::c(3.0);
            let eps_hat = eps.map(|e| e - third);
            let n = norm(eps_hat);
            let alpha = T::c(pc.dp_alpha as f64);
            let dgamma = n + (T::c(3.0) * lambda + T::c(2.0) * mu) / (T::c(2.0) * mu) * tr * alpha;
            if dgamma <= T::zero() {
                unchanged
            } else if tr > T::zero() {
                elastic(svd, [T::one(); 3])
            } else {
                let k = dgamma / n;
                elastic(
                    svd,
                    exp3([
                        eps[0] - k * eps_hat[0],
                        eps[1] - k * eps_hat[1],
                        eps[2] - k * eps_hat[2],
                    ]),
                )
            }
        }
        // Foam: viscoplastic von Mises.
        3 => {
            let s = svd.sigma.map(|x| x.max(T::c(0.01)));
            let b_tr = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]) / T::c(3.0);
            let eps = s.map(|x| x.ln());
            let tr = eps[0] + eps[1] + eps[2];
            let third = tr / T::c(3.0);
            let s_trial = eps.map(|e| T::c(2.0) * mu * (e - third));
            let s_norm = norm(s_trial);
            let y = s_norm - T::c((2.0f64 / 3.0).sqrt()) * state[0];
            if y > T::zero() {
                let mu_hat = mu * b_tr;
                let eta = T::c(pc.plastic_viscosity as f64);
                let s_new_norm = s_norm - y / (T::one() + eta / (T::c(2.0) * mu_hat * dt));
                let k = s_new_norm / s_norm;
                let eps_new = s_trial.map(|x| k * x / (T::c(2.0) * mu) + third);
                elastic(svd, exp3(eps_new))
            } else {
                unchanged
            }
        }
        // Snow: Stomakhin et al. 2013.
        4 => {
            let lo = T::one() - T::c(pc.theta_c as f64);
            let hi = T::one() + T::c(pc.theta_s as f64);
            let sc = svd.sigma.map(|x| x.max(lo).min(hi));
            let j_trial = svd.sigma[0] * svd.sigma[1] * svd.sigma[2];
            let j_e = sc[0] * sc[1] * sc[2];
            state[1] = state[1] * j_trial / j_e;
            let h = (T::c(pc.snow_xi as f64) * (T::one() - state[1])).exp();
            Elastic {
                mu: mu * h,
                lambda: lambda * h,
                ..elastic(svd, sc)
            }
        }
        // Fluid: keep only the volume change.
        6 => {
            let j = svd.sigma[0] * svd.sigma[1] * svd.sigma[2];
            let c = j.abs().cbrt() * j.signum();
            let s = [c; 3];
            Elastic {
                f: Mat3::diag(s),
                svd: Svd3 {
                    u: Mat3::identity(),
                    sigma: s,
                    v: Mat3::identity(),
                },
                mu,
                lambda,
            }
        }
        _ => unchanged,
    }
}

/// Kirchhoff stress `tau = J sigma` of the elastic state (symmetric). `grad_v` is the
/// particle's velocity gradient estimate (the APIC matrix C), used only by the fluid.
pub fn kirchhoff_stress<T: Real>(e: &Elastic<T>, pc: &PartConsts, grad_v: &Mat3<T>) -> Mat3<T> {
    let s = e.svd.sigma;
    let u = e.svd.u;
    let two = T::c(2.0);
    let diag_stress = |d: Vec3<T>| u.mul_diag(d) * u.transpose();
    match pc.material {
        // StVK on the Hencky strain (metal, foam): tau = U diag(t_i s_i) U^T with
        // t_i = 2 mu log s_i + lambda sum log s_j, s clamped to >= 0.01 inside the log.
        1 | 3 => {
            let l = s.map(|x| x.max(T::c(0.01)).ln());
            let tr = l[0] + l[1] + l[2];
            diag_stress([
                (two * e.mu * l[0] + e.lambda * tr) * s[0],
                (two * e.mu * l[1] + e.lambda * tr) * s[1],
                (two * e.mu * l[2] + e.lambda * tr) * s[2],
            ])
        }
        // Drucker-Prager's stress: tau = U diag(2 mu log s_i + lambda sum log s_j) U^T.
        2 => {
            let l = s.map(|x| x.abs().max(T::c(1e-14)).ln());
            let tr = l[0] + l[1] + l[2];
            diag_stress([
                two * e.mu * l[0] + e.lambda * tr,
                two * e.mu * l[1] + e.lambda * tr,
                two * e.mu * l[2] + e.lambda * tr,
            ])
        }
        6 => {
            let j = s[0] * s[1] * s[2];
            let k = T::c(pc.bulk as f64);
            let eta = T::c(pc.plastic_viscosity as f64);
            let p = k * j * (j - T::one());
            let visc = (*grad_v + grad_v.transpose()).scaled(eta * j);
            visc + Mat3::diag([p; 3])
        }
        // Fixed corotated (jelly, snow, plasticine):
        // tau = 2 mu (F - R) F^T + lambda J (J - 1) I = U diag(2 mu (s^2 - s) + lambda J (J-1)) U^T.
        _ => {
            let j = s[0] * s[1] * s[2];
            let vol = e.lambda * j * (j - T::one());
            diag_stress([
                two * e.mu * (s[0] - T::one()) * s[0] + vol,
                two * e.mu * (s[1] - T::one()) * s[1] + vol,
                two * e.mu * (s[2] - T::one()) * s[2] + vol,
            ])
        }
    }
}

/// Convenience: return mapping then stress, as one substep's particle stage does.
pub fn stress_update<T: Real>(
    f_trial: Mat3<T>,
    pc: &PartConsts,
    state: &mut PlasticState<T>,
    grad_v: &Mat3<T>,
    dt: T,
) -> (Mat3<T>, Mat3<T>) {
    let e = return_mapping(f_trial, pc, state, dt);
    let tau = kirchhoff_stress(&e, pc, grad_v);
    (e.f, tau)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::{Material, PartParams};

    fn rot(a: f64) -> Mat3<f64> {
        let (s, c) = a.sin_cos();
        Mat3([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    }

    #[test]
    fn rigid_rotation_gives_zero_stress_for_every_material() {
        for m in [
            Material::Jelly,
            Material::Metal,
            Material::Sand,
            Material::Foam,
            Material::Snow,
            Material::Plasticine,
        ] {
            let pc = PartParams::new(m).consts();
            let mut st = [pc.yield_stress as f64, 1.0];
            let (_, tau) = stress_update(rot(0.7), &pc, &mut st, &Mat3::zero(), 1e-4);
            assert!(tau.frobenius() < 1e-6 * pc.mu as f64, "{m:?}: {tau:?}");
        }
    }

    #[test]
    fn fixed_corotated_matches_matrix_form() {
        let pc = PartParams::new(Material::Jelly).consts();
        let f = Mat3::from_array([1.1, 0.05, -0.02, 0.01, 0.95, 0.03, 0.0, -0.04, 1.02]);
        let mut st = [0.0, 1.0];
        let (_, tau) = stress_update(f, &pc, &mut st, &Mat3::zero(), 1e-4);
        let r = svd3(f).rotation();
        let j = f.det();
        let (mu, la) = (pc.mu as f64, pc.lambda as f64);
        let expect = (f - r) * f.transpose();
        let expect = expect.scaled(2.0 * mu) + Mat3::diag([la * j * (j - 1.0); 3]);
        assert!((tau - expect).frobenius() < 1e-8 * expect.frobenius());
    }

    #[test]
    fn von_mises_projects_onto_yield_surface() {
        let p = PartParams {
            material: Material::Metal,
            youngs_modulus_pa: 1e6,
            poisson_ratio: 0.3,
            yield_stress_pa: 1e3,
            ..Default::default()
        };
        let pc = p.consts();
        let f = Mat3::diag([1.05, 0.98, 0.98]);
        let mut st = [pc.yield_stress as f64, 1.0];
        let e = return_mapping(f, &pc, &mut st, 1e-4);
        let eps = e.svd.sigma.map(|x: f64| x.ln());
        let tr: f64 = eps.iter().sum();
        let t = eps.map(|x| 2.0 * pc.mu as f64 * x + pc.lambda as f64 * tr);
        let m = t.iter().sum::<f64>() / 3.0;
        let dev = norm(t.map(|x| x - m));
        // On the surface up to the 1e-6 regularisation of the norm.
        assert!((dev - 1e3).abs() < 1.0, "{dev}");
    }

    #[test]
    fn snow_compression_lowers_jp() {
        let pc = PartParams::new(Material::Snow).consts();
        let mut st = [0.0, 1.0];
        let _ = return_mapping(Mat3::diag([0.9, 0.9, 0.9f64]), &pc, &mut st, 1e-4);
        assert!(st[1] < 0.8, "{}", st[1]);
    }
}
