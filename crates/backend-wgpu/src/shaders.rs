//! The preprocessed WGSL kernels and the struct layouts naga reflected at build time.

include!(concat!(env!("OUT_DIR"), "/kernels.rs"));

/// The source of a kernel by name (`"mpm_p2g"`, `"mpm_p2g_cas"`, ...).
pub fn source(name: &str) -> Option<&'static str> {
    KERNELS.iter().find(|k| k.0 == name).map(|k| k.1)
}
