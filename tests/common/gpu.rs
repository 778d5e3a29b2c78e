//! One GPU engine of each kind per test binary, shared by its tests.
//!
//! A driver compiles a kernel's pipeline the first time an engine uses it, and on Mesa's
//! lavapipe (CI's Vulkan device) that compilation dominates a GPU test: the adjoint kernels
//! take tens of seconds, their dispatches on the small test scenes a fraction of a second.
//! The engines cache their pipelines, so a binary makes each engine once and its tests share
//! it. A test holds the engine's lease for its whole run, so tests on one engine run one at a
//! time and see only their own work on it (memory figures, profiles); a panicking test
//! releases it for the next. Validation messages accumulate on the shared Vulkan engine, so
//! one message fails every later check on it, never none.
//!
//! Without an adapter or Vulkan device these return `None` (the test returns early; where the
//! build found no GPU driver the GPU tests are `#[ignore]`d anyway, `cfg(r4d_gpu)`); where it
//! found one, or with `R4D_REQUIRE_GPU=1`, every test that asks panics, as with `gpu_or_skip`
//! and `vulkan_or_skip`, which make the engines.
#![allow(dead_code)]

use r4d_backend_vulkan::VulkanEngine;
use r4d_backend_wgpu::WgpuContext;
use std::ops::Deref;
use std::sync::{Arc, Mutex, MutexGuard, OnceLock, PoisonError};

/// A shared engine, held by one test at a time.
pub struct Lease<T: 'static> {
    engine: &'static T,
    _turn: MutexGuard<'static, ()>,
}

impl<T> Deref for Lease<T> {
    type Target = T;
    fn deref(&self) -> &T {
        self.engine
    }
}

/// One lazily made engine and the lock that hands it out.
struct Slot<T> {
    engine: OnceLock<Option<T>>,
    turn: Mutex<()>,
}

impl<T> Slot<T> {
    const fn new() -> Self {
        Slot {
            engine: OnceLock::new(),
            turn: Mutex::new(()),
        }
    }

    fn lease(&'static self, test: &str, make: impl FnOnce() -> Option<T>) -> Option<Lease<T>> {
        let turn = self.turn.lock().unwrap_or_else(PoisonError::into_inner);
        match self.engine.get_or_init(make) {
            Some(engine) => Some(Lease {
                engine,
                _turn: turn,
            }),
            None => {
                eprintln!("{test}: skipped: no GPU (see the first GPU test's message)");
                None
            }
        }
    }
}

static WGPU: Slot<Arc<WgpuContext>> = Slot::new();
static VULKAN: Slot<VulkanEngine> = Slot::new();

/// The binary's wgpu context (`gpu_or_skip`'s: native float atomics unless
/// `R4D_WGPU_NO_FLOAT_ATOMICS`), or `None` (skip).
pub fn wgpu(test: &str) -> Option<Lease<Arc<WgpuContext>>> {
    WGPU.lease(test, || {
        r4d_backend_wgpu::testing::gpu_or_skip(test).map(Arc::new)
    })
}

/// The binary's Vulkan engine (`vulkan_or_skip`'s), or `None` (skip).
pub fn vulkan(test: &str) -> Option<Lease<VulkanEngine>> {
    VULKAN.lease(test, || r4d_backend_vulkan::testing::vulkan_or_skip(test))
}
