//! The kernel-level backend trait ([`MpmKernels`]) and the device-side data it works on.
//!
//! A backend implements one method per stage of a substep (`particle_bcs`, `p2g`,
//! `grid_update`, `g2p`) on top of the family's base trait [`Backend`] (buffers, transfers,
//! errors, memory accounting); everything above (the substep order in [`crate::substep`],
//! the driver [`crate::Simulation`] with its checkpoints and reverse sweep) is written once,
//! generic over the backend. The CPU backends' buffers are `Vec<T>`; a GPU backend keeps
//! device buffers and crosses to the host only in [`Backend::download`].
//!
//! All structs uploaded to a device are `#[repr(C)]` + [`bytemuck::Pod`] and defined here once.

use crate::material::PartConsts;
use crate::math::Real;
use crate::params::MAT_CONSTS;
use bytemuck::{Pod, Zeroable};

pub use r4d_backend::{AnyBuf, Backend, MemoryUsage};

/// GPU time of one kernel, summed over its dispatches (from timestamp queries; a GPU
/// backend's `kernel_times`, printed by the CLI's `--profile`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct KernelTime {
    /// The kernel's name (`p2g`, `splat_rasterize`, ...).
    pub name: String,
    /// Dispatches timed.
    pub dispatches: u64,
    /// Their summed GPU time, in seconds.
    pub seconds: f64,
}

/// Constants of one substep, shared by every stage.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct StepConsts {
    /// Gravity (m/s^2).
    pub gravity: [f32; 3],
    /// Substep length (s).
    pub dt: f32,
    /// Grid spacing (m).
    pub dx: f32,
    /// `1 / dx`.
    pub inv_dx: f32,
    /// Grid nodes per axis (nodes at `i dx`, `i = 0 .. n_grid - 1`).
    pub n_grid: u32,
    /// Global index of this substep (for error reports).
    pub substep: u32,
    /// Time at the start of the substep (s).
    pub time: f32,
    /// RPIC damping r: `C' = (1 - r) C + r/2 (C - C^T)`; below -0.001 plain PIC (`C' = 0`).
    pub rpic_damping: f32,
    /// Grid velocity damping factor; applied only when < 1.
    pub grid_v_damping: f32,
    /// [`FORCE_CLASSIC`] or [`FORCE_MLS`].
    pub force_form: u32,
    /// Number of grid boundary conditions.
    pub n_grid_bcs: u32,
    /// Number of particle boundary conditions.
    pub n_particle_bcs: u32,
    /// [`OUT_OF_DOMAIN_ERROR`] or [`OUT_OF_DOMAIN_CLAMP`].
    pub out_of_domain: u32,
    /// Largest allowed particle speed (m/s); faster is reported as a CFL violation.
    pub max_speed: f32,
}

/// Stress force from the gradient of the B-spline weights (PhysGaussian's solver).
pub const FORCE_CLASSIC: u32 = 0;
/// Stress force from the MLS-MPM affine approximation (Hu et al. 2018).
pub const FORCE_MLS: u32 = 1;
/// A particle leaving the grid stops the simulation with an error.
pub const OUT_OF_DOMAIN_ERROR: u32 = 0;
/// A particle leaving the grid is clamped back inside.
pub const OUT_OF_DOMAIN_CLAMP: u32 = 1;

/// Grid boundary condition (see [`crate::boundary`] for the host-side description).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GridBc {
    /// One of the `BC_*` kinds in [`crate::boundary`].
    pub kind: u32,
    /// Surface mode: 0 sticky, 1 slip, 2 slip with Coulomb friction (separating).
    pub mode: u32,
    /// Bounding box: node layers per face. Cuboid: 1 = PhysGaussian's `reset`.
    pub layers: u32,
    /// Coulomb friction coefficient (mode 2).
    pub friction: f32,
    /// Cuboid centre or a point on the collider plane (m).
    pub point: [f32; 3],
    /// Start of the active window (s), inclusive.
    pub start: f32,
    /// Cuboid half extents, or the collider's unit normal.
    pub axis: [f32; 3],
    /// End of the active window (s), exclusive.
    pub end: f32,
    /// Prescribed velocity (cuboid; the cuboid moves with it while active).
    pub velocity: [f32; 3],
    /// Padding.
    pub _pad: f32,
}

/// Particle boundary condition: impulse or velocity override on the particles whose *initial*
/// position lies in a box.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct ParticleBc {
    /// [`crate::boundary::PBC_IMPULSE`] or [`crate::boundary::PBC_VELOCITY`].
    pub kind: u32,
    /// Padding.
    pub _pad: [u32; 3],
    /// Box centre (m).
    pub point: [f32; 3],
    /// Start of the active window (s), inclusive.
    pub start: f32,
    /// Box half extents (m).
    pub size: [f32; 3],
    /// End of the active window (s), exclusive.
    pub end: f32,
    /// Force per particle (N) for impulses, velocity (m/s) for overrides.
    pub vector: [f32; 3],
    /// Padding.
    pub _pad2: f32,
}

/// First problem met by a substep, written by `g2p`; all zero when healthy.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct Health {
    /// 0 healthy, else one of the `HEALTH_*` codes.
    pub code: u32,
    /// Substep index where it happened.
    pub substep: u32,
    /// Particle index.
    pub particle: u32,
    /// Bit pattern of the offending value (speed in m/s, or the coordinate).
    pub value_bits: u32,
}
/// A NaN or infinite value in a particle's state.
pub const HEALTH_NAN: u32 = 1;
/// A particle faster than [`StepConsts::max_speed`].
pub const HEALTH_SPEED: u32 = 2;
/// A particle outside the grid's interior.
pub const HEALTH_OUT_OF_DOMAIN: u32 = 3;

/// Particle state on a backend: a struct of buffers, defined once for every backend. Floating
/// point fields are in the backend's scalar type `S` ([`MpmKernels::Scalar`]: `f32` on a GPU,
/// `f32` or `f64` on the host backends).
pub struct Particles<B: MpmKernels> {
    /// Number of particles.
    pub count: usize,
    /// Positions (m).
    pub x: B::Buf<[B::Scalar; 3]>,
    /// Velocities (m/s).
    pub v: B::Buf<[B::Scalar; 3]>,
    /// APIC affine matrices C (row-major, 1/s).
    pub c: B::Buf<[B::Scalar; 9]>,
    /// Deformation gradients: F_trial after `g2p`, F_elastic after `p2g` (row-major).
    pub f: B::Buf<[B::Scalar; 9]>,
    /// Initial positions (f32: particle boundary conditions select by them, in f32 as
    /// PhysGaussian does).
    pub x0: B::Buf<[f32; 3]>,
    /// Initial volumes V0 (m^3), never updated.
    pub vol0: B::Buf<B::Scalar>,
    /// Masses (kg).
    pub mass: B::Buf<B::Scalar>,
    /// Parameter slot of each particle: its part (the default) or its own index (the
    /// per-particle ablation); indexes the `parts` and `mats` tables of [`MpmKernels::p2g`].
    pub part: B::Buf<u32>,
    /// Plastic state `[yield stress, J_p]`.
    pub plastic: B::Buf<[B::Scalar; 2]>,
    /// Scratch: the stress term of each particle between the particle stage and the scatter.
    pub stress: B::Buf<[B::Scalar; 9]>,
}

/// Grid state on a backend.
pub struct Grid<B: MpmKernels> {
    /// Nodes per axis.
    pub n: usize,
    /// Per node `[momentum or velocity (3), mass]`, index `(i n + j) n + k`.
    pub nodes: B::Buf<[B::Scalar; 4]>,
    /// One flag per block of [`BLOCK`]^3 nodes: 1 if a particle touched it this substep.
    pub active: B::Buf<u32>,
    /// Backend scratch (the CPU backend keeps its particle ordering here).
    pub scratch: B::Buf<u32>,
    /// Health record of the current frame.
    pub health: B::Buf<Health>,
}

/// Edge length (in nodes) of the blocks the grid tracks as active.
pub const BLOCK: usize = 4;

/// Number of blocks per axis for `n` nodes per axis.
pub fn blocks_per_axis(n: usize) -> usize {
    n.div_ceil(BLOCK)
}

/// The stages of one MPM substep, implemented by each backend.
///
/// The substep, in the order [`crate::substep::forward`] runs it (written once there):
/// 1. [`particle_bcs`](Self::particle_bcs): impulses and velocity overrides;
/// 2. [`p2g`](Self::p2g): clear the grid, return mapping + Kirchhoff stress per particle, then
///    scatter mass, APIC momentum and stress force to the 27-node stencil;
/// 3. [`grid_update`](Self::grid_update): momentum to velocity, gravity, damping, boundary
///    conditions in order;
/// 4. [`g2p`](Self::g2p): gather velocity, APIC C and velocity gradient, advect, update F,
///    check health.
///
/// Every backend must compute what the reference kernels in [`crate::reference`] compute,
/// up to floating-point summation order.
pub trait MpmKernels: Backend {
    /// The scalar type of the particle and grid state (`f32` on a GPU; the host backends are
    /// generic, `f64` being the gradient oracle).
    type Scalar: Real;

    /// `dst[i] += add[i]` element-wise (same length), on the backend: how a loss gradient
    /// enters an adjoint state.
    fn accumulate<const N: usize>(
        &self,
        dst: &mut Self::Buf<[Self::Scalar; N]>,
        add: &[[Self::Scalar; N]],
    ) -> Result<(), Self::Error>;
    /// `dst[i] += add[i]` element-wise (same length) for a buffer `add` already on the
    /// backend: how a loss gradient computed on the device enters an adjoint state.
    fn accumulate_buf<const N: usize>(
        &self,
        dst: &mut Self::Buf<[Self::Scalar; N]>,
        add: &Self::Buf<[Self::Scalar; N]>,
    ) -> Result<(), Self::Error>;

    /// Impulses and velocity overrides (particle boundary conditions) of this substep.
    fn particle_bcs(
        &self,
        p: &mut Particles<Self>,
        bcs: &Self::Buf<ParticleBc>,
        c: &StepConsts,
    ) -> Result<(), Self::Error>;
    /// Return mapping, stress and particle-to-grid transfer (clears the grid first).
    ///
    /// `parts` and `mats` are indexed by the particle's slot ([`Particles::part`]): `parts`
    /// holds the material id and the fixed constants, `mats` the differentiable material
    /// constants `[mu, lambda, plastic viscosity, Drucker-Prager alpha]` in the backend's
    /// scalar type ([`crate::constitutive::MaterialParams`]). Both are written by the same
    /// host function ([`crate::params::SlotTables`]), so `parts[s].mu == mats[s][0] as f32`;
    /// a GPU backend in f32 may read either.
    fn p2g(
        &self,
        p: &mut Particles<Self>,
        parts: &Self::Buf<PartConsts>,
        mats: &Self::Buf<[Self::Scalar; MAT_CONSTS]>,
        g: &mut Grid<Self>,
        c: &StepConsts,
    ) -> Result<(), Self::Error>;
    /// Grid velocity update with gravity, damping and boundary conditions.
    fn grid_update(
        &self,
        g: &mut Grid<Self>,
        bcs: &Self::Buf<GridBc>,
        c: &StepConsts,
    ) -> Result<(), Self::Error>;
    /// Grid-to-particle transfer, advection, F update and health check.
    fn g2p(
        &self,
        p: &mut Particles<Self>,
        g: &mut Grid<Self>,
        c: &StepConsts,
    ) -> Result<(), Self::Error>;
}

/// Implements [`MpmKernels::accumulate`] and [`MpmKernels::accumulate_buf`] for a host backend whose buffers are `Vec<T>` and
/// whose error is [`std::convert::Infallible`] (the reference and CPU backends; their buffer
/// methods come from [`r4d_backend::host_vec_backend!`]). Use inside the
/// `impl MpmKernels for ...` block.
#[macro_export]
macro_rules! host_vec_accumulate {
    () => {
        fn accumulate<const N: usize>(
            &self,
            dst: &mut Vec<[Self::Scalar; N]>,
            add: &[[Self::Scalar; N]],
        ) -> Result<(), std::convert::Infallible> {
            assert_eq!(dst.len(), add.len(), "accumulate: same length");
            for (d, a) in dst.iter_mut().zip(add) {
                for (d, a) in d.iter_mut().zip(a) {
                    *d += *a;
                }
            }
            Ok(())
        }
        fn accumulate_buf<const N: usize>(
            &self,
            dst: &mut Vec<[Self::Scalar; N]>,
            add: &Vec<[Self::Scalar; N]>,
        ) -> Result<(), std::convert::Infallible> {
            self.accumulate(dst, add)
        }
    };
}
