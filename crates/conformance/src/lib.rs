//! # r4d-conformance: the backend conformance suite
//!
//! Any backend of resonance4d ([`Compute`]: a simulation and a renderer) against the CPU
//! backend at the backend's own precision, with the bounds the project's own GPU engines are
//! held to:
//!
//! | check | what | bound |
//! |---|---|---|
//! | `forward.x` | positions at every frame, max abs difference / domain size | 1e-4 |
//! | `forward.F` | deformation gradients at every frame, max abs difference / max abs F | 1e-4 |
//! | `adjoint.<param>` | gradient of a fixed position loss per part (E, nu, density) | 1e-3 relative |
//! | `adjoint.x0`, `adjoint.F0` | adjoint of the initial state | 1e-3 relative L2 |
//! | `render.mean`, `render.max` | colour and alpha, mean and max abs difference | 1e-6, 1e-3 |
//! | `render_vjp.<array>` | every gradient array of the render VJP | 5e-3 relative L2 |
//! | `linked.render.*`, `linked.vjp.{x,F}` | a backend whose frames stay on its device ([`Compute::frames_on_device`]): a simulated frame's own buffers through the device link and the renderer, and the particle gradients back, against the host link and the CPU renderer | 1e-6, 1e-3; 5e-3 relative L2 |
//!
//! The scenes ([`scenes`]): two jelly parts under gravity with a bounding box, a friction
//! collider, a clamp and an impulse (3 frames of 20 substeps, initial velocities), and 240
//! Gaussians of SH degree 1 seen with and without a deformation that moves and shears them.
//! The CPU f32 backend is itself checked against the f64 reference (finite differences) by the
//! project's tests.
//!
//! ```
//! use r4d_conformance::{run, Tolerances};
//! use r4d_optim::compute::ReferenceCompute;
//! // The single-threaded reference kernels against the parallel CPU backend.
//! let report = run(&ReferenceCompute, &Tolerances::default()).unwrap();
//! assert!(report.checks.iter().all(|c| c.error <= c.bound));
//! ```

mod linked;
pub mod scenes;
mod simulation;
mod splat;

use r4d_optim::compute::Compute;
use r4d_optim::FitError;

/// The bounds of the suite (the defaults are those in the table above).
#[derive(Clone, Debug)]
pub struct Tolerances {
    /// Positions: max abs difference / domain size.
    pub positions: f64,
    /// Deformation gradients: max abs difference / max abs F.
    pub deformation: f64,
    /// Parameter gradients: relative difference.
    pub gradient: f64,
    /// Initial-state adjoint: relative L2 difference.
    pub initial_adjoint: f64,
    /// Images: mean abs difference.
    pub image_mean: f64,
    /// Images: max abs difference.
    pub image_max: f64,
    /// Render VJP arrays: relative L2 difference.
    pub render_vjp: f64,
}

impl Default for Tolerances {
    fn default() -> Self {
        Tolerances {
            positions: 1e-4,
            deformation: 1e-4,
            gradient: 1e-3,
            initial_adjoint: 1e-3,
            image_mean: 1e-6,
            image_max: 1e-3,
            render_vjp: 5e-3,
        }
    }
}

/// One measured difference and its bound.
#[derive(Clone, Debug, PartialEq)]
pub struct Check {
    /// What was compared (`forward.x`, `adjoint.E[1]`, `render_vjp.means`, ...).
    pub name: String,
    /// The difference measured.
    pub error: f64,
    /// Its bound.
    pub bound: f64,
}

/// Every check of a passing run.
#[derive(Clone, Debug)]
pub struct Report {
    /// The backend's name.
    pub backend: String,
    /// The precision its simulation ran in (`"f32"`, `"f64"`).
    pub precision: String,
    /// The checks, in the order they ran.
    pub checks: Vec<Check>,
}

impl std::fmt::Display for Report {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "conformance of {} ({}): {} checks passed",
            self.backend,
            self.precision,
            self.checks.len()
        )?;
        for c in &self.checks {
            writeln!(f, "  {:<34} {:.2e} <= {:.0e}", c.name, c.error, c.bound)?;
        }
        Ok(())
    }
}

/// Why a backend failed the suite.
#[derive(Debug, thiserror::Error)]
pub enum Failure {
    /// The backend (or the CPU reference) returned an error.
    #[error("conformance of {backend}: {source}")]
    Backend {
        /// The backend's name.
        backend: String,
        /// Its error.
        #[source]
        source: FitError,
    },
    /// A difference beyond its bound.
    #[error("conformance of {backend}: {} differs by {:.3e} (bound {:.0e})", .check.name, .check.error, .check.bound)]
    Mismatch {
        /// The backend's name.
        backend: String,
        /// The failed check.
        check: Check,
    },
    /// The reference scene did not do what the check needs (it did not move, a gradient is
    /// zero): the suite itself is broken.
    #[error("conformance of {backend}: {message}")]
    Scene {
        /// The backend's name.
        backend: String,
        /// What is wrong.
        message: String,
    },
}

/// Collects checks, failing at the first beyond its bound.
pub(crate) struct Checks {
    backend: String,
    checks: Vec<Check>,
}

impl Checks {
    pub(crate) fn push(&mut self, name: String, error: f64, bound: f64) -> Result<(), Failure> {
        let check = Check { name, error, bound };
        if error.is_nan() || error > bound {
            return Err(Failure::Mismatch {
                backend: self.backend.clone(),
                check,
            });
        }
        self.checks.push(check);
        Ok(())
    }

    pub(crate) fn backend_error(&self, source: FitError) -> Failure {
        Failure::Backend {
            backend: self.backend.clone(),
            source,
        }
    }

    pub(crate) fn scene(&self, message: String) -> Failure {
        Failure::Scene {
            backend: self.backend.clone(),
            message,
        }
    }
}

/// Runs the whole suite on `compute`: its simulation forward and adjoint, its renderer and
/// render VJP against the CPU backend.
pub fn run(compute: &dyn Compute, tol: &Tolerances) -> Result<Report, Failure> {
    let mut checks = Checks {
        backend: compute.name().to_string(),
        checks: Vec::new(),
    };
    let precision = simulation::run(compute, tol, &mut checks)?;
    splat::run(compute, tol, &mut checks)?;
    if compute.frames_on_device() {
        linked::run(compute, tol, &mut checks)?;
    }
    Ok(Report {
        backend: checks.backend,
        precision,
        checks: checks.checks,
    })
}

/// Relative difference of two numbers (0 when both are 0).
pub(crate) fn rel(a: f64, b: f64) -> f64 {
    let s = a.abs().max(b.abs());
    if s == 0.0 {
        0.0
    } else {
        (a - b).abs() / s
    }
}

/// Relative L2 difference of `got` from `want`.
pub(crate) fn rel_l2(got: &[f64], want: &[f64]) -> f64 {
    if got.len() != want.len() {
        return f64::INFINITY;
    }
    let d: f64 = got.iter().zip(want).map(|(a, b)| (a - b) * (a - b)).sum();
    let n: f64 = want.iter().map(|b| b * b).sum();
    (d / n.max(1e-300)).sqrt()
}
