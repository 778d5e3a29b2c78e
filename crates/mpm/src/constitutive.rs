//! Constitutive models: the return mapping (plastic projection of the trial deformation
//! gradient) and the Kirchhoff stress of every [`Material`](crate::Material).
//!
//! Every model except the fluid is *isotropic*: with the SVD `F_trial = U diag(s) V^T`,
//!
//! * the return mapping gives `F_elastic = U diag(s_e) V^T`,
//! * the Kirchhoff stress is `tau = U diag(t) U^T`,
//!
//! where `(s_e, t, plastic state')` are functions of the singular values `s`, the plastic state
//! and the material parameters only. [`scalar_model`] computes exactly that scalar part, once,
//! generic over [`Scalar`]: plain `f32`/`f64` for simulation, and forward-mode dual numbers in
//! [`crate::adjoint`] for its Jacobian. The matrix parts (SVD, reassembly) are in
//! [`stress_update`], and their adjoints in `crate::adjoint`.
//!
//! Formulas follow PhysGaussian's `mpm_utils.py` (Xie et al. 2024) where it has the model, with
//! these deliberate differences:
//!
//! * The stress uses the SVD of the trial F (the elastic F shares its U and V) instead of a
//!   second SVD of the elastic F (same numbers up to round-off).
//! * Sand's stress takes `log(max(|s|, 1e-14))` like its return mapping does, so an inverted
//!   element gives a finite stress instead of NaN.
//! * Snow is Stomakhin et al. 2013 (PhysGaussian's snow branch computes no stress).
//! * Fluid is our addition (weakly compressible Newtonian; not isotropic in the sense above,
//!   handled apart, and not differentiated yet).
//!
//! PhysFlow's two "fluids" follow its `mpm_utils.py` (github zhuomanliu/PhysFlow at b4696871):
//!
//! * [`Material::NonNewtonian`](crate::Material::NonNewtonian) (its id 6):
//!   `viscoplasticity_return_mapping_with_StVK_force` (lines 241-283) then
//!   `kirchoff_stress_StVK` (21-37). The foam's mapping without `if y > 0`: below the yield
//!   surface `|s|` is pushed up toward it. At `F = I` (every particle at the first substep) the
//!   deviatoric strain is zero and PhysFlow's direction `s_trial / |s_trial|` comes from the
//!   rounding of Warp's `svd3(I)`: singular values `(1 - 2^-24, 1 - 2^-22, 1 - 5 2^-24)` on
//!   the simulation's z, y and x axes (the reference data's `svd3_identity.py`). An exact SVD
//!   gives 0 / 0 there; this model uses Warp's values instead whenever the three singular
//!   values are equal ([`WARP_SVD3_IDENTITY`]), deterministically and on every backend, so
//!   the first substep pulls the paste as PhysFlow's CPU run does (vertical tension, lateral
//!   compression).
//! * [`Material::Newtonian`](crate::Material::Newtonian) (its id 5): no return mapping;
//!   `kirchoff_stress_herschel` (82-94) in principal form,
//!   `t_i = (lambda / 2 + mu / 3) (J^2 - 1 + 1e-8) + mu (b_i - mean b)`,
//!   `b_i = max(J^2, 1e-8)^(-1/3) s_i^2`.

use crate::material::PartConsts;
use crate::math::{svd3, Mat3, Real, Svd3};
use std::ops::{Add, Div, Mul, Neg, Sub};

/// Per-particle plastic state carried between substeps: `[yield stress (Pa), J_p]`.
///
/// The yield stress starts at the part's value and changes under metal hardening and
/// plasticine softening; `J_p` (snow's plastic volume ratio) starts at 1.
pub type PlasticState<T> = [T; 2];

/// The scalar arithmetic [`scalar_model`] needs: implemented by `f32`, `f64` and the dual
/// numbers of [`crate::adjoint`]. Branches compare [`Scalar::re`] (the value).
pub trait Scalar:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    /// A constant.
    fn cst(x: f64) -> Self;
    /// The value (for branching).
    fn re(self) -> f64;
    /// Natural logarithm.
    fn ln(self) -> Self;
    /// Exponential.
    fn exp(self) -> Self;
    /// Square root.
    fn sqrt(self) -> Self;
    /// Absolute value.
    fn abs(self) -> Self;
    /// The larger of two values (the first when equal).
    fn max(self, o: Self) -> Self {
        if o.re() > self.re() {
            o
        } else {
            self
        }
    }
    /// The smaller of two values (the first when equal).
    fn min(self, o: Self) -> Self {
        if o.re() < self.re() {
            o
        } else {
            self
        }
    }
}

impl<T: Real> Scalar for T {
    #[inline(always)]
    fn cst(x: f64) -> Self {
        T::c(x)
    }
    #[inline(always)]
    fn re(self) -> f64 {
        self.f64()
    }
    #[inline(always)]
    fn ln(self) -> Self {
        num_traits::Float::ln(self)
    }
    #[inline(always)]
    fn exp(self) -> Self {
        num_traits::Float::exp(self)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        num_traits::Float::sqrt(self)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        num_traits::Float::abs(self)
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        if o > self {
            o
        } else {
            self
        }
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        if o < self {
            o
        } else {
            self
        }
    }
}

/// Inputs of [`scalar_model`]: the trial singular values, the plastic state and the
/// differentiable material constants.
#[derive(Clone, Copy, Debug)]
pub struct ModelIn<S> {
    /// Singular values of F_trial (McAdams' convention: the last may be negative).
    pub sigma: [S; 3],
    /// Plastic state `[yield stress, J_p]`.
    pub state: [S; 2],
    /// Lamé mu (Pa).
    pub mu: S,
    /// Lamé lambda (Pa).
    pub lambda: S,
    /// Plastic viscosity (Pa s).
    pub eta: S,
    /// Drucker-Prager alpha.
    pub alpha: S,
    /// Hardening coefficient ([`PartConsts::hardening_coeff`]): metal's xi, plasticine's
    /// softening.
    pub h: S,
}

impl<T: Real> ModelIn<T> {
    /// The inputs for singular values `sigma`, plastic `state` and a part's constants.
    pub fn new(sigma: [T; 3], state: [T; 2], pc: &PartConsts) -> Self {
        ModelIn {
            sigma,
            state,
            mu: T::c(pc.mu as f64),
            lambda: T::c(pc.lambda as f64),
            eta: T::c(pc.plastic_viscosity as f64),
            alpha: T::c(pc.dp_alpha as f64),
            h: T::c(pc.hardening_coeff() as f64),
        }
    }
}

/// Outputs of [`scalar_model`].
#[derive(Clone, Copy, Debug)]
pub struct ModelOut<S> {
    /// Singular values of F_elastic.
    pub sigma_e: [S; 3],
    /// Principal Kirchhoff stresses: `tau = U diag(t) U^T`.
    pub t: [S; 3],
    /// Plastic state after the substep.
    pub state: [S; 2],
    /// True when the return mapping left F unchanged (F_elastic = F_trial exactly).
    pub unchanged: bool,
}

#[inline(always)]
fn norm3<S: Scalar>(v: [S; 3]) -> S {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// Principal Kirchhoff stresses of the fixed corotated model:
/// `t_i = 2 mu (s_i - 1) s_i + lambda J (J - 1)`.
#[inline(always)]
fn fixed_corotated<S: Scalar>(s: [S; 3], mu: S, lambda: S) -> [S; 3] {
    let two = S::cst(2.0);
    let j = s[0] * s[1] * s[2];
    let vol = lambda * j * (j - S::cst(1.0));
    [
        two * mu * (s[0] - S::cst(1.0)) * s[0] + vol,
        two * mu * (s[1] - S::cst(1.0)) * s[1] + vol,
        two * mu * (s[2] - S::cst(1.0)) * s[2] + vol,
    ]
}

/// Principal Kirchhoff stresses of StVK on the Hencky strain (PhysGaussian's metal and foam
/// stress): `t_i = (2 mu log s_i + lambda sum log s_j) s_i` with the logs of `max(s, 0.01)`.
#[inline(always)]
fn stvk_hencky<S: Scalar>(s: [S; 3], mu: S, lambda: S) -> [S; 3] {
    let two = S::cst(2.0);
    let l = [0, 1, 2].map(|i| s[i].max(S::cst(0.01)).ln());
    let tr = l[0] + l[1] + l[2];
    [0, 1, 2].map(|i| (two * mu * l[i] + lambda * tr) * s[i])
}

/// Warp 0.10.1's `svd3(I)` singular values, on the simulation's x, y and z axes (f32 bits
/// `0x3F7FFFFB`, `0x3F7FFFFC`, `0x3F7FFFFF`): what [`Material::NonNewtonian`]'s mapping
/// uses when all three singular values are equal (see the module docs).
///
/// [`Material::NonNewtonian`]: crate::Material::NonNewtonian
pub const WARP_SVD3_IDENTITY: [f64; 3] = [
    1.0 - 5.0 / 16_777_216.0,
    1.0 - 4.0 / 16_777_216.0,
    1.0 - 1.0 / 16_777_216.0,
];

/// `ln` of [`WARP_SVD3_IDENTITY`] (f64): added to the logarithms of equal singular values, so
/// that no backend's `log` near 1 decides the direction.
pub const WARP_SVD3_IDENTITY_LN: [f64; 3] = [
    -2.9802326828588295e-07,
    -2.3841860752327643e-07,
    -5.960464655174753e-08,
];

/// The scalar part of every isotropic model: return mapping on the singular values, plastic
/// state update and principal Kirchhoff stresses. `pc` supplies the material id and the
/// constants that are not differentiated (snow limits); `m` the differentiable ones, metal's
/// hardening and plasticine's softening among them (`m.h`); `dt` is the substep (foam's
/// viscoplastic update depends on it).
pub fn scalar_model<S: Scalar>(pc: &PartConsts, m: ModelIn<S>, dt: f64) -> ModelOut<S> {
    let (mu, lambda) = (m.mu, m.lambda);
    let two = S::cst(2.0);
    let three = S::cst(3.0);
    let sigma = m.sigma;
    let keep = |t: [S; 3], state: [S; 2]| ModelOut {
        sigma_e: sigma,
        t,
        state,
        unchanged: true,
    };
    let exp3 = |e: [S; 3]| e.map(|x| x.exp());
    match pc.material {
        // Jelly: purely elastic, fixed corotated.
        0 => keep(fixed_corotated(sigma, mu, lambda), m.state),
        // Metal (1) and plasticine (5): von Mises on the Hencky strain.
        1 | 5 => {
            let plasticine = pc.material == 5;
            let y = m.state[0];
            let zero = [S::cst(0.0); 3];
            if plasticine && y.re() <= 0.0 {
                // Fully softened: no stress for good (PhysGaussian sets mu = lambda = 0).
                return keep(zero, m.state);
            }
            let s = sigma.map(|x| x.max(S::cst(0.01)));
            let eps = s.map(|x| x.ln());
            let tr = eps[0] + eps[1] + eps[2];
            let t = eps.map(|e| two * mu * e + lambda * tr);
            let mt = (t[0] + t[1] + t[2]) / three;
            let d = t.map(|x| x - mt);
            if norm3(d).re() > y.re() {
                let third = tr / three;
                let eps_hat = eps.map(|e| e - third);
                let nh = norm3(eps_hat);
                let n = nh + S::cst(1e-6);
                let dgamma = n - y / (two * mu);
                let kk = dgamma / n;
                let eps_new = [0, 1, 2].map(|i| eps[i] - kk * eps_hat[i]);
                let sigma_e = exp3(eps_new);
                let mut state = m.state;
                let mut stress = if plasticine {
                    fixed_corotated(sigma_e, mu, lambda)
                } else {
                    stvk_hencky(sigma_e, mu, lambda)
                };
                if plasticine {
                    state[0] = y - m.h * nh * kk.abs();
                    if state[0].re() <= 0.0 {
                        stress = zero;
                    }
                } else {
                    // Without hardening (h = 0) this is y exactly: its derivative in h is
                    // still there, so a fit can start hardening from none.
                    state[0] = y + two * mu * m.h * dgamma;
                }
                ModelOut {
                    sigma_e,
                    t: stress,
                    state,
                    unchanged: false,
                }
            } else if plasticine {
                keep(fixed_corotated(sigma, mu, lambda), m.state)
            } else {
                keep(stvk_hencky(sigma, mu, lambda), m.state)
            }
        }
        // Sand: Drucker-Prager (Klar et al. 2016), stress 2 mu log s + lambda tr log s.
        2 => {
            let dp_stress = |s: [S; 3]| {
                let l = s.map(|x| x.abs().max(S::cst(1e-14)).ln());
                let tr = l[0] + l[1] + l[2];
                l.map(|e| two * mu * e + lambda * tr)
            };
            let eps = sigma.map(|x| x.abs().max(S::cst(1e-14)).ln());
            let tr = eps[0] + eps[1] + eps[2];
            let third = tr / three;
            let eps_hat = eps.map(|e| e - third);
            let n = norm3(eps_hat);
            let dgamma = n + (three * lambda + two * mu) / (two * mu) * tr * m.alpha;
            let sigma_e = if dgamma.re() <= 0.0 {
                return keep(dp_stress(sigma), m.state);
            } else if tr.re() > 0.0 {
                [S::cst(1.0); 3]
            } else {
                let kk = dgamma / n;
                exp3([0, 1, 2].map(|i| eps[i] - kk * eps_hat[i]))
            };
            ModelOut {
                sigma_e,
                t: dp_stress(sigma_e),
                state: m.state,
                unchanged: false,
            }
        }
        // Foam: viscoplastic von Mises with StVK-Hencky stress; PhysFlow's non_newtonian (7)
        // is the same mapping without the yield guard, with Warp's svd3(I) rounding where
        // the three singular values are equal (see the module docs).
        3 | 7 => {
            let paste = pc.material == 7;
            let c = sigma.map(|x| x.max(S::cst(0.01)));
            let equal = paste && c[0].re() == c[1].re() && c[1].re() == c[2].re();
            let (s, eps) = if equal {
                (
                    [0, 1, 2].map(|i| c[i] * S::cst(WARP_SVD3_IDENTITY[i])),
                    [0, 1, 2].map(|i| c[i].ln() + S::cst(WARP_SVD3_IDENTITY_LN[i])),
                )
            } else {
                (c, c.map(|x| x.ln()))
            };
            let b_tr = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]) / three;
            let tr = eps[0] + eps[1] + eps[2];
            let third = tr / three;
            let s_trial = eps.map(|e| two * mu * (e - third));
            let s_norm = norm3(s_trial);
            let y = s_norm - S::cst((2.0f64 / 3.0).sqrt()) * m.state[0];
            if paste || y.re() > 0.0 {
                let mu_hat = mu * b_tr;
                let s_new_norm = s_norm - y / (S::cst(1.0) + m.eta / (two * mu_hat * S::cst(dt)));
                let kk = s_new_norm / s_norm;
                let sigma_e = exp3(s_trial.map(|x| kk * x / (two * mu) + third));
                ModelOut {
                    sigma_e,
                    t: stvk_hencky(sigma_e, mu, lambda),
                    state: m.state,
                    unchanged: false,
                }
            } else {
                keep(stvk_hencky(sigma, mu, lambda), m.state)
            }
        }
        // Snow: Stomakhin et al. 2013.
        4 => {
            let lo = S::cst(1.0 - pc.theta_c as f64);
            let hi = S::cst(1.0 + pc.theta_s as f64);
            let sigma_e = sigma.map(|x| x.max(lo).min(hi));
            let j_trial = sigma[0] * sigma[1] * sigma[2];
            let j_e = sigma_e[0] * sigma_e[1] * sigma_e[2];
            let jp = m.state[1] * j_trial / j_e;
            let h = (S::cst(pc.snow_xi as f64) * (S::cst(1.0) - jp)).exp();
            // Within the elastic window F is kept as it is (no f32 recomposition noise).
            let clamped = (0..3).any(|i| sigma_e[i].re() != sigma[i].re());
            ModelOut {
                sigma_e,
                t: fixed_corotated(sigma_e, mu * h, lambda * h),
                state: [m.state[0], jp],
                unchanged: !clamped,
            }
        }
        // PhysFlow's newtonian: compressible neo-Hookean (kirchoff_stress_herschel).
        8 => {
            let j = sigma[0] * sigma[1] * sigma[2];
            let bj = (j * j).max(S::cst(1e-8));
            let f = (bj.ln() * S::cst(-1.0 / 3.0)).exp();
            let b = sigma.map(|x| f * x * x);
            let mb = (b[0] + b[1] + b[2]) / three;
            let p = (lambda / two + mu / three) * (j * j - S::cst(1.0) + S::cst(1e-8));
            keep(b.map(|x| p + mu * (x - mb)), m.state)
        }
        _ => keep([S::cst(0.0); 3], m.state),
    }
}

/// The differentiable material constants of a part, in the kernel's scalar type.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaterialParams<T> {
    /// Lamé mu (Pa).
    pub mu: T,
    /// Lamé lambda (Pa).
    pub lambda: T,
    /// Plastic viscosity (Pa s).
    pub eta: T,
    /// Drucker-Prager alpha.
    pub alpha: T,
    /// Hardening coefficient ([`PartConsts::hardening_coeff`]).
    pub h: T,
}

impl<T: Real> MaterialParams<T> {
    /// The constants of a part.
    pub fn of(pc: &PartConsts) -> Self {
        MaterialParams {
            mu: T::c(pc.mu as f64),
            lambda: T::c(pc.lambda as f64),
            eta: T::c(pc.plastic_viscosity as f64),
            alpha: T::c(pc.dp_alpha as f64),
            h: T::c(pc.hardening_coeff() as f64),
        }
    }
}

/// Return mapping and Kirchhoff stress of one particle: returns `(F_elastic, tau)` and updates
/// the plastic state. `grad_v` (the APIC matrix C) is used only by the fluid.
pub fn stress_update<T: Real>(
    f_trial: Mat3<T>,
    pc: &PartConsts,
    state: &mut PlasticState<T>,
    grad_v: &Mat3<T>,
    dt: T,
) -> (Mat3<T>, Mat3<T>) {
    stress_update_from_svd(f_trial, &svd3(f_trial), pc, state, grad_v, dt)
}

/// [`stress_update`] given `svd`, the SVD of `f_trial` (bitwise `svd3(f_trial)`; backends
/// compute them in batches with [`crate::math::svd3_many`]).
pub fn stress_update_from_svd<T: Real>(
    f_trial: Mat3<T>,
    svd: &Svd3<T>,
    pc: &PartConsts,
    state: &mut PlasticState<T>,
    grad_v: &Mat3<T>,
    dt: T,
) -> (Mat3<T>, Mat3<T>) {
    if pc.material == 6 {
        return fluid(svd, MaterialParams::of(pc), grad_v);
    }
    stress_update_with_svd(f_trial, svd, pc, state, MaterialParams::of(pc), dt)
}

/// [`stress_update`] of the isotropic models with explicit material constants `p` (the
/// differentiable ones); `pc` supplies the model id and the fixed constants.
pub fn stress_update_with<T: Real>(
    f_trial: Mat3<T>,
    pc: &PartConsts,
    state: &mut PlasticState<T>,
    p: MaterialParams<T>,
    dt: T,
) -> (Mat3<T>, Mat3<T>) {
    stress_update_with_svd(f_trial, &svd3(f_trial), pc, state, p, dt)
}

/// [`stress_update_with`] given `svd`, the SVD of `f_trial` (bitwise `svd3(f_trial)`).
#[inline(always)]
pub fn stress_update_with_svd<T: Real>(
    f_trial: Mat3<T>,
    svd: &Svd3<T>,
    pc: &PartConsts,
    state: &mut PlasticState<T>,
    p: MaterialParams<T>,
    dt: T,
) -> (Mat3<T>, Mat3<T>) {
    let input = ModelIn {
        sigma: svd.sigma,
        state: *state,
        mu: p.mu,
        lambda: p.lambda,
        eta: p.eta,
        alpha: p.alpha,
        h: p.h,
    };
    let out = scalar_model(pc, input, dt.f64());
    *state = out.state;
    let fe = if out.unchanged {
        f_trial
    } else {
        svd.compose(out.sigma_e)
    };
    let u = svd.u;
    (fe, u.mul_diag(out.t) * u.transpose())
}

/// The weakly compressible Newtonian fluid: F keeps only its volume change; pressure
/// `K J (J - 1)` with the bulk modulus `K = lambda + 2 mu / 3` (= `E / (3 (1 - 2 nu))`),
/// viscous stress `eta J (C + C^T)` (`eta` the plastic viscosity, `C = grad_v` the APIC
/// matrix). Returns `(F_elastic, tau)`.
pub fn fluid<T: Real>(svd: &Svd3<T>, p: MaterialParams<T>, grad_v: &Mat3<T>) -> (Mat3<T>, Mat3<T>) {
    let j = svd.sigma[0] * svd.sigma[1] * svd.sigma[2];
    let c = num_traits::Float::cbrt(num_traits::Float::abs(j)) * num_traits::Float::signum(j);
    let k = p.lambda + T::c(2.0 / 3.0) * p.mu;
    let p_ = k * j * (j - T::one());
    let visc = (*grad_v + grad_v.transpose()).scaled(p.eta * j);
    (Mat3::diag([c; 3]), visc + Mat3::diag([p_; 3]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::{Material, PartParams};
    use crate::math::norm;

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
            Material::Fluid,
        ] {
            let pc = PartParams::new(m).consts();
            let mut st = [pc.yield_stress as f64, 1.0];
            let (_, tau) = stress_update(rot(0.7), &pc, &mut st, &Mat3::zero(), 1e-4);
            assert!(tau.frobenius() < 1e-6 * pc.mu as f64, "{m:?}: {tau:?}");
        }
    }

    /// PhysFlow's non_newtonian at F = I (every particle at the first substep): the stress its
    /// CPU run gives from Warp's svd3(I) rounding (the reference data's README, `ref_paste`:
    /// sim E 5e5 Pa, nu 0.4, yield stress 1500 Pa, plastic viscosity 1500 Pa s, dt 2e-4 s):
    /// deviatoric 55.73 Pa x diag(-0.566, -0.226, +0.793), in f32 and f64 alike.
    #[test]
    fn non_newtonian_at_rest_pulls_as_physflows_svd_rounding_does() {
        let p = PartParams {
            material: Material::NonNewtonian,
            youngs_modulus_pa: 5e5,
            poisson_ratio: 0.4,
            yield_stress_pa: 1500.0,
            plastic_viscosity_pa_s: 1500.0,
            ..Default::default()
        };
        let pc = p.consts();
        let check = |tau: [f64; 3]| {
            let m = (tau[0] + tau[1] + tau[2]) / 3.0;
            let dev = tau.map(|t| t - m);
            let n = norm(dev);
            assert!((n - 55.73).abs() < 0.05, "|dev tau| = {n}");
            for (d, want) in dev.iter().zip([-0.566, -0.226, 0.793]) {
                assert!((d / n - want).abs() < 2e-3, "{dev:?}");
            }
        };
        let mut st = [pc.yield_stress as f64, 1.0];
        let (fe, tau) = stress_update(Mat3::identity(), &pc, &mut st, &Mat3::zero(), 2e-4);
        assert!(fe.to_array().iter().all(|v| v.is_finite()));
        check([0, 1, 2].map(|i| tau.to_array()[4 * i]));
        let mut st = [pc.yield_stress, 1.0f32];
        let (_, tau) = stress_update(Mat3::<f32>::identity(), &pc, &mut st, &Mat3::zero(), 2e-4);
        check([0, 1, 2].map(|i| tau.to_array()[4 * i] as f64));
    }

    /// PhysFlow's newtonian equals its matrix form `(lambda/2 + mu/3)(J^2 - 1 + 1e-8) I +
    /// mu dev(J^(-2/3) F F^T)`, and keeps F.
    #[test]
    fn newtonian_matches_physflows_matrix_form() {
        let p = PartParams {
            material: Material::Newtonian,
            youngs_modulus_pa: 5000.0,
            poisson_ratio: 0.499,
            ..Default::default()
        };
        let pc = p.consts();
        let f = Mat3::from_array([1.1, 0.05, -0.02, 0.01, 0.95, 0.03, 0.0, -0.04, 1.02]);
        let mut st = [0.0, 1.0];
        let (fe, tau) = stress_update(f, &pc, &mut st, &Mat3::zero(), 1e-4);
        assert_eq!(fe, f);
        let (mu, la) = (pc.mu as f64, pc.lambda as f64);
        let j: f64 = f.det();
        let b = (f * f.transpose()).scaled((j * j).max(1e-8).powf(-1.0 / 3.0));
        let tr = (b.to_array()[0] + b.to_array()[4] + b.to_array()[8]) / 3.0;
        let expect = (b - Mat3::diag([tr; 3])).scaled(mu)
            + Mat3::diag([(la / 2.0 + mu / 3.0) * (j * j - 1.0 + 1e-8); 3]);
        assert!(
            (tau - expect).frobenius() < 1e-9 * expect.frobenius(),
            "{tau:?} vs {expect:?}"
        );
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
        let mut st = [pc.yield_stress as f64, 1.0];
        let (fe, _) = stress_update(
            Mat3::diag([1.05, 0.98, 0.98]),
            &pc,
            &mut st,
            &Mat3::zero(),
            1e-4,
        );
        let eps = svd3(fe).sigma.map(|x: f64| x.ln());
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
        let _ = stress_update(
            Mat3::diag([0.9, 0.9, 0.9f64]),
            &pc,
            &mut st,
            &Mat3::zero(),
            1e-4,
        );
        assert!(st[1] < 0.8, "{}", st[1]);
    }
}
