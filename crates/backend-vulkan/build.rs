//! Build script: whether this machine is expected to have a GPU adapter (`cfg(r4d_gpu)`), so
//! that without one the GPU tests are reported as ignored with the reason, never as passed
//! (`build/gpu_probe.rs`).

include!("../../build/gpu_probe.rs");

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=../../build/gpu_probe.rs");
    probe_gpu();
}
