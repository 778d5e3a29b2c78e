//! Initial particles: built-in shapes sampled on a lattice, or a PLY file.

use crate::error::{Error, Result};
use crate::ply::read_ply;
use crate::transfer::in_domain;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Host copy of the initial particles.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ParticleSet {
    /// Initial positions (m).
    pub x: Vec<[f32; 3]>,
    /// Initial volumes (m^3).
    pub volume: Vec<f32>,
    /// Part index per particle.
    pub part: Vec<u32>,
}

fn two() -> u32 {
    2
}
fn z_axis() -> usize {
    2
}

/// A built-in shape filled with a regular lattice of `per_cell` particles per cell per axis
/// (at offsets `(q + 0.5) / per_cell` of a cell, so 2 gives 0.25 dx and 0.75 dx), each of volume
/// `(dx / per_cell)^3`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Shape {
    /// Axis-aligned box `[min, max]`.
    Box {
        /// Lower corner (m).
        min: [f64; 3],
        /// Upper corner (m).
        max: [f64; 3],
        /// Part index.
        #[serde(default)]
        part: u32,
        /// Particles per cell per axis.
        #[serde(default = "two")]
        per_cell: u32,
    },
    /// Cylinder along an axis (0 = x, 1 = y, 2 = z) from `base` over `length`.
    Cylinder {
        /// Centre of the base disc (m).
        base: [f64; 3],
        /// Axis index.
        #[serde(default = "z_axis")]
        axis: usize,
        /// Radius (m).
        radius: f64,
        /// Length along the axis (m).
        length: f64,
        /// Part index.
        #[serde(default)]
        part: u32,
        /// Particles per cell per axis.
        #[serde(default = "two")]
        per_cell: u32,
    },
    /// A beam along x: `[origin, origin + (length, width, thickness)]`, for cantilevers.
    Beam {
        /// Lower corner (m).
        origin: [f64; 3],
        /// Extent along x (m).
        length: f64,
        /// Extent along y (m).
        width: f64,
        /// Extent along z (m).
        thickness: f64,
        /// Part index.
        #[serde(default)]
        part: u32,
        /// Particles per cell per axis.
        #[serde(default = "two")]
        per_cell: u32,
    },
}

impl Shape {
    fn part(&self) -> u32 {
        match self {
            Shape::Box { part, .. } | Shape::Cylinder { part, .. } | Shape::Beam { part, .. } => {
                *part
            }
        }
    }
    fn per_cell(&self) -> u32 {
        match self {
            Shape::Box { per_cell, .. }
            | Shape::Cylinder { per_cell, .. }
            | Shape::Beam { per_cell, .. } => *per_cell,
        }
    }
    /// Bounding box of the shape.
    fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        match *self {
            Shape::Box { min, max, .. } => (min, max),
            Shape::Beam {
                origin,
                length,
                width,
                thickness,
                ..
            } => (
                origin,
                [origin[0] + length, origin[1] + width, origin[2] + thickness],
            ),
            Shape::Cylinder {
                base,
                axis,
                radius,
                length,
                ..
            } => {
                let mut lo = base.map(|b| b - radius);
                let mut hi = base.map(|b| b + radius);
                match (lo.get_mut(axis), hi.get_mut(axis)) {
                    (Some(l), Some(h)) => {
                        *l = base[axis];
                        *h = base[axis] + length;
                    }
                    // No such axis ([`Shape::validate`] refuses it): an empty box.
                    _ => hi = lo,
                }
                (lo, hi)
            }
        }
    }
    fn contains(&self, p: [f64; 3]) -> bool {
        let (lo, hi) = self.bounds();
        let in_box = (0..3).all(|a| p[a] >= lo[a] && p[a] < hi[a]);
        match *self {
            Shape::Cylinder {
                base, axis, radius, ..
            } => {
                let r2: f64 = (0..3)
                    .filter(|&a| a != axis)
                    .map(|a| (p[a] - base[a]).powi(2))
                    .sum();
                in_box && r2 < radius * radius
            }
            _ => in_box,
        }
    }
    /// Checks the shape; `num_parts` bounds the part index.
    pub fn validate(&self, what: &str, num_parts: usize) -> Result<()> {
        // The axis first: the extents below are computed along it.
        if let Shape::Cylinder { axis, .. } = self {
            if *axis > 2 {
                return Err(Error::config(
                    what,
                    format!("axis = {axis}: must be 0 (x), 1 (y) or 2 (z)"),
                ));
            }
        }
        let (lo, hi) = self.bounds();
        if !(lo.iter().chain(&hi).all(|x| x.is_finite()) && (0..3).all(|a| hi[a] > lo[a])) {
            return Err(Error::config(
                what,
                "shape extents must be finite and positive",
            ));
        }
        if self.part() as usize >= num_parts {
            return Err(Error::config(
                what,
                format!(
                    "part = {} but only {num_parts} part(s) are defined",
                    self.part()
                ),
            ));
        }
        if !(1..=8).contains(&self.per_cell()) {
            return Err(Error::config(what, "per_cell must lie in [1, 8]"));
        }
        Ok(())
    }

    /// The lattice indices `m` (points at `(m + 0.5) h`, `h = dx / per_cell`) of the shape's
    /// bounding box per axis, for grid spacing `dx`; for q per cell the points are the cell
    /// offsets `(k + 0.5) / q dx`.
    fn lattice(&self, dx: f64) -> [std::ops::Range<i64>; 3] {
        let (lo, hi) = self.bounds();
        let h = dx / self.per_cell() as f64;
        std::array::from_fn(|a| {
            let m0 = (lo[a] / h - 0.5).ceil() as i64;
            let m1 = (hi[a] / h - 0.5).ceil() as i64; // exclusive
            m0..m1
        })
    }

    /// Checks, before sampling, that the shape's lattice lies in the grid's interior
    /// (`[0.5 dx, (n_grid - 1.5) dx)` on every axis, where a particle's stencil is on the grid)
    /// and returns the number of lattice points of its bounding box: an upper bound of the
    /// particles [`Shape::sample`] adds, computed without sampling. `what` names the shape.
    pub fn check_in_grid(&self, what: &str, dx: f64, n_grid: usize) -> Result<u64> {
        let h = dx / self.per_cell() as f64;
        let ranges = self.lattice(dx);
        if ranges.iter().any(|r| r.is_empty()) {
            return Ok(0);
        }
        let (lo, hi) = (0.5 * dx, (n_grid as f64 - 1.5) * dx);
        for (a, r) in ranges.iter().enumerate() {
            let first = (r.start as f64 + 0.5) * h;
            let last = (r.end as f64 - 0.5) * h;
            if first < lo || last >= hi {
                return Err(Error::config(
                    what,
                    format!(
                        "the shape reaches {} = {} m, outside the grid interior [{lo}, {hi}) m \
                         (grid_lim = {}, n_grid = {n_grid})",
                        ["x", "y", "z"][a],
                        if first < lo { first } else { last },
                        dx * n_grid as f64
                    ),
                ));
            }
        }
        Ok(ranges
            .iter()
            .map(|r| r.end.saturating_sub(r.start) as u64)
            .fold(1u64, u64::saturating_mul))
    }

    /// Appends the lattice points of the shape for grid spacing `dx`. A shape that
    /// [`Shape::validate`] refuses (a cylinder axis other than 0, 1 or 2) adds none.
    pub fn sample(&self, dx: f64, out: &mut ParticleSet) {
        let h = dx / self.per_cell() as f64;
        let vol = (h * h * h) as f32;
        let [r0, r1, r2] = self.lattice(dx);
        for i in r0 {
            for j in r1.clone() {
                for k in r2.clone() {
                    let p = [
                        (i as f64 + 0.5) * h,
                        (j as f64 + 0.5) * h,
                        (k as f64 + 0.5) * h,
                    ];
                    if self.contains(p) {
                        out.x.push(p.map(|c| c as f32));
                        out.volume.push(vol);
                        out.part.push(self.part());
                    }
                }
            }
        }
    }
}

impl ParticleSet {
    /// Samples all shapes.
    pub fn from_shapes(shapes: &[Shape], dx: f64) -> ParticleSet {
        let mut out = ParticleSet::default();
        for s in shapes {
            s.sample(dx, &mut out);
        }
        out
    }

    /// Reads particles from a PLY file with float `x, y, z` and optional `volume` and `part`
    /// properties. Without `volume`, each particle gets PhysGaussian's estimate `dx^3 / (number
    /// of particles in its grid cell)`.
    pub fn from_ply(path: &Path, dx: f64) -> Result<ParticleSet> {
        let file = path.display().to_string();
        let ply = read_ply(path)?;
        let col = |n: &str| {
            ply.get(n).ok_or_else(|| Error::Ply {
                file: file.clone(),
                message: format!("missing vertex property '{n}'"),
            })
        };
        let (xs, ys, zs) = (col("x")?, col("y")?, col("z")?);
        let x: Vec<[f32; 3]> = (0..ply.count).map(|i| [xs[i], ys[i], zs[i]]).collect();
        let part = match ply.get("part") {
            Some(p) => p
                .iter()
                .enumerate()
                .map(|(i, &v)| {
                    if v >= 0.0 && v.fract() == 0.0 {
                        Ok(v as u32)
                    } else {
                        Err(Error::Scene {
                            what: file.clone(),
                            message: format!(
                                "particle {i}: part = {v} is not a non-negative integer"
                            ),
                        })
                    }
                })
                .collect::<Result<Vec<_>>>()?,
            None => vec![0; ply.count],
        };
        let volume = match ply.get("volume") {
            Some(v) => v.to_vec(),
            None => cell_volumes(&x, dx),
        };
        Ok(ParticleSet { x, volume, part })
    }

    /// Number of particles.
    pub fn len(&self) -> usize {
        self.x.len()
    }
    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Checks the particles against the grid and the parts; `what` names the source.
    pub fn validate(&self, what: &str, dx: f64, n_grid: usize, num_parts: usize) -> Result<()> {
        let err = |m: String| Error::Scene {
            what: what.to_string(),
            message: m,
        };
        if self.is_empty() {
            return Err(err("no particles".into()));
        }
        let inv_dx = (1.0 / dx) as f32;
        for (i, p) in self.x.iter().enumerate() {
            if !p.iter().all(|c| c.is_finite()) {
                return Err(err(format!("particle {i}: position {p:?} is not finite")));
            }
            if !in_domain(*p, inv_dx, n_grid) {
                return Err(err(format!(
                    "particle {i} at {p:?} lies outside the grid interior [{}, {}) m of every axis (grid_lim = {}, n_grid = {n_grid})",
                    0.5 * dx,
                    (n_grid as f64 - 1.5) * dx,
                    dx * n_grid as f64
                )));
            }
        }
        for (i, v) in self.volume.iter().enumerate() {
            if !(v.is_finite() && *v > 0.0) {
                return Err(err(format!("particle {i}: volume {v} must be > 0")));
            }
        }
        for (i, p) in self.part.iter().enumerate() {
            if *p as usize >= num_parts {
                return Err(err(format!(
                    "particle {i}: part {p} but only {num_parts} part(s) are defined"
                )));
            }
        }
        Ok(())
    }
}

/// PhysGaussian's particle volume estimate: `dx^3 / (particles in the cell floor(x / dx))`.
pub fn cell_volumes(x: &[[f32; 3]], dx: f64) -> Vec<f32> {
    use std::collections::HashMap;
    let key = |p: &[f32; 3]| p.map(|c| (c as f64 / dx).floor() as i64);
    let mut counts: HashMap<[i64; 3], u32> = HashMap::new();
    for p in x {
        *counts.entry(key(p)).or_default() += 1;
    }
    x.iter()
        .map(|p| (dx * dx * dx / counts[&key(p)] as f64) as f32)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_lattice_matches_cell_offsets() {
        let dx = 1.0 / 32.0;
        let s = Shape::Box {
            min: [0.4375, 0.4375, 0.375],
            max: [0.59375, 0.59375, 0.53125],
            part: 0,
            per_cell: 2,
        };
        let p = ParticleSet::from_shapes(&[s], dx);
        assert_eq!(p.len(), 1000);
        assert!((p.x[0][0] as f64 - (0.4375 + 0.25 * dx)).abs() < 1e-7);
        assert!((p.volume[0] as f64 - (dx / 2.0).powi(3)).abs() < 1e-12);
    }

    #[test]
    fn a_cylinder_axis_outside_0_to_2_is_an_error_not_a_panic() {
        let s = Shape::Cylinder {
            base: [0.5; 3],
            axis: 5,
            radius: 0.1,
            length: 0.2,
            part: 0,
            per_cell: 2,
        };
        let e = s.validate("c.toml: shapes[0]", 1).unwrap_err().to_string();
        assert!(e.contains("shapes[0]") && e.contains("axis = 5"), "{e}");
        assert!(ParticleSet::from_shapes(&[s], 1.0 / 32.0).is_empty());
    }
}
