// Host-shared records of the MPM kernels. Each mirrors a `#[repr(C)]` + Pod struct of
// `r4d_mpm::kernels` / `r4d_mpm::material` field for field (a unit test compares the layouts
// naga reflects with the Rust ones). Rust `[f32; 3]` followed by a scalar is a WGSL `vec3<f32>`
// (size 12, the scalar packs into its fourth slot).
//
// Matrices: Rust stores 3x3 matrices row-major (`m[row][col]`, `[f32; 9]`); in WGSL they are
// `mat3x3<f32>` holding the same mathematical matrix (column j = `m[j]`), so `A * B` in WGSL is
// the product of the Rust matrices. `load_mat3` / `store_mat3` in lib/math.wgsl convert.

struct StepConsts {
    gravity: vec3<f32>,
    dt: f32,
    dx: f32,
    inv_dx: f32,
    n_grid: u32,
    substep: u32,
    time: f32,
    rpic_damping: f32,
    grid_v_damping: f32,
    force_form: u32,
    n_grid_bcs: u32,
    n_particle_bcs: u32,
    out_of_domain: u32,
    max_speed: f32,
}

struct PartConsts {
    mu: f32,
    lambda: f32,
    yield_stress: f32,
    plastic_viscosity: f32,
    dp_alpha: f32,
    hardening_xi: f32,
    softening: f32,
    theta_c: f32,
    theta_s: f32,
    snow_xi: f32,
    bulk: f32,
    material: u32,
}

// Floats per particle and per slot of the parameter adjoints (`pgrad` and the slot sums):
// mu, lambda, plastic viscosity, Drucker-Prager alpha, density, hardening coefficient
// (Rust `r4d_mpm::params::PARAM_ADJOINTS`).
const PGRAD_STRIDE: u32 = 6u;

// The hardening coefficient a part's model reads (Rust `PartConsts::hardening_coeff`):
// metal's xi, plasticine's softening, 0 for the others.
fn hardening_coeff(pc: PartConsts) -> f32 {
    if pc.material == 1u {
        return pc.hardening_xi;
    }
    if pc.material == 5u {
        return pc.softening;
    }
    return 0.0;
}

struct GridBc {
    kind: u32,
    mode: u32,
    layers: u32,
    friction: f32,
    point: vec3<f32>,
    start: f32,
    axis: vec3<f32>,
    end: f32,
    velocity: vec3<f32>,
    _pad: f32,
}

struct ParticleBc {
    kind: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
    point: vec3<f32>,
    start: f32,
    size: vec3<f32>,
    end: f32,
    vector: vec3<f32>,
    _pad3: f32,
}

struct Health {
    code: atomic<u32>,
    substep: u32,
    particle: u32,
    value_bits: u32,
}

const FORCE_CLASSIC: u32 = 0u;
const FORCE_MLS: u32 = 1u;
const OUT_OF_DOMAIN_ERROR: u32 = 0u;
const OUT_OF_DOMAIN_CLAMP: u32 = 1u;
const BC_BOUNDING_BOX: u32 = 0u;
const BC_CUBOID: u32 = 1u;
const BC_SURFACE: u32 = 2u;
const PBC_IMPULSE: u32 = 0u;
const PBC_VELOCITY: u32 = 1u;
const HEALTH_NAN: u32 = 1u;
const HEALTH_SPEED: u32 = 2u;
const HEALTH_OUT_OF_DOMAIN: u32 = 3u;
const MAT_JELLY: u32 = 0u;
const MAT_METAL: u32 = 1u;
const MAT_SAND: u32 = 2u;
const MAT_FOAM: u32 = 3u;
const MAT_SNOW: u32 = 4u;
const MAT_PLASTICINE: u32 = 5u;
const MAT_FLUID: u32 = 6u;

// Per-dispatch sizes (backend-internal, not a Rust kernel record).
struct Counts {
    particles: u32,
    n_grid: u32,
    _pad0: u32,
    _pad1: u32,
}

// Linear thread index of a 1D dispatch split over x and y (workgroups of `wg` threads).
fn linear_id(gid: vec3<u32>, nwg: vec3<u32>, wg: u32) -> u32 {
    return gid.x + gid.y * nwg.x * wg;
}
