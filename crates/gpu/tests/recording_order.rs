//! The dispatch lists of a substep, forward and reverse, as any engine receives them: a
//! tracing engine (host byte buffers, copies and clears executed, dispatches only recorded and
//! checked against the kernels' reflected bindings) runs the one stepper `Simulation` on
//! `Gpu`. No GPU needed.

use r4d_gpu::{Command, Gpu, GpuEngine, Recording, Resource};
use r4d_mpm::adjoint::checkpoint::Differentiable;
use r4d_mpm::adjoint::host::{HostSim, PhysParams};
use r4d_mpm::kernels::MemoryUsage;
use r4d_mpm::Simulation;
use r4d_mpm::{ParticleSet, SimConfig};
use r4d_shaders::BindingKind;
use std::sync::Mutex;

/// Errors of the tracing engine: a dispatch whose bindings don't match the kernel.
#[derive(Debug, PartialEq)]
struct TraceError(String);

impl std::fmt::Display for TraceError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for TraceError {}

#[derive(Default)]
struct TraceEngine {
    trace: Mutex<Vec<&'static str>>,
}

impl GpuEngine for TraceEngine {
    type Raw = Mutex<Vec<u8>>;
    type Error = TraceError;

    fn name(&self) -> &'static str {
        "trace"
    }

    fn alloc(&self, _label: &'static str, bytes: u64) -> Result<Self::Raw, TraceError> {
        Ok(Mutex::new(vec![0; bytes as usize]))
    }

    fn write(&self, raw: &Self::Raw, data: &[u8]) -> Result<(), TraceError> {
        raw.lock().unwrap()[..data.len()].copy_from_slice(data);
        Ok(())
    }

    fn read(&self, raw: &Self::Raw, bytes: u64) -> Result<Vec<u8>, TraceError> {
        Ok(raw.lock().unwrap()[..bytes as usize].to_vec())
    }

    fn execute(&self, rec: Recording<'_, Self::Raw>) -> Result<(), TraceError> {
        for c in &rec.commands {
            match c {
                Command::Dispatch {
                    kernel, bindings, ..
                } => {
                    if bindings.len() != kernel.bindings.len() {
                        return Err(TraceError(format!("{}: binding count", kernel.name)));
                    }
                    for (r, b) in bindings.iter().zip(kernel.bindings) {
                        let ok = match (r, b.kind) {
                            (Resource::Uniform(_), BindingKind::Uniform) => true,
                            (Resource::Data(_), BindingKind::Storage { read_only }) => read_only,
                            (
                                Resource::Buffer(_) | Resource::Scratch(_),
                                BindingKind::Storage { .. },
                            ) => true,
                            _ => false,
                        };
                        if !ok {
                            return Err(TraceError(format!(
                                "{}: {} bound as {r:?}",
                                kernel.name, b.name
                            )));
                        }
                    }
                    self.trace.lock().unwrap().push(kernel.name);
                }
                Command::Clear(Resource::Buffer(i)) => rec.buffers[*i].lock().unwrap().fill(0),
                Command::Copy {
                    src: Resource::Buffer(s),
                    src_offset: 0,
                    dst: Resource::Buffer(d),
                    dst_offset: 0,
                    bytes,
                } => {
                    let v = rec.buffers[*s].lock().unwrap()[..*bytes as usize].to_vec();
                    rec.buffers[*d].lock().unwrap()[..*bytes as usize].copy_from_slice(&v);
                }
                other => return Err(TraceError(format!("unexpected command {other:?}"))),
            }
        }
        Ok(())
    }

    fn memory_usage(&self) -> MemoryUsage {
        MemoryUsage::default()
    }
}

const CONFIG: &str = r#"
[domain]
grid_lim = 1.0
n_grid = 16

[time]
substep_dt = 1e-4
substeps_per_frame = 2
frames = 1

[[parts]]
material = "metal"
youngs_modulus_pa = 5e4
poisson_ratio = 0.3
density_kg_m3 = 800.0
yield_stress_pa = 100.0

[[shapes]]
kind = "box"
min = [0.4, 0.4, 0.4]
max = [0.6, 0.6, 0.6]

[[boundary]]
type = "bounding_box"

[[boundary]]
type = "particle_impulse"
force = [0.0, 0.0, 1.0]
point = [0.5, 0.5, 0.5]
size = [0.2, 0.2, 0.2]
num_dt = 10
start_time = 0.0
"#;

#[test]
fn a_substep_dispatches_its_stages_in_the_order_of_substep_forward_and_reverse() {
    let cfg = SimConfig::parse(CONFIG, std::path::Path::new("trace.toml")).unwrap();
    let scene = ParticleSet::from_shapes(&cfg.shapes, cfg.domain.dx());
    let sim = HostSim::new(&cfg, &scene).unwrap();
    let gpu = Gpu::<TraceEngine>::new(TraceEngine::default());
    let d = Simulation::with_host(gpu, &sim).unwrap();
    let params: Vec<PhysParams<f32>> = cfg.parts.iter().map(PhysParams::of).collect();
    let before = d.init(&params, &vec![[0.0; 3]; sim.len()]).unwrap();
    let mut s = d.clone_state(&before).unwrap();
    let trace = || std::mem::take(&mut *d.backend().engine().trace.lock().unwrap());
    trace();
    d.step(&mut s, &params, 0).unwrap();
    let forward = [
        "mpm_particle_bcs",
        "mpm_p2g_stress",
        "mpm_p2g",
        "mpm_grid_update",
        "mpm_g2p",
        "mpm_health",
    ];
    assert_eq!(trace(), forward);
    let mut adj = d.zero_adjoint(&s).unwrap();
    let mut grad = d.zero_grad().unwrap();
    trace();
    d.step_vjp(&before, &params, 0, &mut adj, &mut grad)
        .unwrap();
    let reverse = [
        "mpm_g2p_vjp",
        "mpm_grid_update_vjp",
        "mpm_pack_info",
        "mpm_scatter_vjp",
        "mpm_stress_vjp",
        "mpm_particle_vjp",
        "mpm_reduce_slots",
    ];
    // The forward up to the updated grid (G2P's outputs are not read by the reverse stages).
    let expected: Vec<&str> = forward[..4].iter().chain(&reverse).copied().collect();
    assert_eq!(
        trace(),
        expected,
        "the reverse substep re-runs its forward up to the grid, then reverses"
    );
}
