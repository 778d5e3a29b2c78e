//! Boundary conditions as the user writes them, and their device form.
//!
//! Grid conditions act on node velocities after gravity, in the order given; particle conditions
//! act on particle velocities before the stress stage. Time windows are `[start, end)` in
//! seconds, compared in f32 at the start of each substep.

use crate::error::{Error, Result};
use crate::kernels::{GridBc, ParticleBc};
use serde::{Deserialize, Serialize};

/// Device kind: bounding-box walls.
pub const BC_BOUNDING_BOX: u32 = 0;
/// Device kind: prescribed velocity on the nodes inside a (moving) cuboid.
pub const BC_CUBOID: u32 = 1;
/// Device kind: half-space surface collider.
pub const BC_SURFACE: u32 = 2;
/// Device kind: per-particle force applied over a window.
pub const PBC_IMPULSE: u32 = 0;
/// Device kind: per-particle velocity override over a window.
pub const PBC_VELOCITY: u32 = 1;

/// How a wall or collider treats the velocity of nodes behind it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Surface {
    /// Zero velocity.
    Sticky,
    /// Bounding box: the velocity component into the wall is removed (separating walls).
    /// Collider: the normal component is removed (PhysGaussian's intended "slip").
    #[default]
    Slip,
    /// Collider only: the normal component is removed when moving into the surface, and the
    /// tangential speed is reduced by `friction x |normal speed|` (Coulomb friction).
    Friction,
}

fn zero3() -> [f64; 3] {
    [0.0; 3]
}
fn three() -> u32 {
    3
}
fn forever() -> f64 {
    f64::INFINITY
}
fn one_step() -> u32 {
    1
}

/// A boundary condition of the project's config (`type = "..."` selects the variant).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum BoundaryCondition {
    /// Walls on the outermost `layers` node layers of each face of the grid.
    BoundingBox {
        /// Node layers per face (PhysGaussian: 3).
        #[serde(default = "three")]
        layers: u32,
        /// `slip` (remove the velocity component into the wall) or `sticky`.
        #[serde(default)]
        surface: Surface,
    },
    /// Nodes strictly inside the box `|x - point| < size` (half extents) get `velocity`; the
    /// box moves with that velocity while active.
    Cuboid {
        /// Centre (m).
        point: [f64; 3],
        /// Half extents (m).
        size: [f64; 3],
        /// Prescribed velocity (m/s); zero clamps.
        #[serde(default = "zero3")]
        velocity: [f64; 3],
        /// Start (s).
        #[serde(default)]
        start_time: f64,
        /// End (s).
        #[serde(default = "forever")]
        end_time: f64,
        /// PhysGaussian's `reset`: outside the window (and until 15 substeps after its end)
        /// zero the velocity of the whole grid.
        #[serde(default)]
        reset: bool,
    },
    /// Half-space collider: nodes with `(x - point) . normal < 0` are treated per `surface`.
    SurfaceCollider {
        /// A point on the plane (m).
        point: [f64; 3],
        /// Outward normal (normalised on load).
        normal: [f64; 3],
        /// Sticky, slip or friction.
        #[serde(default)]
        surface: Surface,
        /// Coulomb friction coefficient (for `friction`).
        #[serde(default)]
        friction: f64,
        /// Start (s).
        #[serde(default)]
        start_time: f64,
        /// End (s).
        #[serde(default = "forever")]
        end_time: f64,
    },
    /// Every particle whose initial position is strictly inside the box gets
    /// `v += force / m dt` in each of `num_dt` substeps from `start_time` (the force acts on
    /// every selected particle; it is not shared).
    ParticleImpulse {
        /// Force per particle (N).
        force: [f64; 3],
        /// Box centre (m).
        point: [f64; 3],
        /// Box half extents (m).
        size: [f64; 3],
        /// Number of substeps.
        #[serde(default = "one_step")]
        num_dt: u32,
        /// Start (s).
        #[serde(default)]
        start_time: f64,
    },
    /// Every particle whose initial position is strictly inside the box has its velocity set to
    /// `velocity` while active (PhysGaussian's `enforce_particle_translation`).
    ParticleVelocity {
        /// Velocity (m/s).
        velocity: [f64; 3],
        /// Box centre (m).
        point: [f64; 3],
        /// Box half extents (m).
        size: [f64; 3],
        /// Start (s).
        #[serde(default)]
        start_time: f64,
        /// End (s).
        #[serde(default = "forever")]
        end_time: f64,
    },
}

fn f3(v: [f64; 3]) -> [f32; 3] {
    v.map(|x| x as f32)
}
fn time32(t: f64) -> f32 {
    if t.is_infinite() {
        f32::MAX
    } else {
        t as f32
    }
}

impl BoundaryCondition {
    /// Checks values against the grid of `n_grid` nodes per axis; `what` names the condition
    /// in errors (e.g. `"c.toml: boundary[2]"`), and each error is an
    /// [`Error::InvalidParameter`] whose `field` is the bare key (`start_time`, `size[1]`).
    ///
    /// Every vector is finite; a box's half extents (`size`) are > 0; a time window has a
    /// finite `start_time` and an `end_time` after it (an empty or NaN window never acts);
    /// `layers` lies in `[1, (n_grid - 1) / 2]` (walls on both faces leave interior nodes);
    /// `num_dt >= 1`; a collider's normal is non-zero and its friction >= 0.
    pub fn validate(&self, what: &str, n_grid: usize) -> Result<()> {
        let bad = |field: &str, value: f64, reason: &str| {
            Err(Error::InvalidParameter {
                what: what.to_string(),
                field: field.to_string(),
                value,
                reason: reason.to_string(),
            })
        };
        let finite = |field: &str, v: &[f64; 3]| -> Result<()> {
            match v.iter().position(|x| !x.is_finite()) {
                Some(a) => bad(&format!("{field}[{a}]"), v[a], "must be finite"),
                None => Ok(()),
            }
        };
        let half = |v: &[f64; 3]| -> Result<()> {
            finite("size", v)?;
            match v.iter().position(|x| *x <= 0.0) {
                Some(a) => bad(
                    &format!("size[{a}]"),
                    v[a],
                    "a half extent must be > 0 (a box with a zero or negative half extent \
                     holds nothing)",
                ),
                None => Ok(()),
            }
        };
        let window = |start: f64, end: Option<f64>| -> Result<()> {
            if !start.is_finite() {
                return bad("start_time", start, "must be finite (s)");
            }
            match end {
                Some(e) if e.is_nan() || e <= start => bad(
                    "end_time",
                    e,
                    &format!("must be > start_time = {start} (the window [start, end) is empty)"),
                ),
                _ => Ok(()),
            }
        };
        match self {
            BoundaryCondition::BoundingBox { layers, .. } => {
                let max = n_grid.saturating_sub(1) / 2;
                if *layers == 0 || *layers as usize > max {
                    return bad(
                        "layers",
                        f64::from(*layers),
                        &format!(
                            "must lie in [1, {max}] (walls on both faces of a grid of n_grid = \
                             {n_grid} nodes must leave interior nodes)"
                        ),
                    );
                }
                Ok(())
            }
            BoundaryCondition::Cuboid {
                point,
                size,
                velocity,
                start_time,
                end_time,
                ..
            } => {
                finite("point", point)?;
                half(size)?;
                finite("velocity", velocity)?;
                window(*start_time, Some(*end_time))
            }
            BoundaryCondition::SurfaceCollider {
                point,
                normal,
                friction,
                start_time,
                end_time,
                ..
            } => {
                finite("point", point)?;
                finite("normal", normal)?;
                if normal.iter().map(|x| x * x).sum::<f64>() < 1e-20 {
                    return bad("normal", 0.0, "must be non-zero");
                }
                if !(friction.is_finite() && *friction >= 0.0) {
                    return bad("friction", *friction, "must be >= 0");
                }
                window(*start_time, Some(*end_time))
            }
            BoundaryCondition::ParticleImpulse {
                force,
                point,
                size,
                num_dt,
                start_time,
            } => {
                finite("force", force)?;
                finite("point", point)?;
                half(size)?;
                if *num_dt == 0 {
                    return bad("num_dt", 0.0, "must be >= 1 (substeps the force acts)");
                }
                window(*start_time, None)
            }
            BoundaryCondition::ParticleVelocity {
                velocity,
                point,
                size,
                start_time,
                end_time,
            } => {
                finite("velocity", velocity)?;
                finite("point", point)?;
                half(size)?;
                window(*start_time, Some(*end_time))
            }
        }
    }

    /// The device form of a grid condition (`None` for particle conditions).
    pub fn grid_bc(&self) -> Option<GridBc> {
        Some(match *self {
            BoundaryCondition::BoundingBox { layers, surface } => GridBc {
                kind: BC_BOUNDING_BOX,
                mode: if surface == Surface::Sticky { 0 } else { 1 },
                layers,
                start: 0.0,
                end: f32::MAX,
                ..Default::default()
            },
            BoundaryCondition::Cuboid {
                point,
                size,
                velocity,
                start_time,
                end_time,
                reset,
            } => GridBc {
                kind: BC_CUBOID,
                layers: reset as u32,
                point: f3(point),
                axis: f3(size),
                velocity: f3(velocity),
                start: time32(start_time),
                end: time32(end_time),
                ..Default::default()
            },
            BoundaryCondition::SurfaceCollider {
                point,
                normal,
                surface,
                friction,
                start_time,
                end_time,
            } => {
                let l = normal.iter().map(|x| x * x).sum::<f64>().sqrt();
                GridBc {
                    kind: BC_SURFACE,
                    mode: match surface {
                        Surface::Sticky => 0,
                        Surface::Slip => 1,
                        Surface::Friction => 2,
                    },
                    friction: friction as f32,
                    point: f3(point),
                    axis: f3(normal.map(|x| x / l)),
                    start: time32(start_time),
                    end: time32(end_time),
                    ..Default::default()
                }
            }
            _ => return None,
        })
    }

    /// The device form of a particle condition (`None` for grid conditions); `dt` converts
    /// `num_dt` into an end time.
    pub fn particle_bc(&self, dt: f64) -> Option<ParticleBc> {
        Some(match *self {
            BoundaryCondition::ParticleImpulse {
                force,
                point,
                size,
                num_dt,
                start_time,
            } => ParticleBc {
                kind: PBC_IMPULSE,
                point: f3(point),
                size: f3(size),
                vector: f3(force),
                start: time32(start_time),
                end: time32(start_time + num_dt as f64 * dt),
                ..Default::default()
            },
            BoundaryCondition::ParticleVelocity {
                velocity,
                point,
                size,
                start_time,
                end_time,
            } => ParticleBc {
                kind: PBC_VELOCITY,
                point: f3(point),
                size: f3(size),
                vector: f3(velocity),
                start: time32(start_time),
                end: time32(end_time),
                ..Default::default()
            },
            _ => return None,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A condition that could never act (a NaN or infinite start, an empty window, a box with
    /// a zero or negative half extent, no substeps) or that would index past the grid (walls
    /// thicker than half of it) is an error naming the field and the limit.
    #[test]
    fn conditions_that_never_act_or_overrun_the_grid_are_refused() {
        let cuboid = |start_time: f64, end_time: f64, size: [f64; 3]| BoundaryCondition::Cuboid {
            point: [0.5; 3],
            size,
            velocity: [0.0; 3],
            start_time,
            end_time,
            reset: false,
        };
        let err = |b: BoundaryCondition| b.validate("c.toml", 32).unwrap_err().to_string();
        let e = err(cuboid(f64::NAN, f64::INFINITY, [0.1; 3]));
        assert!(
            e.contains("c.toml") && e.contains("start_time = NaN") && e.contains("finite"),
            "{e}"
        );
        let e = err(cuboid(1.0, 0.5, [0.1; 3]));
        assert!(
            e.contains("end_time = 0.5") && e.contains("> start_time"),
            "{e}"
        );
        let e = err(cuboid(0.0, f64::NAN, [0.1; 3]));
        assert!(e.contains("end_time = NaN"), "{e}");
        let e = err(cuboid(0.0, 1.0, [0.1, -0.2, 0.1]));
        assert!(
            e.contains("size[1] = -0.2") && e.contains("half extent"),
            "{e}"
        );
        let e = err(BoundaryCondition::ParticleVelocity {
            velocity: [0.0; 3],
            point: [0.5; 3],
            size: [0.0, 0.1, 0.1],
            start_time: 0.0,
            end_time: 1.0,
        });
        assert!(e.contains("size[0] = 0"), "{e}");
        let e = err(BoundaryCondition::ParticleImpulse {
            force: [0.0; 3],
            point: [0.5; 3],
            size: [0.1; 3],
            num_dt: 0,
            start_time: 0.0,
        });
        assert!(e.contains("num_dt = 0"), "{e}");
        for layers in [0, 16, u32::MAX] {
            let e = err(BoundaryCondition::BoundingBox {
                layers,
                surface: Surface::Slip,
            });
            assert!(
                e.contains(&format!("layers = {layers}")) && e.contains("[1, 15]"),
                "{e}"
            );
        }
        BoundaryCondition::BoundingBox {
            layers: 15,
            surface: Surface::Slip,
        }
        .validate("c.toml", 32)
        .unwrap();
        cuboid(0.0, f64::INFINITY, [0.1; 3])
            .validate("c.toml", 32)
            .unwrap();
    }
}
