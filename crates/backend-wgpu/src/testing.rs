//! Helpers for tests that need a device.

use crate::WgpuContext;

/// The device for a GPU test, or `None` (the test then returns early) when no adapter exists
/// and the build expected none (then the GPU tests are compiled `#[ignore]`d: `cfg(r4d_gpu)`,
/// `build/gpu_probe.rs`). Where the build found a driver, or with `R4D_REQUIRE_GPU=1` (set in
/// CI), a missing adapter panics instead, so GPU tests can never pass by skipping. Native float atomics are used where the adapter has them, unless
/// `R4D_WGPU_NO_FLOAT_ATOMICS` is set (as [`WgpuContext::new`]), so a whole suite can be run
/// on the compare-exchange scatter.
pub fn gpu_or_skip(test: &str) -> Option<WgpuContext> {
    gpu_or_skip_with(
        test,
        std::env::var_os("R4D_WGPU_NO_FLOAT_ATOMICS").is_none(),
    )
}

/// [`gpu_or_skip`] with the choice of native float atomics (`false`: the compare-exchange
/// scatter).
pub fn gpu_or_skip_with(test: &str, float_atomics: bool) -> Option<WgpuContext> {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        // Mesa's drivers warn without it; any writable folder will do.
        let d = std::env::temp_dir().join("r4d-xdg-runtime");
        let _ = std::fs::create_dir_all(&d);
        // SAFETY: tests set this before any thread reads the environment through wgpu.
        unsafe { std::env::set_var("XDG_RUNTIME_DIR", d) };
    }
    match WgpuContext::with_float_atomics(float_atomics) {
        Ok(c) => Some(c),
        Err(e) => {
            if std::env::var("R4D_REQUIRE_GPU").is_ok_and(|v| v == "1") {
                panic!("{test}: R4D_REQUIRE_GPU=1 but {e}");
            }
            if cfg!(r4d_gpu) {
                // The build found a driver (build/gpu_probe.rs) and compiled the GPU tests to
                // run: one that cannot is a failure, never a pass.
                panic!(
                    "{test}: a GPU driver was found when this was built, but {e}; rebuild with \
                     R4D_NO_GPU=1 to report the GPU tests as ignored"
                );
            }
            eprintln!("{test}: skipped: {e}");
            None
        }
    }
}
