//! Materials and per-part parameters, with PhysGaussian's meaning, units and defaults.
//!
//! A scene is made of parts; every particle carries a part id and every part carries a
//! [`PartParams`]: a [`Material`] plus the six learnable physical parameters of the paper
//! (Young's modulus, Poisson's ratio, yield stress, plastic viscosity, friction angle, density)
//! and the fixed constants of some models (hardening, softening, snow limits).
//! [`PartParams::validate`] turns bad values into typed errors; [`PartConsts`] is the
//! device-ready (`#[repr(C)]`, f32) form the kernels read.

use crate::error::{Error, Result};
use bytemuck::{Pod, Zeroable};
use serde::{Deserialize, Serialize};

/// Constitutive model of a part. The ids in brackets are PhysGaussian's `material` ids.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Material {
    /// Elastic jelly: fixed corotated hyperelasticity, no plasticity (0).
    #[default]
    Jelly,
    /// Metal: StVK on the Hencky strain with von Mises plasticity, optional hardening (1).
    Metal,
    /// Sand: Drucker-Prager plasticity (Klar et al. 2016) on the Hencky strain (2).
    Sand,
    /// Foam: viscoplastic von Mises (Perzyna-type rate dependence through the plastic
    /// viscosity) with StVK-Hencky stress (3).
    Foam,
    /// Snow: Stomakhin et al. 2013 (singular values clamped to `[1 - theta_c, 1 + theta_s]`,
    /// hardening `exp(xi (1 - J_p))`, fixed corotated stress). PhysGaussian's id 4 computes no
    /// stress at all; this is the real model.
    Snow,
    /// Plasticine: von Mises with softening and fixed corotated stress (5).
    Plasticine,
    /// Weakly compressible Newtonian fluid: pressure `K (J - 1)` with the bulk modulus
    /// `K = E / (3 (1 - 2 nu))` and viscous stress `mu_v (grad v + grad v^T)` with
    /// `mu_v = plastic_viscosity` (Pa s). The deformation gradient keeps only its volume.
    Fluid,
    /// PhysFlow's `"non_newtonian"` (its id 6; toothpaste, cream): the foam's viscoplastic
    /// von Mises mapping on the Hencky strain **without** the yield guard (below the yield
    /// surface the deviatoric stress is pulled toward it every substep), StVK-Hencky stress
    /// (`viscoplasticity_return_mapping_with_StVK_force` and `kirchoff_stress_StVK` of
    /// PhysFlow's `mpm_utils.py`). See [`crate::constitutive`] for its rule at `F = I`.
    NonNewtonian,
    /// PhysFlow's `"newtonian"` (its id 5; droplet, letter): no return mapping and the
    /// compressible neo-Hookean stress of PhysFlow's `kirchoff_stress_herschel`,
    /// `tau = (lambda / 2 + mu / 3) (J^2 - 1 + 1e-8) I + mu dev(J^(-2/3) F F^T)`: an elastic
    /// solid of low shear and high bulk modulus (PhysFlow reads no viscosity for it).
    Newtonian,
}

impl Material {
    /// PhysGaussian's integer id (`None` for models it does not have).
    pub fn physgaussian_id(self) -> Option<u32> {
        match self {
            Material::Jelly => Some(0),
            Material::Metal => Some(1),
            Material::Sand => Some(2),
            Material::Foam => Some(3),
            Material::Snow => Some(4),
            Material::Plasticine => Some(5),
            Material::Fluid | Material::NonNewtonian | Material::Newtonian => None,
        }
    }

    /// PhysFlow's integer id (`set_parameters_dict`: plasticine is 4 there; `None` for models
    /// it does not have).
    pub fn physflow_id(self) -> Option<u32> {
        match self {
            Material::Jelly => Some(0),
            Material::Metal => Some(1),
            Material::Sand => Some(2),
            Material::Foam => Some(3),
            Material::Plasticine => Some(4),
            Material::Newtonian => Some(5),
            Material::NonNewtonian => Some(6),
            Material::Snow | Material::Fluid => None,
        }
    }
    /// The name configs, `params.json` and messages use (`"jelly"`, ..., `"non_newtonian"`,
    /// `"newtonian"`); [`Material::from_name`] reads it back.
    pub fn name(self) -> &'static str {
        match self {
            Material::Jelly => "jelly",
            Material::Metal => "metal",
            Material::Sand => "sand",
            Material::Foam => "foam",
            Material::Snow => "snow",
            Material::Plasticine => "plasticine",
            Material::Fluid => "fluid",
            Material::NonNewtonian => "non_newtonian",
            Material::Newtonian => "newtonian",
        }
    }

    /// Parses PhysGaussian's material name (`"jelly"`, `"metal"`, ...), also accepting
    /// `"water"`/`"fluid"`.
    pub fn from_name(name: &str) -> Option<Material> {
        Some(match name.to_ascii_lowercase().as_str() {
            "jelly" => Material::Jelly,
            "metal" => Material::Metal,
            "sand" => Material::Sand,
            "foam" => Material::Foam,
            "snow" => Material::Snow,
            "plasticine" => Material::Plasticine,
            "fluid" | "water" => Material::Fluid,
            "non_newtonian" => Material::NonNewtonian,
            "newtonian" => Material::Newtonian,
            _ => return None,
        })
    }
    /// The id the kernels switch on.
    pub fn kernel_id(self) -> u32 {
        match self {
            Material::Jelly => 0,
            Material::Metal => 1,
            Material::Sand => 2,
            Material::Foam => 3,
            Material::Snow => 4,
            Material::Plasticine => 5,
            Material::Fluid => 6,
            Material::NonNewtonian => 7,
            Material::Newtonian => 8,
        }
    }
    /// Inverse of [`Material::kernel_id`].
    pub fn from_kernel_id(id: u32) -> Option<Material> {
        Some(match id {
            0 => Material::Jelly,
            1 => Material::Metal,
            2 => Material::Sand,
            3 => Material::Foam,
            4 => Material::Snow,
            5 => Material::Plasticine,
            6 => Material::Fluid,
            7 => Material::NonNewtonian,
            8 => Material::Newtonian,
            _ => return None,
        })
    }
}

/// Parameters of one part, in SI units. Field names carry the units where ambiguous.
///
/// Defaults follow PhysGaussian's solver (`E` 1e5 Pa... see each field); the six learnable
/// parameters are `youngs_modulus_pa`, `poisson_ratio`, `yield_stress_pa`,
/// `plastic_viscosity_pa_s`, `friction_angle_deg` and `density_kg_m3`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PartParams {
    /// Constitutive model.
    pub material: Material,
    /// Young's modulus E in Pa (> 0). Default 1e5.
    #[serde(alias = "E")]
    pub youngs_modulus_pa: f64,
    /// Poisson's ratio nu, in (-1, 0.5). Default 0.2.
    #[serde(alias = "nu")]
    pub poisson_ratio: f64,
    /// Yield stress in Pa (metal, foam, plasticine). Default 1.5e4.
    #[serde(alias = "yield_stress")]
    pub yield_stress_pa: f64,
    /// Plastic viscosity in Pa s (foam; dynamic viscosity for fluids). Default 0.
    #[serde(alias = "plastic_viscosity")]
    pub plastic_viscosity_pa_s: f64,
    /// Friction angle in degrees (sand), in [0, 90). Default 25.
    #[serde(alias = "friction_angle")]
    pub friction_angle_deg: f64,
    /// Density in kg/m^3 (> 0); particle mass = density x initial volume. Default 1000.
    #[serde(alias = "density")]
    pub density_kg_m3: f64,
    /// Metal: when true the yield stress grows by `2 mu xi dgamma` at each plastic step.
    pub hardening: bool,
    /// Metal hardening coefficient xi (dimensionless). Default 0.
    pub xi: f64,
    /// Plasticine softening rate (dimensionless): the yield stress drops by
    /// `softening x |plastic strain increment|` (in Pa per unit strain, PhysGaussian's
    /// convention). Default 0.1.
    pub softening: f64,
    /// Snow critical compression theta_c. Default 2.5e-2 (Stomakhin et al. 2013).
    pub snow_critical_compression: f64,
    /// Snow critical stretch theta_s. Default 7.5e-3.
    pub snow_critical_stretch: f64,
    /// Snow hardening coefficient (xi of Stomakhin et al.). Default 10.
    pub snow_hardening: f64,
}

impl Default for PartParams {
    fn default() -> Self {
        PartParams {
            material: Material::Jelly,
            youngs_modulus_pa: 1e5,
            poisson_ratio: 0.2,
            yield_stress_pa: 1.5e4,
            plastic_viscosity_pa_s: 0.0,
            friction_angle_deg: 25.0,
            density_kg_m3: 1000.0,
            hardening: false,
            xi: 0.0,
            softening: 0.1,
            snow_critical_compression: 2.5e-2,
            snow_critical_stretch: 7.5e-3,
            snow_hardening: 10.0,
        }
    }
}

/// The range every part parameter must lie in (inclusive), besides its own rule (E and
/// density > 0, nu in (-1, 0.5), ...): wide enough for any physical material (diamond's
/// Young's modulus is 1.2e12 Pa, osmium's density 2.3e4 kg/m^3) and narrow enough that the
/// kernels' f32 constants, masses and stresses stay finite and non-zero (with nu < 0.5 in
/// f64, lambda stays below 1e29 Pa).
pub const PARAM_LIMITS: [(&str, f64, f64); 7] = [
    ("youngs_modulus_pa", 1e-6, 1e13),
    ("density_kg_m3", 1e-6, 1e6),
    ("yield_stress_pa", 0.0, 1e13),
    ("plastic_viscosity_pa_s", 0.0, 1e13),
    ("xi", -1e6, 1e6),
    ("softening", 0.0, 1e9),
    ("snow_hardening", -1e6, 1e6),
];

impl PartParams {
    /// The value of a field named in [`PARAM_LIMITS`].
    fn field(&self, name: &str) -> f64 {
        match name {
            "youngs_modulus_pa" => self.youngs_modulus_pa,
            "density_kg_m3" => self.density_kg_m3,
            "yield_stress_pa" => self.yield_stress_pa,
            "plastic_viscosity_pa_s" => self.plastic_viscosity_pa_s,
            "xi" => self.xi,
            "softening" => self.softening,
            "snow_hardening" => self.snow_hardening,
            other => unreachable!("PARAM_LIMITS names {other}"),
        }
    }

    /// Default parameters for a material.
    pub fn new(material: Material) -> Self {
        PartParams {
            material,
            ..Default::default()
        }
    }

    /// Lamé parameters `(mu, lambda)` from E and nu.
    pub fn lame(&self) -> (f64, f64) {
        let e = self.youngs_modulus_pa;
        let nu = self.poisson_ratio;
        (
            e / (2.0 * (1.0 + nu)),
            e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
        )
    }

    /// The longest substep the explicit viscous stress of a `fluid` allows on a grid of
    /// spacing `dx` (m), `max_cfl VISCOUS_STABILITY rho dx^2 / viscosity` (s); `None` for the
    /// other materials and for a fluid without viscosity.
    pub fn viscous_dt_bound(&self, dx: f64, max_cfl: f64) -> Option<f64> {
        (self.material == Material::Fluid && self.plastic_viscosity_pa_s > 0.0).then(|| {
            max_cfl * crate::VISCOUS_STABILITY * self.density_kg_m3 * dx * dx
                / self.plastic_viscosity_pa_s
        })
    }

    /// Speed of the pressure (P) wave `sqrt((lambda + 2 mu) / rho)` in m/s: the fastest wave
    /// the explicit integrator must resolve.
    pub fn p_wave_speed(&self) -> f64 {
        let (mu, la) = self.lame();
        let m = match self.material {
            Material::Fluid => self.youngs_modulus_pa / (3.0 * (1.0 - 2.0 * self.poisson_ratio)),
            _ => la + 2.0 * mu,
        };
        (m / self.density_kg_m3).sqrt()
    }

    /// Checks every field; `what` names the part in errors (e.g. `"parts[2]"` or a file).
    pub fn validate(&self, what: &str) -> Result<()> {
        let bad = |field: &str, value: f64, why: &str| Error::InvalidParameter {
            what: what.to_string(),
            field: field.to_string(),
            value,
            reason: why.to_string(),
        };
        let fin = |field: &str, v: f64| {
            if v.is_finite() {
                Ok(())
            } else {
                Err(bad(field, v, "must be finite"))
            }
        };
        fin("youngs_modulus_pa", self.youngs_modulus_pa)?;
        fin("poisson_ratio", self.poisson_ratio)?;
        fin("yield_stress_pa", self.yield_stress_pa)?;
        fin("plastic_viscosity_pa_s", self.plastic_viscosity_pa_s)?;
        fin("friction_angle_deg", self.friction_angle_deg)?;
        fin("density_kg_m3", self.density_kg_m3)?;
        fin("xi", self.xi)?;
        fin("softening", self.softening)?;
        if self.youngs_modulus_pa <= 0.0 {
            return Err(bad(
                "youngs_modulus_pa",
                self.youngs_modulus_pa,
                "must be > 0",
            ));
        }
        if !(self.poisson_ratio > -1.0 && self.poisson_ratio < 0.5) {
            return Err(bad(
                "poisson_ratio",
                self.poisson_ratio,
                "must lie in (-1, 0.5): at 0.5 the Lame parameter lambda is infinite",
            ));
        }
        if self.density_kg_m3 <= 0.0 {
            return Err(bad("density_kg_m3", self.density_kg_m3, "must be > 0"));
        }
        if self.yield_stress_pa < 0.0 {
            return Err(bad("yield_stress_pa", self.yield_stress_pa, "must be >= 0"));
        }
        if self.plastic_viscosity_pa_s < 0.0 {
            return Err(bad(
                "plastic_viscosity_pa_s",
                self.plastic_viscosity_pa_s,
                "must be >= 0",
            ));
        }
        if !(0.0..90.0).contains(&self.friction_angle_deg) {
            return Err(bad(
                "friction_angle_deg",
                self.friction_angle_deg,
                "must lie in [0, 90)",
            ));
        }
        if self.softening < 0.0 {
            return Err(bad("softening", self.softening, "must be >= 0"));
        }
        for &(field, lo, hi) in PARAM_LIMITS.iter() {
            let v = self.field(field);
            if !(lo..=hi).contains(&v) {
                return Err(bad(
                    field,
                    v,
                    &format!("must lie in [{lo:e}, {hi:e}] (PARAM_LIMITS)"),
                ));
            }
        }
        if self.material == Material::Snow {
            for (f, v) in [
                ("snow_critical_compression", self.snow_critical_compression),
                ("snow_critical_stretch", self.snow_critical_stretch),
            ] {
                if !(v > 0.0 && v < 1.0) {
                    return Err(bad(f, v, "must lie in (0, 1)"));
                }
            }
            fin("snow_hardening", self.snow_hardening)?;
        }
        Ok(())
    }

    /// The f32 constants the kernels read.
    pub fn consts(&self) -> PartConsts {
        let (mu, la) = self.lame();
        // PhysGaussian's constant for pi, kept so imported scenes yield identically.
        #[expect(clippy::approx_constant, reason = "PhysGaussian's truncated pi")]
        let phi = self.friction_angle_deg * 3.14159265 / 180.0;
        let sp = phi.sin();
        let alpha = (2.0f64 / 3.0).sqrt() * 2.0 * sp / (3.0 - sp);
        PartConsts {
            mu: mu as f32,
            lambda: la as f32,
            yield_stress: self.yield_stress_pa as f32,
            plastic_viscosity: self.plastic_viscosity_pa_s as f32,
            dp_alpha: alpha as f32,
            hardening_xi: if self.hardening { self.xi as f32 } else { 0.0 },
            softening: self.softening as f32,
            theta_c: self.snow_critical_compression as f32,
            theta_s: self.snow_critical_stretch as f32,
            snow_xi: self.snow_hardening as f32,
            bulk: (self.youngs_modulus_pa / (3.0 * (1.0 - 2.0 * self.poisson_ratio))) as f32,
            material: self.material.kernel_id(),
        }
    }
}

/// Device-ready constants of one part (f32, `#[repr(C)]`, 48 bytes). Built by
/// [`PartParams::consts`].
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PartConsts {
    /// Lamé mu (Pa).
    pub mu: f32,
    /// Lamé lambda (Pa).
    pub lambda: f32,
    /// Initial yield stress (Pa).
    pub yield_stress: f32,
    /// Plastic viscosity (Pa s).
    pub plastic_viscosity: f32,
    /// Drucker-Prager alpha = sqrt(2/3) 2 sin(phi) / (3 - sin(phi)).
    pub dp_alpha: f32,
    /// Metal hardening coefficient (0 when hardening is off).
    pub hardening_xi: f32,
    /// Plasticine softening.
    pub softening: f32,
    /// Snow critical compression.
    pub theta_c: f32,
    /// Snow critical stretch.
    pub theta_s: f32,
    /// Snow hardening coefficient.
    pub snow_xi: f32,
    /// Bulk modulus (fluid).
    pub bulk: f32,
    /// [`Material::kernel_id`].
    pub material: u32,
}

impl PartConsts {
    /// The hardening coefficient of this part's model, the differentiable constant `h` of
    /// [`crate::constitutive::MaterialParams`]: metal's `hardening_xi` (0 when hardening is
    /// off), plasticine's `softening`, 0 for the models that have none.
    pub fn hardening_coeff(&self) -> f32 {
        match self.material {
            1 => self.hardening_xi,
            5 => self.softening,
            _ => 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One name per material, the one serde writes and `from_name` reads.
    #[test]
    fn names_round_trip() {
        for id in 0..9 {
            let m = Material::from_kernel_id(id).unwrap();
            assert_eq!(Material::from_name(m.name()), Some(m));
            assert_eq!(
                serde_json::to_value(m).unwrap(),
                serde_json::Value::from(m.name())
            );
        }
    }

    #[test]
    fn validation_names_the_field() {
        let mut p = PartParams {
            poisson_ratio: 0.5,
            ..Default::default()
        };
        let e = p.validate("parts[1]").unwrap_err().to_string();
        assert!(e.contains("parts[1]") && e.contains("poisson_ratio"), "{e}");
        p.poisson_ratio = 0.3;
        p.youngs_modulus_pa = -1.0;
        assert!(p
            .validate("x")
            .unwrap_err()
            .to_string()
            .contains("youngs_modulus_pa"));
        p.youngs_modulus_pa = f64::NAN;
        assert!(p.validate("x").is_err());
        p.youngs_modulus_pa = 1e5;
        assert!(p.validate("x").is_ok());
    }

    #[test]
    fn lame_matches_definition() {
        let p = PartParams {
            youngs_modulus_pa: 1e6,
            poisson_ratio: 0.3,
            ..Default::default()
        };
        let (mu, la) = p.lame();
        assert!((mu - 1e6 / 2.6).abs() < 1e-6);
        assert!((la - 0.3e6 / (1.3 * 0.4)).abs() < 1e-6);
    }
}
