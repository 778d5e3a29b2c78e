//! Errors of the `r4d-mpm` crate.
//!
//! Everything that comes from outside (files, configs, parameter values) gets a typed error that
//! names the file and field; a simulation that blows up names the frame and substep.

use std::path::PathBuf;

/// Result with the crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Errors of the simulator and its inputs.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A parameter value is out of its valid range.
    #[error("{what}: invalid {field} = {value}: {reason}")]
    InvalidParameter {
        /// Where the value came from (a file, a part).
        what: String,
        /// The field name.
        field: String,
        /// The value.
        value: f64,
        /// Why it is rejected.
        reason: String,
    },
    /// A configuration file is malformed.
    #[error("{file}: {message}")]
    Config {
        /// The file (or `<memory>`).
        file: String,
        /// What is wrong, with the field where known.
        message: String,
    },
    /// A PLY file is malformed.
    #[error("{file}: malformed PLY: {message}")]
    Ply {
        /// The file.
        file: String,
        /// What is wrong.
        message: String,
    },
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// The substep is too long for the stiffest part (refused before running).
    #[error(
        "substep_dt = {dt_s:e} s violates the CFL bound for part {part} ({material}): \
         dt must be <= {cfl} * dx / c_p = {bound_s:e} s (dx = {dx_m} m, P-wave speed \
         c_p = sqrt((lambda + 2 mu) / rho) = {wave_speed:.3} m/s); use a smaller substep_dt, a \
         coarser grid, or a softer/denser material"
    )]
    CflViolation {
        /// The requested substep (s).
        dt_s: f64,
        /// The largest allowed substep (s).
        bound_s: f64,
        /// The CFL number used.
        cfl: f64,
        /// Grid spacing (m).
        dx_m: f64,
        /// P-wave speed of the part (m/s).
        wave_speed: f64,
        /// The part index.
        part: usize,
        /// The material name.
        material: String,
    },
    /// The substep is too long for the explicit viscous stress of a `fluid` part (refused
    /// before running).
    #[error(
        "substep_dt = {dt_s:e} s is too long for the viscosity of part {part} ({material}, \
         plastic_viscosity_pa_s = {viscosity:e} Pa s): the explicit viscous stress is stable \
         for dt <= {cfl} * {factor} * rho dx^2 / viscosity = {bound_s:e} s (rho = {density} \
         kg/m^3, dx = {dx_m} m); use a smaller substep_dt, a coarser grid or a lower viscosity"
    )]
    ViscousStability {
        /// The requested substep (s).
        dt_s: f64,
        /// The largest allowed substep (s).
        bound_s: f64,
        /// The CFL number used (`max_cfl`).
        cfl: f64,
        /// The stability factor ([`crate::VISCOUS_STABILITY`]).
        factor: f64,
        /// Grid spacing (m).
        dx_m: f64,
        /// The part's viscosity (Pa s).
        viscosity: f64,
        /// The part's density (kg/m^3).
        density: f64,
        /// The part index.
        part: usize,
        /// The material name.
        material: String,
    },
    /// A substep produced NaN or infinity.
    #[error("simulation diverged: non-finite state of particle {particle} in frame {frame}, substep {substep} (global substep {global_substep})")]
    NonFinite {
        /// Frame being computed (1-based: frame 1 is the first simulated frame).
        frame: usize,
        /// Substep within the frame.
        substep: usize,
        /// Global substep index.
        global_substep: u64,
        /// Particle index.
        particle: usize,
    },
    /// A particle moved faster than the CFL limit (more than `max_cfl` cells per substep).
    #[error("simulation exploding: particle {particle} reached {speed:.4e} m/s in frame {frame}, substep {substep}, beyond the CFL limit {limit:.4e} m/s (= max_cfl dx / dt)")]
    SpeedLimit {
        /// Frame being computed.
        frame: usize,
        /// Substep within the frame.
        substep: usize,
        /// Particle index.
        particle: usize,
        /// Its speed (m/s).
        speed: f64,
        /// The limit (m/s).
        limit: f64,
    },
    /// A particle left the simulation grid (policy `out_of_domain = "error"`).
    #[error("particle {particle} left the simulation domain ({} = {coord} m; the grid interior is [{lo}, {hi}) m on every axis) in frame {frame}, substep {substep}; add a bounding_box boundary condition or set out_of_domain = \"clamp\"", ["x", "y", "z"][(*axis).min(2)])]
    OutOfDomain {
        /// Frame being computed.
        frame: usize,
        /// Substep within the frame.
        substep: usize,
        /// Particle index.
        particle: usize,
        /// The axis that left (0 = x, 1 = y, 2 = z).
        axis: usize,
        /// The offending coordinate.
        coord: f64,
        /// Lower bound of the interior.
        lo: f64,
        /// Upper bound of the interior.
        hi: f64,
    },
    /// Initial particles are unusable (outside the grid, NaN, bad part id).
    #[error("{what}: {message}")]
    Scene {
        /// Where the particles came from.
        what: String,
        /// What is wrong.
        message: String,
    },
    /// A backend returned data the generic code cannot use (a buffer of the wrong length, a
    /// state another simulation made).
    #[error("backend {backend}, {op}: {message}")]
    BackendOutput {
        /// The backend's name.
        backend: String,
        /// The operation.
        op: &'static str,
        /// What is wrong.
        message: String,
    },
    /// A backend failure the caller can't prevent (device lost, out of memory).
    #[error("backend: {0}")]
    Backend(#[source] Box<dyn std::error::Error + Send + Sync>),
}

impl Error {
    /// Wraps a backend error.
    pub fn backend<E: std::error::Error + Send + Sync + 'static>(e: E) -> Self {
        Error::Backend(Box::new(e))
    }
    /// A config error.
    pub fn config(file: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Config {
            file: file.into(),
            message: message.into(),
        }
    }
}
