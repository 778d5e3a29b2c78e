//! The reverse of a particle's P2G stage (particle boundary conditions, return mapping and
//! stress, scatter) as one per-particle function, written once and called by every host
//! backend's `p2g_vjp` kernel.

use super::constitutive_vjp::{fluid_vjp, stress_update_vjp_svd, ConstitutiveBar};
use super::transfer_vjp::{damped_affine_vjp, particle_bcs_vjp, scatter_vjp, ScatterBar};
use crate::constitutive::MaterialParams;
use crate::kernels::{ParticleBc, StepConsts};
use crate::material::PartConsts;
use crate::math::{svd3, Mat3, Real, Svd3};
use crate::params::{material_of, MAT_CONSTS, PARAM_ADJOINTS};
use crate::transfer::{damped_affine, in_domain, k, stencil, stress_scale};

/// What the reverse of one particle's P2G stage reads from the forward pass.
#[derive(Clone, Copy, Debug)]
pub struct ParticleForward<'a, T> {
    /// Initial position (particle boundary conditions select by it).
    pub x0: [f32; 3],
    /// Position at the start of the substep.
    pub x: [T; 3],
    /// APIC matrix at the start of the substep.
    pub c: &'a [T; 9],
    /// F_trial (F at the start of the substep).
    pub f_trial: &'a [T; 9],
    /// Plastic state at the start of the substep.
    pub plastic: [T; 2],
    /// Velocity after the particle boundary conditions.
    pub v1: [T; 3],
    /// Mass.
    pub mass: T,
    /// Initial volume.
    pub vol0: T,
    /// The scatter's stress term.
    pub stress: &'a [T; 9],
    /// The slot's constants.
    pub pc: &'a PartConsts,
    /// The slot's material constants `[mu, lambda, eta, alpha]`.
    pub mat: &'a [T; MAT_CONSTS],
}

/// One particle's adjoint state before the substep.
#[derive(Clone, Copy, Debug, Default)]
pub struct ParticleBar<T> {
    /// Position adjoint.
    pub x: [T; 3],
    /// Velocity adjoint.
    pub v: [T; 3],
    /// APIC matrix adjoint.
    pub c: [T; 9],
    /// Deformation gradient adjoint.
    pub f: [T; 9],
    /// Plastic state adjoint.
    pub plastic: [T; 2],
}

/// Reverse of the particle's P2G stage: from the scattered grid's adjoint `grid_in_bar` (the
/// whole grid, `n^3` nodes), the adjoints of F_elastic and of the plastic state after the
/// substep and the position adjoint gathered by G2P, returns the particle's adjoint before the
/// substep and its parameter adjoints `[mu, lambda, eta, alpha, density]` (for its slot).
/// A particle outside the grid (skipped by the forward transfers) gets zeros.
#[allow(clippy::too_many_arguments)]
pub fn particle_stage_vjp<T: Real>(
    fw: &ParticleForward<T>,
    grid_in_bar: &[[T; 4]],
    n: usize,
    pbcs: &[ParticleBc],
    c: &StepConsts,
    fe_bar: &[T; 9],
    x_bar_g2p: &[T; 3],
    plastic_bar: &[T; 2],
) -> (ParticleBar<T>, [T; PARAM_ADJOINTS]) {
    let svd = svd3(Mat3::from_array(*fw.f_trial).cast::<f64>());
    particle_stage_vjp_svd(
        fw,
        &svd,
        grid_in_bar,
        n,
        pbcs,
        c,
        fe_bar,
        x_bar_g2p,
        plastic_bar,
    )
}

/// [`particle_stage_vjp`] given `svd`, the f64 SVD of F_trial (bitwise
/// `svd3(f_trial.cast::<f64>())`; the CPU backend computes them in batches with
/// [`crate::math::svd3_many`]).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn particle_stage_vjp_svd<T: Real>(
    fw: &ParticleForward<T>,
    svd: &Svd3<f64>,
    grid_in_bar: &[[T; 4]],
    n: usize,
    pbcs: &[ParticleBc],
    c: &StepConsts,
    fe_bar: &[T; 9],
    x_bar_g2p: &[T; 3],
    plastic_bar: &[T; 2],
) -> (ParticleBar<T>, [T; PARAM_ADJOINTS]) {
    let z = T::zero();
    if !in_domain(fw.x, k::<T>(c.inv_dx), n) {
        return (ParticleBar::default(), [z; PARAM_ADJOINTS]);
    }
    let st = stencil(fw.x, k::<T>(c.inv_dx));
    let a = damped_affine(fw.c, c.rpic_damping);
    let mut sb = ScatterBar::default();
    scatter_vjp(
        grid_in_bar,
        n,
        &st,
        fw.v1,
        &a,
        fw.mass,
        fw.stress,
        c,
        &mut sb,
    );
    let tau_bar = Mat3::from_array(sb.s).scaled(stress_scale(fw.vol0, c));
    let mut c_bar = damped_affine_vjp(&sb.a, c.rpic_damping);
    let cb = if fw.pc.material == crate::Material::Fluid.kernel_id() {
        // The fluid reads the APIC matrix itself (its viscous stress) and keeps the plastic
        // state; the forward symmetrises tau, so its adjoint is symmetrised first.
        let m = material_of(fw.mat);
        let f64m = |x: T| x.f64();
        let fb = fluid_vjp::<f64>(
            svd,
            MaterialParams {
                mu: f64m(m.mu),
                lambda: f64m(m.lambda),
                eta: f64m(m.eta),
                alpha: 0.0,
                h: 0.0,
            },
            &Mat3::from_array(*fw.c).cast(),
            Mat3::from_array(*fe_bar).cast(),
            tau_bar.sym().cast(),
        );
        let cf = fb.grad_v.to_array();
        for (a, &b) in c_bar.iter_mut().zip(&cf) {
            *a += T::c(b);
        }
        let t = |x: f64| T::c(x);
        ConstitutiveBar {
            f_trial: fb.f_trial.cast(),
            state: *plastic_bar,
            params: MaterialParams {
                mu: t(fb.params.mu),
                lambda: t(fb.params.lambda),
                eta: t(fb.params.eta),
                alpha: T::zero(),
                h: T::zero(),
            },
        }
    } else {
        stress_update_vjp_svd(
            svd,
            fw.pc,
            fw.plastic,
            material_of(fw.mat),
            k(c.dt),
            Mat3::from_array(*fe_bar),
            tau_bar,
            *plastic_bar,
        )
    };
    let mut v_bar = sb.v;
    let mut m_bar = sb.mass;
    particle_bcs_vjp(fw.x0, fw.mass, pbcs, c, &mut v_bar, &mut m_bar);
    let bar = ParticleBar {
        x: std::array::from_fn(|q| x_bar_g2p[q] + sb.x[q]),
        v: v_bar,
        c: c_bar,
        f: cb.f_trial.to_array(),
        plastic: cb.state,
    };
    let p = cb.params;
    (bar, [p.mu, p.lambda, p.eta, p.alpha, m_bar * fw.vol0, p.h])
}
