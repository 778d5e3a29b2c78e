//! The kernels come from `r4d-shaders` (WGSL validated by naga at build time, dispatched as
//! typed constants); this module checks that the structs they share with the host have the
//! Rust `#[repr(C)]` layouts naga reflected.

pub use r4d_shaders::{layout, Kernel, LAYOUTS};

#[cfg(test)]
mod tests {
    use super::*;
    use r4d_mpm::kernels::{GridBc, Health, ParticleBc, StepConsts};
    use r4d_mpm::PartConsts;
    use std::mem::{offset_of, size_of};

    /// Checks size and the offsets of the named (non-padding) fields.
    fn check(name: &str, size: usize, fields: &[(&str, usize)]) {
        let (wsize, members) =
            layout(name).unwrap_or_else(|| panic!("WGSL struct {name} not found"));
        assert_eq!(
            wsize as usize, size,
            "{name}: WGSL size {wsize} vs Rust {size}"
        );
        for (f, off) in fields {
            let m = members
                .iter()
                .find(|m| m.0 == *f)
                .unwrap_or_else(|| panic!("{name}.{f} missing in WGSL"));
            assert_eq!(
                m.1 as usize, *off,
                "{name}.{f}: WGSL offset {} vs Rust {off}",
                m.1
            );
        }
    }

    macro_rules! fields {
        ($t:ty; $($f:ident),*) => { &[$((stringify!($f), offset_of!($t, $f))),*] };
    }

    #[test]
    fn wgsl_structs_match_the_rust_layouts() {
        check(
            "StepConsts",
            size_of::<StepConsts>(),
            fields!(StepConsts; gravity, dt, dx, inv_dx, n_grid, substep, time, rpic_damping,
                grid_v_damping, force_form, n_grid_bcs, n_particle_bcs, out_of_domain, max_speed),
        );
        check(
            "PartConsts",
            size_of::<PartConsts>(),
            fields!(PartConsts; mu, lambda, yield_stress, plastic_viscosity, dp_alpha,
                hardening_xi, softening, theta_c, theta_s, snow_xi, bulk, material),
        );
        check(
            "GridBc",
            size_of::<GridBc>(),
            fields!(GridBc; kind, mode, layers, friction, point, start, axis, end, velocity),
        );
        check(
            "ParticleBc",
            size_of::<ParticleBc>(),
            fields!(ParticleBc; kind, point, start, size, end, vector),
        );
        check(
            "Health",
            size_of::<Health>(),
            fields!(Health; code, substep, particle, value_bits),
        );
        check(
            "LinkConsts",
            size_of::<r4d_splat::LinkConsts>(),
            fields!(r4d_splat::LinkConsts; to_world, rot, inv_scale, simulated, particles),
        );
        check(
            "Counts",
            size_of::<r4d_gpu::Counts>(),
            &[("particles", 0), ("n_grid", 4)],
        );
    }
}
