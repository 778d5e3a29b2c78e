//! # r4d-shaders: the WGSL compute kernels as a typed table
//!
//! One WGSL file per kernel under `wgsl/mpm/` and `wgsl/splat/`, named after the CPU function
//! it mirrors (vello's layout: `mpm/p2g.wgsl` is `r4d_mpm::transfer`'s scatter,
//! `splat/rasterize.wgsl` is `r4d_splat::raster::composite_pixel` over a tile); `wgsl/lib/`
//! holds what kernels share (structs, 3x3 math, the SVD, the compositing rule).
//!
//! The build script preprocesses every kernel (`#import`), validates it with naga (a broken
//! shader fails `cargo build`) and emits one [`Kernel`] constant per kernel: its WGSL (what
//! wgpu compiles), its SPIR-V (what a Vulkan backend loads), the workgroup size and the
//! bindings its entry point uses, reflected by naga. A GPU backend dispatches a constant
//! (`mpm::P2G`), never a string, and takes workgroup sizes and binding counts from it.
//!
//! ```
//! let k = &r4d_shaders::mpm::P2G;
//! assert_eq!(k.name, "mpm_p2g");
//! assert_eq!(k.threads_per_group(), 64);
//! assert!(k.bindings.len() >= 3 && !k.spirv.is_empty());
//! // Scatter kernels have a compare-exchange variant for adapters without float atomics.
//! assert_eq!(k.cas.map(|c| c.name), Some("mpm_p2g_cas"));
//! ```

/// How a kernel binds one buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BindingKind {
    /// A uniform buffer.
    Uniform,
    /// A storage buffer.
    Storage {
        /// True when the kernel only reads it.
        read_only: bool,
    },
}

/// One binding of a kernel (group 0; its index is its position in [`Kernel::bindings`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Binding {
    /// The WGSL variable's name.
    pub name: &'static str,
    /// Uniform or storage.
    pub kind: BindingKind,
}

/// A compiled compute kernel (entry point `main`).
#[derive(Debug)]
pub struct Kernel {
    /// Unique name (`mpm_p2g`, `mpm_p2g_cas`): pipeline caches and labels use it.
    pub name: &'static str,
    /// Source file under `wgsl/`.
    pub file: &'static str,
    /// Preprocessed WGSL.
    pub wgsl: &'static str,
    /// SPIR-V (little-endian 32-bit words).
    pub spirv: &'static [u8],
    /// `@workgroup_size`.
    pub workgroup_size: [u32; 3],
    /// The buffers a dispatch binds, in order (bindings 0, 1, ...).
    pub bindings: &'static [Binding],
    /// The compare-exchange variant, for kernels that add floats atomically.
    pub cas: Option<&'static Kernel>,
}

impl Kernel {
    /// Invocations per workgroup.
    pub fn threads_per_group(&self) -> u32 {
        self.workgroup_size.iter().product()
    }

    /// The variant to run: this one, or its compare-exchange twin when the device has no
    /// float atomics.
    pub fn variant(&'static self, float_atomics: bool) -> &'static Kernel {
        match self.cas {
            Some(c) if !float_atomics => c,
            _ => self,
        }
    }

    /// The SPIR-V as 32-bit words.
    pub fn spirv_words(&self) -> Vec<u32> {
        self.spirv
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect()
    }
}

include!(concat!(env!("OUT_DIR"), "/kernels.rs"));

/// The layout naga reflected for a WGSL struct: size and member offsets.
pub fn layout(name: &str) -> Option<(u32, &'static [(&'static str, u32)])> {
    LAYOUTS.iter().find(|l| l.0 == name).map(|l| (l.1, l.2))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kernel_is_in_the_table_once_with_spirv_and_bindings() {
        let mut names: Vec<&str> = ALL.iter().map(|k| k.name).collect();
        let n = names.len();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), n, "duplicate kernel names");
        for k in ALL {
            assert_eq!(k.spirv.len() % 4, 0, "{}", k.name);
            assert_eq!(k.spirv_words()[0], 0x0723_0203, "{}: SPIR-V magic", k.name);
            assert!(k.threads_per_group() >= 1, "{}", k.name);
            assert!(!k.bindings.is_empty(), "{}", k.name);
            assert!(k.wgsl.contains("fn main"), "{}", k.name);
        }
    }

    #[test]
    fn reflection_reads_the_shaders() {
        assert_eq!(splat::RASTERIZE.workgroup_size, [16, 16, 1]);
        assert_eq!(mpm::HEALTH.threads_per_group(), 1);
        let b = mpm::G2P_VJP.bindings;
        assert_eq!(b[0].kind, BindingKind::Uniform);
        assert_eq!(b[2].name, "nodes");
        assert_eq!(b[2].kind, BindingKind::Storage { read_only: true });
        assert_eq!(b[5].kind, BindingKind::Storage { read_only: false });
        assert!(mpm::G2P.cas.is_none());
        assert_eq!(
            mpm::REDUCE_SLOTS.variant(false).name,
            "mpm_reduce_slots_cas"
        );
        assert_eq!(mpm::REDUCE_SLOTS.variant(true).name, "mpm_reduce_slots");
    }
}
