//! `--profile`: per-kernel GPU time, measured by the backend's timestamp queries (the Vulkan
//! backend), and the bytes moved between host and device (the GPU backends of the fits),
//! printed to stderr when the command ends (also when it fails: the figures so far).

use anyhow::Result;
use r4d_mpm::KernelTime;
use resonance4d::compute::Compute;
use std::sync::Arc;

type Times = Box<dyn Fn() -> Result<Vec<KernelTime>>>;

/// Prints the per-kernel times and the bytes moved when dropped (nothing when `--profile` is
/// off).
pub struct Profile {
    times: Option<Times>,
    moved: Option<(Arc<dyn Compute>, r4d_mpm::MemoryUsage)>,
}

impl Profile {
    /// On a fit backend: turns its timing on; a backend that cannot measure says so.
    pub fn on_compute(backend: &Arc<dyn Compute>, on: bool) -> Result<Self> {
        if !on {
            return Ok(Profile {
                times: None,
                moved: None,
            });
        }
        let moved = backend.device_memory().map(|m| (backend.clone(), m));
        if !backend.set_profiling(true)? {
            let mut p = Self::unsupported(backend.name(), true);
            p.moved = moved;
            return Ok(p);
        }
        let b = backend.clone();
        Ok(Profile {
            times: Some(Box::new(move || Ok(b.kernel_times()?))),
            moved,
        })
    }

    /// On a Vulkan engine used directly (`simulate`, `render`).
    pub fn on_vulkan(e: &r4d_backend_vulkan::VulkanEngine, on: bool) -> Result<Self> {
        if !on {
            return Ok(Profile {
                times: None,
                moved: None,
            });
        }
        if !e.set_profiling(true)? {
            return Ok(Self::unsupported(
                "vulkan (this device has no timestamps)",
                true,
            ));
        }
        let e = e.clone();
        Ok(Profile {
            times: Some(Box::new(move || {
                e.finish()?;
                Ok(e.kernel_times())
            })),
            moved: None,
        })
    }

    /// A backend without per-kernel timing: a note when `--profile` was given.
    pub fn unsupported(backend: &str, on: bool) -> Self {
        if on {
            eprintln!(
                "--profile: the {backend} backend does not measure per-kernel GPU time (the \
                 Vulkan backend does, with timestamp queries); no per-kernel times will be printed"
            );
        }
        Profile {
            times: None,
            moved: None,
        }
    }
}

impl Drop for Profile {
    fn drop(&mut self) {
        if let Some((b, start)) = &self.moved {
            if let Some(now) = b.device_memory() {
                let mib = |x: u64| x as f64 / (1u64 << 20) as f64;
                eprintln!(
                    "moved between host and device: {:.1} MiB up, {:.1} MiB down",
                    mib(now.uploaded_bytes - start.uploaded_bytes),
                    mib(now.downloaded_bytes - start.downloaded_bytes)
                );
            }
        }
        let Some(f) = &self.times else { return };
        match f() {
            Ok(t) => eprint!("{}", table(&t)),
            Err(e) => eprintln!("--profile: {e:#}"),
        }
    }
}

/// The table: kernel, dispatches, total and mean GPU time, share of the total.
pub fn table(times: &[KernelTime]) -> String {
    let total: f64 = times.iter().map(|t| t.seconds).sum();
    let mut s = format!(
        "GPU time per kernel ({} dispatches, {:.3} s in all):\n{:<28} {:>10} {:>12} {:>11} {:>7}\n",
        times.iter().map(|t| t.dispatches).sum::<u64>(),
        total,
        "kernel",
        "dispatches",
        "total ms",
        "mean us",
        "share"
    );
    for t in times {
        s += &format!(
            "{:<28} {:>10} {:>12.3} {:>11.2} {:>6.1}%\n",
            t.name,
            t.dispatches,
            t.seconds * 1e3,
            t.seconds * 1e6 / t.dispatches.max(1) as f64,
            100.0 * t.seconds / total.max(1e-300)
        );
    }
    s
}
