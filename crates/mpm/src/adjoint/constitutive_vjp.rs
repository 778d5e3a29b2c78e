//! Adjoint of the isotropic constitutive models ([`crate::constitutive::stress_update_with`]):
//! from the adjoints of `F_elastic`, `tau` and the plastic state after the substep to those of
//! `F_trial`, the plastic state before it and the material constants (mu, lambda, plastic
//! viscosity, Drucker-Prager alpha, hardening coefficient).
//!
//! # Method
//!
//! With `F_trial = U diag(s) V^T`, every model is `F_e = U diag(g(s)) V^T`,
//! `tau = U diag(t(s)) U^T`, `state' = h(s, state)`, where `(g, t, h)` come from
//! [`scalar_model`]. The Jacobian of that scalar part is computed by forward-mode dual numbers
//! ([`Dual`], 10 directions: 3 singular values, 2 state entries, 5 constants), so the scalar
//! math exists once; the jelly's (fixed corotated, the hottest path) is written in closed form
//! and checked against the dual numbers. The matrix part uses the classic derivative of isotropic matrix
//! functions (Ogden; Irving, Teran and Fedkiw 2004): in the rotated frame
//! `dF^ = U^T dF V`,
//!
//! * `dG^_ii = sum_j dg_i/ds_j dF^_jj`, and for `i != j` the 2x2 block
//!   `dG^_ij = a dF^_ij + b dF^_ji`, `dG^_ji = b dF^_ij + a dF^_ji` with
//!   `a, b = (d- +- d+) / 2`, `d- = (g_i - g_j) / (s_i - s_j)`, `d+ = (g_i + g_j) / (s_i + s_j)`;
//! * `d tau^_ij = d-(t) (s_j dF^_ij + s_i dF^_ji) / (s_i + s_j)` for `i != j`.
//!
//! # Regularisation of repeated and vanishing singular values
//!
//! The divided difference `d- = (g_i - g_j) / (s_i - s_j)` is evaluated as written when
//! `|s_i - s_j| > eps max(1, |s_i|, |s_j|)` and otherwise replaced by its limit
//! `(dg_i/ds_i - dg_i/ds_j + dg_j/ds_j - dg_j/ds_i) / 2` (exact for the symmetric functions all
//! models are), with `eps = 4 sqrt(machine epsilon)` (6e-8 in f64, 1.4e-3 in f32): the error is
//! then O(eps) instead of the O(machine epsilon / gap) cancellation. Sums `s_i + s_j` (which
//! vanish only for inverted elements with equal magnitudes) are kept at least `eps` in
//! magnitude. A material at rest (`F = I`, all singular values equal) is therefore handled
//! exactly by the limit.

use crate::constitutive::{scalar_model, MaterialParams, ModelIn, ModelOut, PlasticState, Scalar};
use crate::material::PartConsts;
use crate::math::{svd3, Mat3, Real, Svd3};
use std::ops::{Add, Div, Mul, Neg, Sub};

/// Number of dual directions: 3 singular values, 2 plastic state entries, mu, lambda,
/// plastic viscosity, Drucker-Prager alpha, hardening coefficient.
pub const DIRS: usize = 10;

/// A forward-mode dual number with `N` tangent directions.
#[derive(Clone, Copy, Debug)]
pub struct Dual<T, const N: usize> {
    /// Value.
    pub v: T,
    /// Derivatives along each direction.
    pub d: [T; N],
}

impl<T: Real, const N: usize> Dual<T, N> {
    /// A variable: value `v`, derivative 1 along direction `i`.
    pub fn var(v: T, i: usize) -> Self {
        let mut d = [T::zero(); N];
        d[i] = T::one();
        Dual { v, d }
    }
    fn scale_d(self, k: T) -> [T; N] {
        self.d.map(|x| x * k)
    }
}

impl<T: Real, const N: usize> Add for Dual<T, N> {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Dual {
            v: self.v + o.v,
            d: std::array::from_fn(|i| self.d[i] + o.d[i]),
        }
    }
}
impl<T: Real, const N: usize> Sub for Dual<T, N> {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        Dual {
            v: self.v - o.v,
            d: std::array::from_fn(|i| self.d[i] - o.d[i]),
        }
    }
}
impl<T: Real, const N: usize> Mul for Dual<T, N> {
    type Output = Self;
    #[expect(clippy::suspicious_arithmetic_impl, reason = "the product rule adds")]
    fn mul(self, o: Self) -> Self {
        Dual {
            v: self.v * o.v,
            d: std::array::from_fn(|i| self.d[i] * o.v + self.v * o.d[i]),
        }
    }
}
impl<T: Real, const N: usize> Div for Dual<T, N> {
    type Output = Self;
    fn div(self, o: Self) -> Self {
        let inv = T::one() / o.v;
        let q = self.v * inv;
        Dual {
            v: q,
            d: std::array::from_fn(|i| (self.d[i] - q * o.d[i]) * inv),
        }
    }
}
impl<T: Real, const N: usize> Neg for Dual<T, N> {
    type Output = Self;
    fn neg(self) -> Self {
        Dual {
            v: -self.v,
            d: self.d.map(|x| -x),
        }
    }
}

impl<T: Real, const N: usize> Scalar for Dual<T, N> {
    fn cst(x: f64) -> Self {
        Dual {
            v: T::c(x),
            d: [T::zero(); N],
        }
    }
    fn re(self) -> f64 {
        self.v.f64()
    }
    fn ln(self) -> Self {
        Dual {
            v: num_traits::Float::ln(self.v),
            d: self.scale_d(T::one() / self.v),
        }
    }
    fn exp(self) -> Self {
        let e = num_traits::Float::exp(self.v);
        Dual {
            v: e,
            d: self.scale_d(e),
        }
    }
    fn sqrt(self) -> Self {
        let r = num_traits::Float::sqrt(self.v);
        // At 0 (the norm of a zero vector) the derivative does not exist; use 0.
        let k = if r > T::zero() {
            T::c(0.5) / r
        } else {
            T::zero()
        };
        Dual {
            v: r,
            d: self.scale_d(k),
        }
    }
    fn abs(self) -> Self {
        if self.v < T::zero() {
            -self
        } else {
            self
        }
    }
}

/// Adjoints of the inputs of [`stress_update_with`](crate::constitutive::stress_update_with).
#[derive(Clone, Copy, Debug)]
pub struct ConstitutiveBar<T> {
    /// Adjoint of F_trial.
    pub f_trial: Mat3<T>,
    /// Adjoint of the plastic state before the substep.
    pub state: PlasticState<T>,
    /// Adjoints of the material constants.
    pub params: MaterialParams<T>,
}

/// The jelly's scalar model (fixed corotated, purely elastic) with its Jacobian in closed form:
/// `t_i = 2 mu (s_i - 1) s_i + lambda J (J - 1)`, `J = s_0 s_1 s_2`, so
/// `dt_i/ds_j = [i = j] 2 mu (2 s_i - 1) + lambda (2 J - 1) J / s_j` (`J / s_j` the product of
/// the other two), `dt_i/dmu = 2 (s_i - 1) s_i`, `dt_i/dlambda = J (J - 1)`; F and the plastic
/// state pass through unchanged. The same values and derivatives as [`scalar_model`] on dual
/// numbers (the test oracle) without the ten-direction arithmetic of the hottest material.
fn fixed_corotated_jacobian<T: Real>(
    s: [T; 3],
    state: PlasticState<T>,
    p: MaterialParams<T>,
) -> ModelOut<Dual<T, DIRS>> {
    let (one, two) = (T::one(), T::c(2.0));
    let j = s[0] * s[1] * s[2];
    let vol = p.lambda * j * (j - one);
    let cof = [s[1] * s[2], s[0] * s[2], s[0] * s[1]];
    let dvol = p.lambda * (two * j - one);
    let t = std::array::from_fn(|i| {
        let mut d = [T::zero(); DIRS];
        for (jj, dj) in d.iter_mut().take(3).enumerate() {
            *dj = dvol * cof[jj];
        }
        d[i] += two * p.mu * (two * s[i] - one);
        d[5] = two * (s[i] - one) * s[i];
        d[6] = j * (j - one);
        Dual {
            v: two * p.mu * (s[i] - one) * s[i] + vol,
            d,
        }
    });
    let var = |v: T, i: usize| Dual::<T, DIRS>::var(v, i);
    ModelOut {
        sigma_e: [var(s[0], 0), var(s[1], 1), var(s[2], 2)],
        t,
        state: [var(state[0], 3), var(state[1], 4)],
        unchanged: true,
    }
}

/// The scalar model's inputs as dual numbers, one direction each (the order of [`DIRS`]).
fn dual_inputs<T: Real>(
    s: [T; 3],
    state: PlasticState<T>,
    p: MaterialParams<T>,
) -> ModelIn<Dual<T, DIRS>> {
    let var = |v: T, i: usize| Dual::<T, DIRS>::var(v, i);
    ModelIn {
        sigma: [var(s[0], 0), var(s[1], 1), var(s[2], 2)],
        state: [var(state[0], 3), var(state[1], 4)],
        mu: var(p.mu, 5),
        lambda: var(p.lambda, 6),
        eta: var(p.eta, 7),
        alpha: var(p.alpha, 8),
        h: var(p.h, 9),
    }
}

/// Stable divided difference `(g_i - g_j) / (s_i - s_j)` (see the module docs).
fn divided<T: Real>(g: &[Dual<T, DIRS>; 3], s: [T; 3], i: usize, j: usize, eps: T) -> T {
    let gap = s[i] - s[j];
    let scale = T::one().max(s[i].abs()).max(s[j].abs());
    if gap.abs() > eps * scale {
        (g[i].v - g[j].v) / gap
    } else {
        T::c(0.5) * (g[i].d[i] - g[i].d[j] + g[j].d[j] - g[j].d[i])
    }
}

/// Keeps `x` at least `eps` in magnitude, with its sign.
fn away_from_zero<T: Real>(x: T, eps: T) -> T {
    if x.abs() >= eps {
        x
    } else if x < T::zero() {
        -eps
    } else {
        eps
    }
}

/// Adjoint of [`stress_update_with`](crate::constitutive::stress_update_with) (isotropic
/// models; the fluid is not differentiated yet). `fe_bar`, `tau_bar` and `state_bar` are the
/// adjoints of `F_elastic`, `tau` and the plastic state after the call.
///
/// The adjoint is evaluated in f64 whatever `T` is: the divided differences of the
/// regularisation need a threshold well below the plastic windows of the models (snow's
/// critical stretch is 7.5e-3), which f32 arithmetic cannot resolve.
#[allow(clippy::too_many_arguments)]
pub fn stress_update_vjp<T: Real>(
    f_trial: Mat3<T>,
    pc: &PartConsts,
    state: PlasticState<T>,
    p: MaterialParams<T>,
    dt: T,
    fe_bar: Mat3<T>,
    tau_bar: Mat3<T>,
    state_bar: PlasticState<T>,
) -> ConstitutiveBar<T> {
    let f64_trial: Mat3<f64> = f_trial.cast();
    stress_update_vjp_svd(
        &svd3(f64_trial),
        pc,
        state,
        p,
        dt,
        fe_bar,
        tau_bar,
        state_bar,
    )
}

/// [`stress_update_vjp`] given `svd`, the f64 SVD of F_trial (bitwise
/// `svd3(f_trial.cast::<f64>())`, which is all the adjoint reads of F_trial; backends compute
/// them in batches with [`crate::math::svd3_many`]).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn stress_update_vjp_svd<T: Real>(
    svd: &Svd3<f64>,
    pc: &PartConsts,
    state: PlasticState<T>,
    p: MaterialParams<T>,
    dt: T,
    fe_bar: Mat3<T>,
    tau_bar: Mat3<T>,
    state_bar: PlasticState<T>,
) -> ConstitutiveBar<T> {
    let c = |x: T| x.f64();
    let b = stress_update_vjp_inner::<f64>(
        svd,
        pc,
        state.map(c),
        MaterialParams {
            mu: c(p.mu),
            lambda: c(p.lambda),
            eta: c(p.eta),
            alpha: c(p.alpha),
            h: c(p.h),
        },
        c(dt),
        fe_bar.cast(),
        tau_bar.cast(),
        state_bar.map(c),
    );
    let t = |x: f64| T::c(x);
    ConstitutiveBar {
        f_trial: b.f_trial.cast(),
        state: b.state.map(t),
        params: MaterialParams {
            mu: t(b.params.mu),
            lambda: t(b.params.lambda),
            eta: t(b.params.eta),
            alpha: t(b.params.alpha),
            h: t(b.params.h),
        },
    }
}

#[allow(clippy::too_many_arguments)]
fn stress_update_vjp_inner<T: Real>(
    svd: &Svd3<T>,
    pc: &PartConsts,
    state: PlasticState<T>,
    p: MaterialParams<T>,
    dt: T,
    fe_bar: Mat3<T>,
    tau_bar: Mat3<T>,
    state_bar: PlasticState<T>,
) -> ConstitutiveBar<T> {
    assert!(
        pc.material != 6,
        "the fluid model is not differentiated yet"
    );
    let s = svd.sigma;
    let out = if pc.material == 0 {
        fixed_corotated_jacobian(s, state, p)
    } else {
        scalar_model(pc, dual_inputs(s, state, p), dt.f64())
    };
    let (u, v) = (svd.u, svd.v);
    let g_hat = u.transpose() * fe_bar * v;
    let t_hat = u.transpose() * tau_bar.sym() * u;
    // Adjoint of the 10 scalar inputs.
    let mut d_bar = [T::zero(); DIRS];
    for i in 0..3 {
        for (e, db) in d_bar.iter_mut().enumerate() {
            *db += t_hat.0[i][i] * out.t[i].d[e];
            if !out.unchanged {
                *db += g_hat.0[i][i] * out.sigma_e[i].d[e];
            }
        }
    }
    for kx in 0..2 {
        for (e, db) in d_bar.iter_mut().enumerate() {
            *db += state_bar[kx] * out.state[kx].d[e];
        }
    }
    let eps = T::c(4.0) * num_traits::Float::sqrt(T::epsilon());
    let mut f_hat = Mat3::diag([d_bar[0], d_bar[1], d_bar[2]]);
    for i in 0..3 {
        for j in (i + 1)..3 {
            let sum = away_from_zero(s[i] + s[j], eps);
            if !out.unchanged {
                let dm = divided(&out.sigma_e, s, i, j, eps);
                let dp = (out.sigma_e[i].v + out.sigma_e[j].v) / sum;
                let (a, b) = (T::c(0.5) * (dm + dp), T::c(0.5) * (dm - dp));
                let (gij, gji) = (g_hat.0[i][j], g_hat.0[j][i]);
                f_hat.0[i][j] += a * gij + b * gji;
                f_hat.0[j][i] += b * gij + a * gji;
            }
            let c = divided(&out.t, s, i, j, eps) / sum * (t_hat.0[i][j] + t_hat.0[j][i]);
            f_hat.0[i][j] += c * s[j];
            f_hat.0[j][i] += c * s[i];
        }
    }
    let mut f_bar = u * f_hat * v.transpose();
    if out.unchanged {
        f_bar = f_bar + fe_bar;
    }
    ConstitutiveBar {
        f_trial: f_bar,
        state: [d_bar[3], d_bar[4]],
        params: MaterialParams {
            mu: d_bar[5],
            lambda: d_bar[6],
            eta: d_bar[7],
            alpha: d_bar[8],
            h: d_bar[9],
        },
    }
}

/// Adjoints of the inputs of the fluid model ([`crate::constitutive::fluid`]).
#[derive(Clone, Copy, Debug)]
pub struct FluidBar<T> {
    /// Adjoint of F_trial.
    pub f_trial: Mat3<T>,
    /// Adjoint of the APIC matrix `C` the viscous stress reads.
    pub grad_v: Mat3<T>,
    /// Adjoints of the material constants: `mu` and `lambda` through the bulk modulus
    /// `K = lambda + 2 mu / 3`, and the viscosity `eta` (alpha and h are 0).
    pub params: MaterialParams<T>,
}

/// Reverse of [`crate::constitutive::fluid`] given `svd`, the SVD of F_trial: from the
/// adjoints of `F_elastic = cbrt(J) I` and of `tau = eta J (C + C^T) + K J (J - 1) I`
/// (`J = det F_trial = s_0 s_1 s_2`) to those of F_trial (`dJ/dF = cof F = U diag(s_1 s_2,
/// s_0 s_2, s_0 s_1) V^T`), of `C` and of the constants.
pub fn fluid_vjp<T: Real>(
    svd: &Svd3<T>,
    p: MaterialParams<T>,
    grad_v: &Mat3<T>,
    fe_bar: Mat3<T>,
    tau_bar: Mat3<T>,
) -> FluidBar<T> {
    let s = svd.sigma;
    let j = s[0] * s[1] * s[2];
    let (one, two, three) = (T::one(), T::c(2.0), T::c(3.0));
    let k = p.lambda + T::c(2.0 / 3.0) * p.mu;
    let sym = (*grad_v + grad_v.transpose()).to_array();
    let tb = tau_bar.to_array();
    let contract = (0..9).fold(T::zero(), |a, e| a + tb[e] * sym[e]);
    let tr_tb = tb[0] + tb[4] + tb[8];
    let fe = fe_bar.to_array();
    let tr_fe = fe[0] + fe[4] + fe[8];
    // d cbrt(J) / dJ = cbrt(J) / (3 J) (taken as 0 at J = 0, where the forward's cbrt has
    // no derivative).
    let dc = if j == T::zero() {
        T::zero()
    } else {
        num_traits::Float::cbrt(num_traits::Float::abs(j)) * num_traits::Float::signum(j)
            / (three * j)
    };
    let j_bar = tr_fe * dc + p.eta * contract + k * (two * j - one) * tr_tb;
    let cof = svd.compose([s[1] * s[2], s[0] * s[2], s[0] * s[1]]);
    let k_bar = j * (j - one) * tr_tb;
    FluidBar {
        f_trial: cof.scaled(j_bar),
        grad_v: (tau_bar + tau_bar.transpose()).scaled(p.eta * j),
        params: MaterialParams {
            mu: T::c(2.0 / 3.0) * k_bar,
            lambda: k_bar,
            eta: j * contract,
            alpha: T::zero(),
            h: T::zero(),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::PartConsts;

    #[test]
    fn jelly_jacobian_in_closed_form_matches_the_dual_numbers() {
        let pc = PartConsts {
            material: 0,
            ..Default::default()
        };
        let mut seed = 17u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for k in 0..200 {
            // Near rest, stretched, compressed, inverted (negative last value), repeated.
            let mut s = [0.5 + rnd(), 0.5 + rnd(), 0.5 + rnd()];
            if k % 5 == 0 {
                s[2] = -s[2];
            }
            if k % 7 == 0 {
                s[1] = s[0];
            }
            let state = [rnd() * 1e3, 1.0 + rnd()];
            let p = MaterialParams {
                mu: 1e3 + 1e5 * rnd(),
                lambda: 1e3 + 1e5 * rnd(),
                eta: rnd(),
                alpha: rnd(),
                h: rnd(),
            };
            let want = scalar_model(&pc, dual_inputs(s, state, p), 1e-4);
            let got = fixed_corotated_jacobian(s, state, p);
            assert_eq!(want.unchanged, got.unchanged);
            let pairs = want
                .t
                .iter()
                .zip(&got.t)
                .chain(want.sigma_e.iter().zip(&got.sigma_e))
                .chain(want.state.iter().zip(&got.state));
            for (w, g) in pairs {
                let scale =
                    w.v.abs()
                        .max(w.d.iter().fold(0.0f64, |m, x| m.max(x.abs())));
                assert!(
                    (w.v - g.v).abs() <= 1e-13 * scale.max(1.0),
                    "{s:?}: {} vs {}",
                    w.v,
                    g.v
                );
                for e in 0..DIRS {
                    assert!(
                        (w.d[e] - g.d[e]).abs() <= 1e-12 * scale.max(1.0),
                        "{s:?} direction {e}: {} vs {}",
                        w.d[e],
                        g.d[e]
                    );
                }
            }
        }
    }

    /// The fluid's VJP against central differences of the forward model in f64, for every
    /// entry of F_trial and C and every constant, at stretched, compressed and inverted F.
    #[test]
    fn fluid_vjp_matches_finite_differences() {
        use crate::constitutive::fluid;
        let mut seed = 11u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for case in 0..6 {
            let mut fa: [f64; 9] =
                std::array::from_fn(|e| (if e % 4 == 0 { 1.0 } else { 0.0 }) + 0.3 * rnd());
            if case == 5 {
                fa[8] = -fa[8]; // inverted
            }
            let f = Mat3::from_array(fa);
            let c = Mat3::from_array(std::array::from_fn(|_| 20.0 * rnd()));
            let p = MaterialParams {
                mu: 1e3 * (1.5 + rnd()),
                lambda: 3e4 * (1.5 + rnd()),
                eta: 0.5 + rnd(),
                alpha: 0.0,
                h: 0.0,
            };
            let wf = Mat3::from_array(std::array::from_fn(|_| rnd()));
            let wt = Mat3::from_array(std::array::from_fn(|_| 1e-4 * rnd()));
            let loss = |f: Mat3<f64>, c: Mat3<f64>, p: MaterialParams<f64>| {
                let (fe, tau) = fluid(&svd3(f), p, &c);
                let (fe, tau, a, b) = (fe.to_array(), tau.to_array(), wf.to_array(), wt.to_array());
                (0..9).map(|e| fe[e] * a[e] + tau[e] * b[e]).sum::<f64>()
            };
            let bar = fluid_vjp(&svd3(f), p, &c, wf, wt);
            let fd = |g: &dyn Fn(f64) -> f64, x: f64| {
                let h = 1e-6 * x.abs().max(1.0);
                (g(x + h) - g(x - h)) / (2.0 * h)
            };
            // Relative 1e-6, above the differences' round-off (the loss is O(10): about 1e-10
            // absolute at these steps).
            let check = |what: String, a: f64, n: f64| {
                let scale = a.abs().max(n.abs());
                assert!(
                    (a - n).abs() < 1e-6 * scale + 1e-9,
                    "case {case}: {what}: {a:e} vs fd {n:e}"
                );
            };
            for e in 0..9 {
                let g = |t: f64| {
                    let mut a = fa;
                    a[e] = t;
                    loss(Mat3::from_array(a), c, p)
                };
                check(format!("dF[{e}]"), bar.f_trial.to_array()[e], fd(&g, fa[e]));
                let ca = c.to_array();
                let g = |t: f64| {
                    let mut a = ca;
                    a[e] = t;
                    loss(f, Mat3::from_array(a), p)
                };
                check(format!("dC[{e}]"), bar.grad_v.to_array()[e], fd(&g, ca[e]));
            }
            let g = |t: f64| loss(f, c, MaterialParams { mu: t, ..p });
            check("dmu".into(), bar.params.mu, fd(&g, p.mu));
            let g = |t: f64| loss(f, c, MaterialParams { lambda: t, ..p });
            check("dlambda".into(), bar.params.lambda, fd(&g, p.lambda));
            let g = |t: f64| loss(f, c, MaterialParams { eta: t, ..p });
            check("deta".into(), bar.params.eta, fd(&g, p.eta));
        }
    }
}
