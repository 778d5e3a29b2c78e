//! The parameter mapping, written once: from the physical parameters of each parameter slot
//! (a part, or a particle in the per-particle ablation) to the tables the kernels read
//! ([`SlotTables`]: fixed constants and differentiable material constants per slot, masses per
//! particle), and its chain rule back ([`PhysParams::add_material_vjp`]).

use crate::constitutive::MaterialParams;
use crate::material::{PartConsts, PartParams};
use crate::math::Real;

/// The physical parameters of a part that receive gradients, in SI units.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PhysParams<T> {
    /// Young's modulus E (Pa).
    pub youngs_modulus: T,
    /// Poisson's ratio nu.
    pub poisson_ratio: T,
    /// Initial yield stress (Pa).
    pub yield_stress: T,
    /// Plastic viscosity (Pa s).
    pub plastic_viscosity: T,
    /// Friction angle (degrees).
    pub friction_angle_deg: T,
    /// Density (kg/m^3).
    pub density: T,
    /// Metal's hardening coefficient xi (0 for a metal whose `hardening` is off).
    pub hardening: T,
    /// Plasticine's softening rate.
    pub softening: T,
}

/// Floats per slot of the differentiable material constants table ([`SlotTables::mats`]):
/// `[mu, lambda, plastic viscosity, Drucker-Prager alpha, hardening coefficient]`.
pub const MAT_CONSTS: usize = 5;

/// Floats per particle and per slot of the parameter adjoints the reverse sweep accumulates:
/// `[mu, lambda, plastic viscosity, Drucker-Prager alpha, density, hardening coefficient]`
/// (the adjoints of the [`SlotTables::mats`] entries and of the density).
pub const PARAM_ADJOINTS: usize = 6;

/// PhysGaussian's degrees-to-radians factor (its truncated pi), kept for identical yields.
#[expect(clippy::approx_constant, reason = "PhysGaussian's truncated pi")]
const DEG: f64 = 3.14159265 / 180.0;

impl<T: Real> PhysParams<T> {
    /// The values of a part.
    pub fn of(p: &PartParams) -> Self {
        PhysParams {
            youngs_modulus: T::c(p.youngs_modulus_pa),
            poisson_ratio: T::c(p.poisson_ratio),
            yield_stress: T::c(p.yield_stress_pa),
            plastic_viscosity: T::c(p.plastic_viscosity_pa_s),
            friction_angle_deg: T::c(p.friction_angle_deg),
            density: T::c(p.density_kg_m3),
            hardening: T::c(if p.hardening { p.xi } else { 0.0 }),
            softening: T::c(p.softening),
        }
    }

    /// The hardening coefficient model `model` ([`crate::Material::kernel_id`]) reads:
    /// metal's xi, plasticine's softening, 0 for the others
    /// ([`PartConsts::hardening_coeff`]).
    pub fn hardening_coeff(&self, model: u32) -> T {
        match model {
            1 => self.hardening,
            5 => self.softening,
            _ => T::zero(),
        }
    }

    /// The constants model `model` ([`crate::Material::kernel_id`]) reads: mu, lambda,
    /// plastic viscosity, alpha, hardening coefficient.
    pub fn material(&self, model: u32) -> MaterialParams<T> {
        let (e, nu) = (self.youngs_modulus, self.poisson_ratio);
        let one = T::one();
        let two = T::c(2.0);
        let phi = self.friction_angle_deg * T::c(DEG);
        let sp = phi.sin();
        MaterialParams {
            mu: e / (two * (one + nu)),
            lambda: e * nu / ((one + nu) * (one - two * nu)),
            eta: self.plastic_viscosity,
            alpha: T::c((2.0f64 / 3.0).sqrt()) * two * sp / (T::c(3.0) - sp),
            h: self.hardening_coeff(model),
        }
    }

    /// Chain rule of [`PhysParams::material`] for model `model`: adds the gradient of the
    /// physical parameters given that of the material constants.
    pub fn add_material_vjp(&self, bar: &MaterialParams<T>, model: u32, out: &mut PhysParams<T>) {
        let (e, nu) = (self.youngs_modulus, self.poisson_ratio);
        let one = T::one();
        let two = T::c(2.0);
        let d = (one + nu) * (one - two * nu);
        out.youngs_modulus += bar.mu / (two * (one + nu)) + bar.lambda * nu / d;
        out.poisson_ratio += -bar.mu * e / (two * (one + nu) * (one + nu))
            + bar.lambda * e * (one + two * nu * nu) / (d * d);
        out.plastic_viscosity += bar.eta;
        let phi = self.friction_angle_deg * T::c(DEG);
        let (sp, cp) = (phi.sin(), phi.cos());
        let da = T::c((2.0f64 / 3.0).sqrt()) * two * T::c(3.0) * cp
            / ((T::c(3.0) - sp) * (T::c(3.0) - sp));
        out.friction_angle_deg += bar.alpha * da * T::c(DEG);
        match model {
            1 => out.hardening += bar.h,
            5 => out.softening += bar.h,
            _ => {}
        }
    }
}

impl<T: Real> PhysParams<T> {
    /// The same values in f64.
    pub fn to_f64(&self) -> PhysParams<f64> {
        PhysParams {
            youngs_modulus: self.youngs_modulus.f64(),
            poisson_ratio: self.poisson_ratio.f64(),
            yield_stress: self.yield_stress.f64(),
            plastic_viscosity: self.plastic_viscosity.f64(),
            friction_angle_deg: self.friction_angle_deg.f64(),
            density: self.density.f64(),
            hardening: self.hardening.f64(),
            softening: self.softening.f64(),
        }
    }

    /// The gradient of these parameters, for a slot of model `model`, from the slot's
    /// accumulated adjoints (the kernels' parameter adjoints, [`PARAM_ADJOINTS`]): the chain
    /// rule of [`PhysParams::material`] and of the masses.
    pub fn from_slot_adjoint(&self, a: &[T; PARAM_ADJOINTS], model: u32) -> PhysParams<T> {
        let mut out = PhysParams::default();
        let bar = MaterialParams {
            mu: a[0],
            lambda: a[1],
            eta: a[2],
            alpha: a[3],
            h: a[5],
        };
        self.add_material_vjp(&bar, model, &mut out);
        out.density += a[4];
        out
    }
}

/// What the kernels read about the parameters: per slot the fixed constants ([`PartConsts`],
/// with the differentiable fields overwritten from the slot's parameters, rounded to f32) and
/// the material constants ([`MAT_CONSTS`]: mu, lambda, plastic viscosity, alpha, hardening
/// coefficient) in the scalar type `S`; per particle its mass `density x V0`.
#[derive(Clone, Debug, PartialEq)]
pub struct SlotTables<S> {
    /// Constants per slot.
    pub parts: Vec<PartConsts>,
    /// `[mu, lambda, plastic viscosity, Drucker-Prager alpha, hardening coefficient]` per slot.
    pub mats: Vec<[S; MAT_CONSTS]>,
    /// Mass per particle.
    pub mass: Vec<S>,
}

impl<S: Real> SlotTables<S> {
    /// The tables for parameters `params` (one per slot). `part_consts` holds each part's
    /// constants ([`PartParams::consts`]), `slot_part` the part of each slot, `slot` the slot
    /// of each particle and `vol0` its initial volume (`f32` as files hold it, or `f64`).
    pub fn new<V: Copy + Into<f64>>(
        params: &[PhysParams<S>],
        part_consts: &[PartConsts],
        slot_part: &[u32],
        slot: &[u32],
        vol0: &[V],
    ) -> Self {
        let mut parts = Vec::with_capacity(params.len());
        let mut mats = Vec::with_capacity(params.len());
        for (p, &part) in params.iter().zip(slot_part) {
            let base = &part_consts[part as usize];
            let m = p.material(base.material);
            mats.push([m.mu, m.lambda, m.eta, m.alpha, m.h]);
            parts.push(PartConsts {
                mu: m.mu.f64() as f32,
                lambda: m.lambda.f64() as f32,
                plastic_viscosity: m.eta.f64() as f32,
                dp_alpha: m.alpha.f64() as f32,
                yield_stress: p.yield_stress.f64() as f32,
                hardening_xi: p.hardening.f64() as f32,
                softening: p.softening.f64() as f32,
                bulk: (m.lambda + S::c(2.0 / 3.0) * m.mu).f64() as f32,
                ..*base
            });
        }
        let mass = vol0
            .iter()
            .zip(slot)
            .map(|(&v, &s)| params[s as usize].density * S::c(v.into()))
            .collect();
        SlotTables { parts, mats, mass }
    }
}

/// The material constants of a `mats` table entry.
#[inline(always)]
pub fn material_of<S: Real>(m: &[S; MAT_CONSTS]) -> MaterialParams<S> {
    MaterialParams {
        mu: m[0],
        lambda: m[1],
        eta: m[2],
        alpha: m[3],
        h: m[4],
    }
}

/// The parameters of each part of a config, in scalar type `S`.
pub fn phys_params<S: Real>(parts: &[PartParams]) -> Vec<PhysParams<S>> {
    parts.iter().map(PhysParams::of).collect()
}
