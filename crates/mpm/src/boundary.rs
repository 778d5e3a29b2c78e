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
    /// Checks values; `what` names the condition in errors (e.g. `"boundary[2]"`).
    pub fn validate(&self, what: &str) -> Result<()> {
        let bad = |field: &str, msg: &str| Err(Error::config(what, format!("{field}: {msg}")));
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        match self {
            BoundaryCondition::BoundingBox { layers, .. } if *layers == 0 => {
                bad("layers", "must be >= 1")
            }
            BoundaryCondition::Cuboid {
                point,
                size,
                velocity,
                ..
            } => {
                if !finite(point) || !finite(size) || !finite(velocity) {
                    return bad("point/size/velocity", "must be finite");
                }
                Ok(())
            }
            BoundaryCondition::SurfaceCollider {
                point,
                normal,
                friction,
                ..
            } => {
                if !finite(point) || !finite(normal) {
                    return bad("point/normal", "must be finite");
                }
                if normal.iter().map(|x| x * x).sum::<f64>() < 1e-20 {
                    return bad("normal", "must be non-zero");
                }
                if !(friction.is_finite() && *friction >= 0.0) {
                    return bad("friction", "must be >= 0");
                }
                Ok(())
            }
            BoundaryCondition::ParticleImpulse {
                force, point, size, ..
            } => {
                if !finite(force) || !finite(point) || !finite(size) {
                    return bad("force/point/size", "must be finite");
                }
                Ok(())
            }
            BoundaryCondition::ParticleVelocity {
                velocity,
                point,
                size,
                ..
            } => {
                if !finite(velocity) || !finite(point) || !finite(size) {
                    return bad("velocity/point/size", "must be finite");
                }
                Ok(())
            }
            _ => Ok(()),
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
