//! The flat vector of free parameters a fit optimises, and its mapping to parts.
//!
//! A fit sees `theta`, a vector of positive physical values with bounds. Each entry is one
//! [`ParamKind`] of one parameter slot (a part, or a particle for the per-particle ablation)
//! or, at object granularity, one kind shared by every part. [`ParamSpace`] maps `theta` onto
//! the parts' [`PartParams`] and the simulator's per-slot gradients back onto `dL/dtheta`.

use crate::ParamKind;
use r4d_mpm::adjoint::host::PhysParams;
use r4d_mpm::{Material, PartParams};
use serde::{Deserialize, Serialize};

/// Whether parts share their parameters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Granularity {
    /// One value per part (default).
    #[default]
    Part,
    /// One value for the whole object, shared by all parts.
    Object,
    /// One value per particle (the paper's ablation).
    Particle,
}

/// The value of `k` in `p`.
pub fn get(p: &PartParams, k: ParamKind) -> f64 {
    match k {
        ParamKind::YoungsModulus => p.youngs_modulus_pa,
        ParamKind::PoissonRatio => p.poisson_ratio,
        ParamKind::YieldStress => p.yield_stress_pa,
        ParamKind::PlasticViscosity => p.plastic_viscosity_pa_s,
        ParamKind::FrictionAngle => p.friction_angle_deg,
        ParamKind::Density => p.density_kg_m3,
        ParamKind::Hardening => p.xi,
        ParamKind::Softening => p.softening,
    }
}

/// Sets `k` in `p` to `v`.
pub fn set(p: &mut PartParams, k: ParamKind, v: f64) {
    match k {
        ParamKind::YoungsModulus => p.youngs_modulus_pa = v,
        ParamKind::PoissonRatio => p.poisson_ratio = v,
        ParamKind::YieldStress => p.yield_stress_pa = v,
        ParamKind::PlasticViscosity => p.plastic_viscosity_pa_s = v,
        ParamKind::FrictionAngle => p.friction_angle_deg = v,
        ParamKind::Density => p.density_kg_m3 = v,
        ParamKind::Hardening => p.xi = v,
        ParamKind::Softening => p.softening = v,
    }
}

/// The gradient entry of `k` in a simulator gradient.
pub fn grad_of(g: &PhysParams<f64>, k: ParamKind) -> f64 {
    match k {
        ParamKind::YoungsModulus => g.youngs_modulus,
        ParamKind::PoissonRatio => g.poisson_ratio,
        ParamKind::YieldStress => g.yield_stress,
        ParamKind::PlasticViscosity => g.plastic_viscosity,
        ParamKind::FrictionAngle => g.friction_angle_deg,
        ParamKind::Density => g.density,
        ParamKind::Hardening => g.hardening,
        ParamKind::Softening => g.softening,
    }
}

/// Whether part `p`'s model reads `k`: `E`, `nu` and density for all; yield stress for metal,
/// foam and plasticine; plastic viscosity for foam and fluid; friction angle for sand; the
/// hardening coefficient for a metal whose `hardening` is on; softening for plasticine.
pub fn reads(p: &PartParams, k: ParamKind) -> bool {
    use Material as M;
    match k {
        ParamKind::YoungsModulus | ParamKind::PoissonRatio | ParamKind::Density => true,
        ParamKind::YieldStress => matches!(
            p.material,
            M::Metal | M::Foam | M::Plasticine | M::NonNewtonian
        ),
        ParamKind::PlasticViscosity => {
            matches!(p.material, M::Foam | M::Fluid | M::NonNewtonian)
        }
        ParamKind::FrictionAngle => p.material == M::Sand,
        ParamKind::Hardening => p.material == M::Metal && p.hardening,
        ParamKind::Softening => p.material == M::Plasticine,
    }
}

/// The parameters part `p`'s model reads ([`reads`]), free by default; the hardening and
/// softening coefficients only when set (a positive value: a log-domain fit cannot start
/// from 0).
pub fn default_free(p: &PartParams) -> Vec<ParamKind> {
    ParamKind::ALL
        .into_iter()
        .filter(|&k| reads(p, k))
        .filter(|&k| !matches!(k, ParamKind::Hardening | ParamKind::Softening) || get(p, k) > 0.0)
        .collect()
}

/// Checks free kinds against the parts' models: a kind a part's model does not read
/// ([`reads`]) would receive a zero gradient and be reported as if fitted, so it is refused
/// (at object granularity when no part reads it), naming the part, its material and what it
/// reads.
pub fn check_free(
    parts: &[PartParams],
    free: &[Vec<ParamKind>],
    granularity: Granularity,
) -> Result<(), String> {
    let names = |p: &PartParams| {
        ParamKind::ALL
            .into_iter()
            .filter(|&k| reads(p, k))
            .map(|k| k.name())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let hint = |p: &PartParams, k: ParamKind| {
        if k == ParamKind::Hardening && p.material == Material::Metal {
            " (set `hardening = true` on the part to use metal hardening)"
        } else {
            ""
        }
    };
    if granularity == Granularity::Object {
        for k in free.iter().flatten() {
            if !parts.iter().any(|p| reads(p, *k)) {
                return Err(format!(
                    "free parameter {}: no part's model reads it",
                    k.name()
                ));
            }
        }
        return Ok(());
    }
    for (i, (p, kinds)) in parts.iter().zip(free).enumerate() {
        if let Some(&k) = kinds.iter().find(|&&k| !reads(p, k)) {
            return Err(format!(
                "free parameter {} of part {i}: the {} model does not read it (it reads: {}){}",
                k.name(),
                p.material.name(),
                names(p),
                hint(p, k)
            ));
        }
    }
    Ok(())
}

/// One free parameter.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FreeParam {
    /// Parameter slot (part or particle); `None`: shared by every slot.
    pub slot: Option<usize>,
    /// Part the slot belongs to (for names and reports); `None` for shared parameters.
    pub part: Option<usize>,
    /// The kind.
    pub kind: ParamKind,
    /// Bounds `[lo, hi]`, positive.
    pub bounds: (f64, f64),
}

impl FreeParam {
    /// A readable name, e.g. `part1.E` or `object.density`.
    pub fn name(&self) -> String {
        match (self.slot, self.part) {
            (None, _) => format!("object.{}", self.kind.name()),
            (Some(s), Some(p)) if s != p => format!("part{p}.particle{s}.{}", self.kind.name()),
            (Some(s), _) => format!("part{s}.{}", self.kind.name()),
        }
    }
}

/// The free parameters of a fit, in a fixed order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParamSpace {
    /// Granularity the slots were built for.
    pub granularity: Granularity,
    /// The entries of `theta`.
    pub entries: Vec<FreeParam>,
}

impl ParamSpace {
    /// Builds the space: `free[p]` lists part `p`'s free kinds and `bounds(p, kind)` their
    /// bounds; `slot_part[s]` is the part of slot `s` (the identity for part granularity,
    /// every particle's part for particle granularity). At object granularity the free kinds
    /// are the union over parts, each shared by all slots.
    pub fn new(
        granularity: Granularity,
        free: &[Vec<ParamKind>],
        slot_part: &[u32],
        bounds: impl Fn(Option<usize>, ParamKind) -> (f64, f64),
    ) -> ParamSpace {
        let entries = match granularity {
            Granularity::Object => {
                let kinds: Vec<ParamKind> = ParamKind::ALL
                    .into_iter()
                    .filter(|k| free.iter().any(|f| f.contains(k)))
                    .collect();
                kinds
                    .into_iter()
                    .map(|kind| FreeParam {
                        slot: None,
                        part: None,
                        kind,
                        bounds: bounds(None, kind),
                    })
                    .collect()
            }
            Granularity::Part | Granularity::Particle => slot_part
                .iter()
                .enumerate()
                .flat_map(|(s, &p)| {
                    let p = p as usize;
                    free[p].iter().map(move |&kind| (s, p, kind))
                })
                .map(|(s, p, kind)| FreeParam {
                    slot: Some(s),
                    part: Some(p),
                    kind,
                    bounds: bounds(Some(p), kind),
                })
                .collect(),
        };
        ParamSpace {
            granularity,
            entries,
        }
    }

    /// Number of free parameters.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// True when nothing is free.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Names of the entries.
    pub fn names(&self) -> Vec<String> {
        self.entries.iter().map(FreeParam::name).collect()
    }

    /// Bounds of the entries.
    pub fn bounds(&self) -> Vec<(f64, f64)> {
        self.entries.iter().map(|e| e.bounds).collect()
    }

    /// `theta` read from per-slot parameters (a shared entry reads slot 0).
    pub fn values(&self, slots: &[PartParams]) -> Vec<f64> {
        self.entries
            .iter()
            .map(|e| get(&slots[e.slot.unwrap_or(0)], e.kind))
            .collect()
    }

    /// Writes `theta` into per-slot parameters.
    pub fn apply(&self, slots: &mut [PartParams], theta: &[f64]) {
        for (e, &v) in self.entries.iter().zip(theta) {
            match e.slot {
                Some(s) => set(&mut slots[s], e.kind, v),
                None => slots.iter_mut().for_each(|p| set(p, e.kind, v)),
            }
        }
    }

    /// `dL/dtheta` from the simulator's per-slot gradient (shared entries sum over slots).
    pub fn gather(&self, grad: &[PhysParams<f64>]) -> Vec<f64> {
        self.entries
            .iter()
            .map(|e| match e.slot {
                Some(s) => grad_of(&grad[s], e.kind),
                None => grad.iter().map(|g| grad_of(g, e.kind)).sum(),
            })
            .collect()
    }
}

/// Per-part parameters from per-slot ones (per-particle slots: geometric means per part;
/// `slot_parts` gives each slot's part, `base` the parts' values for everything not free).
pub fn part_summary(
    base: &[PartParams],
    slot_parts: &[u32],
    slots: &[PartParams],
) -> Vec<PartParams> {
    if slots.len() == base.len() && slot_parts.iter().enumerate().all(|(i, &p)| p as usize == i) {
        return slots.to_vec();
    }
    (0..base.len())
        .map(|i| {
            let mine: Vec<&PartParams> = slots
                .iter()
                .zip(slot_parts)
                .filter(|(_, &p)| p as usize == i)
                .map(|(v, _)| v)
                .collect();
            let mut out = base[i];
            if !mine.is_empty() {
                for k in ParamKind::ALL {
                    let m = mine.iter().map(|v| get(v, k).ln()).sum::<f64>() / mine.len() as f64;
                    set(&mut out, k, m.exp());
                }
            }
            out
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn part_and_object_spaces_round_trip() {
        let mut parts = vec![PartParams::default(), PartParams::default()];
        parts[1].material = Material::Sand;
        let free: Vec<Vec<ParamKind>> = parts.iter().map(default_free).collect();
        let sp = ParamSpace::new(Granularity::Part, &free, &[0, 1], |_, k| k.default_bounds());
        assert_eq!(sp.len(), 3 + 4);
        assert_eq!(sp.names()[6], "part1.density");
        let theta: Vec<f64> = (0..sp.len()).map(|i| 1.0 + i as f64).collect();
        sp.apply(&mut parts, &theta);
        assert_eq!(sp.values(&parts), theta);
        let ob = ParamSpace::new(Granularity::Object, &free, &[0, 1], |_, k| {
            k.default_bounds()
        });
        assert_eq!(ob.len(), 4);
        let g = vec![
            PhysParams {
                density: 2.0,
                ..Default::default()
            },
            PhysParams {
                density: 3.0,
                ..Default::default()
            },
        ];
        assert_eq!(*ob.gather(&g).last().unwrap(), 5.0);
    }

    /// Hardening and softening are free only where the model reads them, and a kind a part's
    /// model does not read is refused with the part, its material and what it reads.
    #[test]
    fn free_kinds_follow_the_models() {
        let metal = PartParams::new(Material::Metal);
        assert!(!default_free(&metal).contains(&ParamKind::Hardening));
        let hardened = PartParams {
            hardening: true,
            xi: 0.4,
            ..metal
        };
        assert!(default_free(&hardened).contains(&ParamKind::Hardening));
        let plasticine = PartParams::new(Material::Plasticine);
        assert!(default_free(&plasticine).contains(&ParamKind::Softening));
        assert!(!default_free(&PartParams::new(Material::Jelly)).contains(&ParamKind::Softening));
        let free = vec![vec![ParamKind::YoungsModulus, ParamKind::Hardening]];
        let e = check_free(&[metal], &free, Granularity::Part).unwrap_err();
        assert!(
            e.contains("hardening") && e.contains("part 0") && e.contains("hardening = true"),
            "{e}"
        );
        check_free(&[hardened], &free, Granularity::Part).unwrap();
        let e = check_free(
            &[PartParams::default()],
            &[vec![ParamKind::FrictionAngle]],
            Granularity::Part,
        )
        .unwrap_err();
        assert!(
            e.contains("jelly model") && e.contains("E, nu, density"),
            "{e}"
        );
        // Object granularity: refused only when no part reads it.
        let two = [PartParams::default(), PartParams::new(Material::Sand)];
        let free = vec![vec![ParamKind::FrictionAngle]; 2];
        check_free(&two, &free, Granularity::Object).unwrap();
        assert!(check_free(&two, &free, Granularity::Part).is_err());
        // The values round-trip through get/set and the gradient entries.
        let mut p = plasticine;
        set(&mut p, ParamKind::Softening, 123.0);
        assert_eq!(get(&p, ParamKind::Softening), 123.0);
        let g = PhysParams {
            softening: 2.0,
            hardening: 3.0,
            ..Default::default()
        };
        assert_eq!(grad_of(&g, ParamKind::Softening), 2.0);
        assert_eq!(grad_of(&g, ParamKind::Hardening), 3.0);
    }
}
