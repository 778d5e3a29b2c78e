//! Helpers for tests that need a Vulkan device.

use crate::VulkanEngine;

/// Fails `test` when the Khronos validation layer reported anything on `engine` (with
/// `R4D_VULKAN_VALIDATION=1`, as CI runs the tests; a no-op otherwise).
pub fn assert_validation_clean(engine: &VulkanEngine, test: &str) {
    let n = engine.validation_messages();
    assert_eq!(
        n, 0,
        "{test}: {n} Vulkan validation message(s), printed above"
    );
}

/// The engine for a Vulkan test, or `None` (the test then returns early) when there is no
/// Vulkan loader or device and the build expected none (then the GPU tests are compiled
/// `#[ignore]`d: `cfg(r4d_gpu)`, `build/gpu_probe.rs`). Where the build found a driver, or with
/// `R4D_REQUIRE_GPU=1` (set in CI, where Mesa's lavapipe is installed), a missing device
/// panics instead, so Vulkan tests can never pass by skipping.
pub fn vulkan_or_skip(test: &str) -> Option<VulkanEngine> {
    vulkan_or_skip_with(
        test,
        std::env::var_os("R4D_VULKAN_NO_FLOAT_ATOMICS").is_none(),
    )
}

/// [`vulkan_or_skip`] with the choice of native float atomics (`false`: the compare-exchange
/// scatter).
pub fn vulkan_or_skip_with(test: &str, float_atomics: bool) -> Option<VulkanEngine> {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        // Mesa's drivers warn without it; any writable folder will do.
        let d = std::env::temp_dir().join("r4d-xdg-runtime");
        let _ = std::fs::create_dir_all(&d);
        // SAFETY: tests set this before any thread reads the environment through Vulkan.
        unsafe { std::env::set_var("XDG_RUNTIME_DIR", d) };
    }
    match VulkanEngine::with_float_atomics(float_atomics) {
        Ok(e) => Some(e),
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
