//! The simulator's reverse sweep on the device: [`WgpuAdjoint`] implements
//! [`Differentiable`] (so the checkpointing driver `r4d_mpm::adjoint::checkpoint::value_and_grad`
//! runs it unchanged) with the state in device buffers ([`DeviceState`], whose `Clone` copies on
//! the GPU) and the parameter gradient accumulated on the device ([`DeviceGrad`]).
//!
//! A substep forward reuses the forward kernels of [`crate::mpm`] (`particle_bcs`,
//! `p2g_stress`, `p2g`, `grid_update`, `g2p`; the health record is not kept). A substep's
//! reverse sweep re-runs its first half forward from the checkpoint (velocities after the
//! particle conditions, stress, the scattered and the updated grid), then, mirroring
//! the reverse order of `r4d_mpm::substep::reverse`:
//!
//! * `g2p_vjp`: one thread per particle; node velocity adjoints scattered with float atomics
//!   (native or compare-exchange, as `p2g`);
//! * `grid_update_vjp`: one thread per node, every grid boundary condition (the branch the
//!   forward pass took);
//! * `scatter_vjp`: one thread per particle gathering the node adjoints (no atomics);
//! * `stress_vjp`: the constitutive VJP in f32: fixed corotated (jelly) in closed form, every
//!   other isotropic model (metal, sand, foam, snow, plasticine) as the CPU does it, the scalar
//!   model's Jacobian from dual numbers (`shaders/lib/dual_model.wgsl`, a mirror of
//!   `r4d_mpm::constitutive::scalar_model`) and the matrix part by divided differences (the
//!   regularisation threshold differs from the CPU's: see the kernel's header);
//! * `particle_vjp`: particle conditions, RPIC damping, and the per-slot adjoints of mu, lambda,
//!   plastic viscosity, Drucker-Prager alpha and density reduced in workgroup memory (one tree
//!   reduction per slot present in the workgroup), then one atomic per slot and field.
//!
//! A particle outside the grid is skipped by the transfers and gets a zero adjoint, as on the
//! CPU. Scattered sums follow the hardware's order: results are not bitwise reproducible.
//!
//! The host never reads particles: [`DeviceState::download`] and
//! [`WgpuAdjoint::grad_to_host`] are explicit. The chain rule from (mu, lambda) to (E, nu) is
//! applied once per slot on the host ([`PhysParams::add_material_vjp`] is linear in the
//! adjoints, so summing first is exact up to rounding).
//!
//! Gradients reach E, nu, yield stress (through the initial plastic state: call
//! [`HostSim::init_vjp`] on the downloaded initial adjoint, as on the CPU), plastic viscosity,
//! friction angle and density. Measured against the CPU backend in f32 (`KernelAdjoint<CpuBackend<f32>>`) (tests/adjoint.rs, 2142
//! particles, 3 frames x 20 substeps, every boundary condition kind): jelly within 1.2e-4
//! relative; metal, sand, foam, plasticine within 5e-4, snow 1.1e-3 (6e-3 on a nearly
//! cancelled gradient); the initial F adjoint within 1.4e-4 except sand's 1.2e-2 (f32 near the
//! Drucker-Prager apex) and snow's 1.4e-3.
//!
//! Not yet: the fluid (no adjoint on the CPU either; [`AdjointError::Unsupported`]).

use crate::context::{GpuBuffer, WgpuContext, WgpuError};
use crate::mpm::Counts;
use r4d_mpm::adjoint::checkpoint::Differentiable;
use r4d_mpm::adjoint::host::{HostSim, HostState, PhysParams};
use r4d_mpm::kernels::{GridBc, ParticleBc, StepConsts};
use r4d_mpm::params::SlotTables;
use r4d_mpm::{Material, PartConsts};
use std::sync::{Arc, Mutex};

/// Floats per particle of the reverse sweep's scratch record (`SBAR_STRIDE` in
/// `shaders/lib/transfer_vjp.wgsl`).
const SBAR_STRIDE: usize = 32;
/// Floats per particle of the constant record (`INFO_STRIDE` there).
const INFO_STRIDE: usize = 8;
/// Accumulated adjoints per parameter slot: mu, lambda, plastic viscosity, Drucker-Prager
/// alpha, density, padding (`GRAD_STRIDE` in `shaders/mpm/particle_vjp.wgsl`).
const GRAD_STRIDE: usize = 8;

/// Materials whose VJP runs on the device and is checked against the CPU adjoint.
pub const SUPPORTED: &[Material] = &[
    Material::Jelly,
    Material::Metal,
    Material::Sand,
    Material::Foam,
    Material::Snow,
    Material::Plasticine,
];

/// Errors of the device adjoint.
#[derive(Debug, thiserror::Error)]
pub enum AdjointError {
    /// A part uses a material whose VJP has no kernel yet.
    #[error(
        "parts[{part}] is {material:?}: the GPU adjoint does not support this material yet \
         (supported: jelly, metal, sand, foam, snow, plasticine)"
    )]
    Unsupported {
        /// The part.
        part: usize,
        /// Its material.
        material: Material,
    },
    /// A device error.
    #[error(transparent)]
    Wgpu(#[from] WgpuError),
}

/// A simulation state (or its adjoint) in device buffers, struct-of-arrays as
/// [`HostState`]: `x`, `v` (3 floats per particle), `c`, `f` (9, row-major), `plastic` (2).
/// `Clone` copies the buffers on the device.
pub struct DeviceState {
    ctx: Arc<WgpuContext>,
    /// Positions.
    pub x: GpuBuffer<f32>,
    /// Velocities.
    pub v: GpuBuffer<f32>,
    /// APIC matrices.
    pub c: GpuBuffer<f32>,
    /// Deformation gradients.
    pub f: GpuBuffer<f32>,
    /// Plastic state `[yield stress, J_p]`.
    pub plastic: GpuBuffer<f32>,
}

impl DeviceState {
    /// Uploads a host state.
    pub fn upload(ctx: &Arc<WgpuContext>, s: &HostState<f32>) -> Result<Self, WgpuError> {
        Ok(DeviceState {
            ctx: ctx.clone(),
            x: ctx.upload("adjoint x", bytemuck::cast_slice(&s.x))?,
            v: ctx.upload("adjoint v", bytemuck::cast_slice(&s.v))?,
            c: ctx.upload("adjoint c", bytemuck::cast_slice(&s.c))?,
            f: ctx.upload("adjoint f", bytemuck::cast_slice(&s.f))?,
            plastic: ctx.upload("adjoint plastic", bytemuck::cast_slice(&s.plastic))?,
        })
    }

    /// A zero state of `n` particles.
    pub fn zeros(ctx: &Arc<WgpuContext>, n: usize) -> Result<Self, WgpuError> {
        Ok(DeviceState {
            ctx: ctx.clone(),
            x: ctx.zeros("adjoint x", 3 * n)?,
            v: ctx.zeros("adjoint v", 3 * n)?,
            c: ctx.zeros("adjoint c", 9 * n)?,
            f: ctx.zeros("adjoint f", 9 * n)?,
            plastic: ctx.zeros("adjoint plastic", 2 * n)?,
        })
    }

    /// Number of particles.
    pub fn len(&self) -> usize {
        self.x.len / 3
    }

    /// True when there are no particles.
    pub fn is_empty(&self) -> bool {
        self.x.len == 0
    }

    /// Reads the state back (waits for the device).
    pub fn download(&self) -> Result<HostState<f32>, WgpuError> {
        fn chunks<const N: usize>(v: Vec<f32>) -> Vec<[f32; N]> {
            v.chunks_exact(N)
                .map(|c| std::array::from_fn(|i| c[i]))
                .collect()
        }
        Ok(HostState {
            x: chunks(self.ctx.download(&self.x)?),
            v: chunks(self.ctx.download(&self.v)?),
            c: chunks(self.ctx.download(&self.c)?),
            f: chunks(self.ctx.download(&self.f)?),
            plastic: chunks(self.ctx.download(&self.plastic)?),
        })
    }

    /// Adds `dx` (one vector per particle) to the positions on the device (how a loss
    /// gradient enters an adjoint state).
    pub fn add_to_x(&self, dx: &[[f32; 3]]) -> Result<(), WgpuError> {
        assert_eq!(dx.len(), self.len(), "add_to_x: one vector per particle");
        self.add_into(&self.x, bytemuck::cast_slice(dx))
    }

    /// Adds `df` (one row-major 3x3 matrix per particle) to the deformation gradients on the
    /// device (how a rendering loss's dL/dF enters an adjoint state).
    pub fn add_to_f(&self, df: &[[f32; 9]]) -> Result<(), WgpuError> {
        assert_eq!(df.len(), self.len(), "add_to_f: one matrix per particle");
        self.add_into(&self.f, bytemuck::cast_slice(df))
    }

    /// `dst += values` on the device.
    fn add_into(&self, dst: &GpuBuffer<f32>, values: &[f32]) -> Result<(), WgpuError> {
        if values.is_empty() {
            return Ok(());
        }
        let src: GpuBuffer<f32> = self.ctx.upload("adjoint increment", values)?;
        let counts = self.ctx.uniform(
            "Counts",
            &Counts {
                particles: values.len() as u32,
                n_grid: 0,
                _pad: [0; 2],
            },
        )?;
        let mut enc = self.ctx.encoder();
        self.ctx.dispatch(
            &mut enc,
            "mpm_add_vjp",
            &[&counts.buffer, &src.buffer, &dst.buffer],
            values.len() as u32,
            64,
        )?;
        self.ctx.submit(enc);
        Ok(())
    }

    /// A copy on the device.
    pub fn try_clone(&self) -> Result<Self, WgpuError> {
        let copy = |b: &GpuBuffer<f32>| -> Result<GpuBuffer<f32>, WgpuError> {
            self.ctx.zeros(b.label, b.len)
        };
        let out = DeviceState {
            ctx: self.ctx.clone(),
            x: copy(&self.x)?,
            v: copy(&self.v)?,
            c: copy(&self.c)?,
            f: copy(&self.f)?,
            plastic: copy(&self.plastic)?,
        };
        let mut enc = self.ctx.encoder();
        for (s, d) in [
            (&self.x, &out.x),
            (&self.v, &out.v),
            (&self.c, &out.c),
            (&self.f, &out.f),
            (&self.plastic, &out.plastic),
        ] {
            copy_all(&mut enc, s, d);
        }
        self.ctx.submit(enc);
        Ok(out)
    }
}

/// Records a copy of a whole buffer.
fn copy_all<T>(enc: &mut wgpu::CommandEncoder, src: &GpuBuffer<T>, dst: &GpuBuffer<T>) {
    let bytes = src.bytes().min(dst.bytes());
    if bytes > 0 {
        enc.copy_buffer_to_buffer(&src.buffer, 0, &dst.buffer, 0, bytes);
    }
}

/// Parameter adjoints accumulated on the device over a reverse sweep: per slot the adjoints
/// of mu, lambda and density (float atomics). [`WgpuAdjoint::grad_to_host`] turns them into
/// [`PhysParams`] gradients.
pub struct DeviceGrad {
    acc: GpuBuffer<f32>,
}

/// What depends on the parameters: masses, per-slot constants, the particle records.
struct Prepared {
    params: Vec<PhysParams<f32>>,
    mass: GpuBuffer<f32>,
    parts: GpuBuffer<PartConsts>,
    info: GpuBuffer<f32>,
}

/// Device scratch of one substep (sized once).
struct Scratch {
    stress: GpuBuffer<f32>,
    v1: GpuBuffer<f32>,
    fe: GpuBuffer<f32>,
    plastic: GpuBuffer<f32>,
    sbar: GpuBuffer<f32>,
    grid_in: GpuBuffer<f32>,
    grid: GpuBuffer<f32>,
    grid_bar: GpuBuffer<f32>,
    grid_in_bar: GpuBuffer<f32>,
    /// `g2p`'s problem reports (never read: a NaN or a particle leaving the grid shows in the
    /// loss, as with the CPU adjoint).
    health_scratch: GpuBuffer<u32>,
}

/// The device adjoint of a [`HostSim`] (same substep, same parameter slots), for
/// [`value_and_grad`](r4d_mpm::adjoint::checkpoint::value_and_grad).
///
/// # Panics
/// The [`Differentiable`] methods have no error path: a device failure during a sweep (lost
/// device, a kernel missing from the build) panics with its message. Sizes are checked by
/// [`WgpuAdjoint::new`].
pub struct WgpuAdjoint<'a> {
    ctx: Arc<WgpuContext>,
    sim: &'a HostSim,
    x0: GpuBuffer<f32>,
    vol0: GpuBuffer<f32>,
    slot: GpuBuffer<u32>,
    grid_bcs: GpuBuffer<GridBc>,
    particle_bcs: GpuBuffer<ParticleBc>,
    scratch: Scratch,
    prepared: Mutex<Option<Prepared>>,
}

impl<'a> WgpuAdjoint<'a> {
    /// The device adjoint of `sim`; every part's material must be in [`SUPPORTED`].
    pub fn new(ctx: Arc<WgpuContext>, sim: &'a HostSim) -> Result<Self, AdjointError> {
        for (i, p) in sim.setup.config.parts.iter().enumerate() {
            if !SUPPORTED.contains(&p.material) {
                return Err(AdjointError::Unsupported {
                    part: i,
                    material: p.material,
                });
            }
        }
        let np = sim.len();
        let n = sim.setup.n;
        let nodes = n * n * n;
        let vol0: Vec<f32> = sim.vol0.iter().map(|&v| v as f32).collect();
        let mut gb = sim.setup.grid_bcs.clone();
        if gb.is_empty() {
            gb.push(bytemuck::Zeroable::zeroed());
        }
        let mut pb = sim.setup.particle_bcs.clone();
        if pb.is_empty() {
            pb.push(bytemuck::Zeroable::zeroed());
        }
        let mut health_init = vec![0u32; 1 + 2 * np];
        health_init[0] = u32::MAX;
        let scratch = Scratch {
            stress: ctx.zeros("adjoint stress", 9 * np)?,
            v1: ctx.zeros("adjoint v1", 3 * np)?,
            fe: ctx.zeros("adjoint F_elastic", 9 * np)?,
            plastic: ctx.zeros("adjoint plastic scratch", 2 * np)?,
            sbar: ctx.zeros("adjoint particle scratch", SBAR_STRIDE * np)?,
            grid_in: ctx.zeros("adjoint grid_in", 4 * nodes)?,
            grid: ctx.zeros("adjoint grid", 4 * nodes)?,
            grid_bar: ctx.zeros("adjoint grid_bar", 4 * nodes)?,
            grid_in_bar: ctx.zeros("adjoint grid_in_bar", 4 * nodes)?,
            health_scratch: ctx.upload("adjoint health scratch", &health_init)?,
        };
        Ok(WgpuAdjoint {
            x0: ctx.upload("adjoint x0", bytemuck::cast_slice(&sim.x0))?,
            vol0: ctx.upload("adjoint vol0", &vol0)?,
            slot: ctx.upload("adjoint slot", &sim.slot)?,
            grid_bcs: ctx.upload("adjoint grid bcs", &gb)?,
            particle_bcs: ctx.upload("adjoint particle bcs", &pb)?,
            scratch,
            prepared: Mutex::new(None),
            ctx,
            sim,
        })
    }

    /// The device.
    pub fn context(&self) -> &Arc<WgpuContext> {
        &self.ctx
    }

    /// The initial state on the device ([`HostSim::init`] uploaded).
    pub fn init(
        &self,
        params: &[PhysParams<f32>],
        v0: &[[f32; 3]],
    ) -> Result<DeviceState, WgpuError> {
        DeviceState::upload(&self.ctx, &self.sim.init(params, v0))
    }

    /// A zero gradient for the simulator's parameter slots.
    pub fn zero_grad(&self) -> Result<DeviceGrad, WgpuError> {
        Ok(DeviceGrad {
            acc: self
                .ctx
                .zeros("adjoint grad", GRAD_STRIDE * self.sim.slots().max(1))?,
        })
    }

    /// Reads the accumulated gradient back and applies the chain rule of the Lamé constants
    /// and of the masses: one [`PhysParams`] per slot. The yield stress gradient of the initial
    /// state is not included (add it with [`HostSim::init_vjp`]).
    pub fn grad_to_host(
        &self,
        g: &DeviceGrad,
        params: &[PhysParams<f32>],
    ) -> Result<Vec<PhysParams<f32>>, WgpuError> {
        let acc = self.ctx.download(&g.acc)?;
        Ok(params
            .iter()
            .enumerate()
            .map(|(s, p)| p.from_slot_adjoint(&acc[GRAD_STRIDE * s..GRAD_STRIDE * (s + 1)]))
            .collect())
    }

    /// Uploads what depends on the parameters, when they changed.
    fn prepare(&self, params: &[PhysParams<f32>]) -> Result<(), WgpuError> {
        let mut guard = self.prepared.lock().expect("prepared parameters");
        if guard.as_ref().is_some_and(|p| p.params == params) {
            return Ok(());
        }
        let sim = self.sim;
        // The one parameter mapping (also the CPU's): every differentiable constant of a slot
        // (mu, lambda, plastic viscosity, Drucker-Prager alpha, initial yield stress) comes
        // from its current parameters, the rest from its part.
        let tables = SlotTables::new(params, &sim.consts, &sim.slot_parts(), &sim.slot, &sim.vol0);
        let (mass, parts) = (tables.mass, tables.parts);
        let mut info = vec![0f32; INFO_STRIDE * sim.len()];
        for p in 0..sim.len() {
            let r = &mut info[INFO_STRIDE * p..INFO_STRIDE * (p + 1)];
            r[..3].copy_from_slice(&sim.x0[p]);
            r[3] = sim.vol0[p] as f32;
            r[4] = mass[p];
            r[5] = f32::from_bits(sim.slot[p]);
        }
        *guard = Some(Prepared {
            params: params.to_vec(),
            mass: self.ctx.upload("adjoint mass", &mass)?,
            parts: self.ctx.upload("adjoint slot consts", &parts)?,
            info: self.ctx.upload("adjoint particle info", &info)?,
        });
        Ok(())
    }

    fn uniforms(&self, k: u64) -> Result<(GpuBuffer<StepConsts>, GpuBuffer<Counts>), WgpuError> {
        let c = self.sim.consts_at(k);
        Ok((
            self.ctx.uniform("StepConsts", &c)?,
            self.ctx.uniform(
                "Counts",
                &Counts {
                    particles: self.sim.len() as u32,
                    n_grid: self.sim.setup.n as u32,
                    _pad: [0; 2],
                },
            )?,
        ))
    }

    /// One substep forward, in place.
    pub fn try_step(
        &self,
        s: &mut DeviceState,
        params: &[PhysParams<f32>],
        k: u64,
    ) -> Result<(), WgpuError> {
        self.prepare(params)?;
        let guard = self.prepared.lock().expect("prepared parameters");
        let pr = guard.as_ref().expect("prepared");
        let (cb, counts) = self.uniforms(k)?;
        let (np, nodes) = (self.sim.len() as u32, self.nodes() as u32);
        let sc = &self.scratch;
        let ctx = &self.ctx;
        let mut enc = ctx.encoder();
        let (c, n) = (&cb.buffer, &counts.buffer);
        ctx.dispatch(
            &mut enc,
            "mpm_particle_bcs",
            &[
                c,
                n,
                &self.particle_bcs.buffer,
                &self.x0.buffer,
                &pr.mass.buffer,
                &s.v.buffer,
            ],
            np,
            64,
        )?;
        ctx.dispatch(
            &mut enc,
            "mpm_p2g_stress",
            &[
                c,
                n,
                &pr.parts.buffer,
                &self.slot.buffer,
                &self.vol0.buffer,
                &s.c.buffer,
                &s.f.buffer,
                &s.plastic.buffer,
                &sc.stress.buffer,
            ],
            np,
            64,
        )?;
        enc.clear_buffer(&sc.grid.buffer, 0, None);
        ctx.dispatch(
            &mut enc,
            "mpm_p2g",
            &[
                c,
                n,
                &s.x.buffer,
                &s.v.buffer,
                &s.c.buffer,
                &pr.mass.buffer,
                &sc.stress.buffer,
                &sc.grid.buffer,
            ],
            np,
            64,
        )?;
        ctx.dispatch(
            &mut enc,
            "mpm_grid_update",
            &[c, n, &self.grid_bcs.buffer, &sc.grid.buffer],
            nodes,
            64,
        )?;
        ctx.dispatch(
            &mut enc,
            "mpm_g2p",
            &[
                c,
                n,
                &sc.grid.buffer,
                &s.x.buffer,
                &s.v.buffer,
                &s.c.buffer,
                &s.f.buffer,
                &sc.health_scratch.buffer,
            ],
            np,
            64,
        )?;
        ctx.submit(enc);
        Ok(())
    }

    /// Reverse sweep of substep `k` (see [`Differentiable::step_vjp`]).
    pub fn try_step_vjp(
        &self,
        before: &DeviceState,
        params: &[PhysParams<f32>],
        k: u64,
        adj: &mut DeviceState,
        grad: &mut DeviceGrad,
    ) -> Result<(), WgpuError> {
        self.prepare(params)?;
        let guard = self.prepared.lock().expect("prepared parameters");
        let pr = guard.as_ref().expect("prepared");
        let (cb, counts) = self.uniforms(k)?;
        let (np, nodes) = (self.sim.len() as u32, self.nodes() as u32);
        let sc = &self.scratch;
        let ctx = &self.ctx;
        let mut enc = ctx.encoder();
        let (c, n) = (&cb.buffer, &counts.buffer);
        // Forward to the updated grid, on copies of v, F and the plastic state.
        copy_all(&mut enc, &before.v, &sc.v1);
        copy_all(&mut enc, &before.f, &sc.fe);
        copy_all(&mut enc, &before.plastic, &sc.plastic);
        ctx.dispatch(
            &mut enc,
            "mpm_particle_bcs",
            &[
                c,
                n,
                &self.particle_bcs.buffer,
                &self.x0.buffer,
                &pr.mass.buffer,
                &sc.v1.buffer,
            ],
            np,
            64,
        )?;
        ctx.dispatch(
            &mut enc,
            "mpm_p2g_stress",
            &[
                c,
                n,
                &pr.parts.buffer,
                &self.slot.buffer,
                &self.vol0.buffer,
                &before.c.buffer,
                &sc.fe.buffer,
                &sc.plastic.buffer,
                &sc.stress.buffer,
            ],
            np,
            64,
        )?;
        enc.clear_buffer(&sc.grid_in.buffer, 0, None);
        ctx.dispatch(
            &mut enc,
            "mpm_p2g",
            &[
                c,
                n,
                &before.x.buffer,
                &sc.v1.buffer,
                &before.c.buffer,
                &pr.mass.buffer,
                &sc.stress.buffer,
                &sc.grid_in.buffer,
            ],
            np,
            64,
        )?;
        copy_all(&mut enc, &sc.grid_in, &sc.grid);
        ctx.dispatch(
            &mut enc,
            "mpm_grid_update",
            &[c, n, &self.grid_bcs.buffer, &sc.grid.buffer],
            nodes,
            64,
        )?;
        // Reverse.
        enc.clear_buffer(&sc.grid_bar.buffer, 0, None);
        ctx.dispatch(
            &mut enc,
            "mpm_g2p_vjp",
            &[
                c,
                n,
                &sc.grid.buffer,
                &before.x.buffer,
                &sc.fe.buffer,
                &adj.x.buffer,
                &adj.v.buffer,
                &adj.c.buffer,
                &adj.f.buffer,
                &sc.grid_bar.buffer,
            ],
            np,
            64,
        )?;
        ctx.dispatch(
            &mut enc,
            "mpm_grid_update_vjp",
            &[
                c,
                n,
                &self.grid_bcs.buffer,
                &sc.grid_in.buffer,
                &sc.grid_bar.buffer,
                &sc.grid_in_bar.buffer,
            ],
            nodes,
            64,
        )?;
        ctx.dispatch(
            &mut enc,
            "mpm_scatter_vjp",
            &[
                c,
                n,
                &before.x.buffer,
                &sc.v1.buffer,
                &before.c.buffer,
                &pr.info.buffer,
                &sc.stress.buffer,
                &sc.grid_in_bar.buffer,
                &sc.sbar.buffer,
            ],
            np,
            64,
        )?;
        ctx.dispatch(
            &mut enc,
            "mpm_stress_vjp",
            &[
                c,
                n,
                &pr.parts.buffer,
                &pr.info.buffer,
                &before.f.buffer,
                &before.plastic.buffer,
                &sc.sbar.buffer,
                &adj.f.buffer,
                &adj.plastic.buffer,
            ],
            np,
            64,
        )?;
        ctx.dispatch(
            &mut enc,
            "mpm_particle_vjp",
            &[
                c,
                n,
                &sc.sbar.buffer,
                &pr.info.buffer,
                &self.particle_bcs.buffer,
                &adj.x.buffer,
                &adj.v.buffer,
                &adj.c.buffer,
                &adj.plastic.buffer,
                &grad.acc.buffer,
            ],
            np,
            64,
        )?;
        ctx.submit(enc);
        Ok(())
    }

    fn nodes(&self) -> usize {
        let n = self.sim.setup.n;
        n * n * n
    }
}

impl Differentiable for WgpuAdjoint<'_> {
    type State = DeviceState;
    type Params = Vec<PhysParams<f32>>;
    type Grad = DeviceGrad;
    type Error = WgpuError;

    fn step(&self, s: &mut DeviceState, p: &Vec<PhysParams<f32>>, k: u64) -> Result<(), WgpuError> {
        self.try_step(s, p, k)
    }

    fn step_vjp(
        &self,
        before: &DeviceState,
        p: &Vec<PhysParams<f32>>,
        k: u64,
        adj: &mut DeviceState,
        grad: &mut DeviceGrad,
    ) -> Result<(), WgpuError> {
        self.try_step_vjp(before, p, k, adj, grad)
    }

    fn zero_adjoint(&self, s: &DeviceState) -> Result<DeviceState, WgpuError> {
        DeviceState::zeros(&self.ctx, s.len())
    }

    fn clone_state(&self, s: &DeviceState) -> Result<DeviceState, WgpuError> {
        s.try_clone()
    }
}
