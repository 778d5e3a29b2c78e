//! Per-kernel GPU time from timestamp queries (`VulkanEngine::set_profiling`): a query pool
//! of [`PAIRS`] start/end pairs, reset at the start of each command buffer; every dispatch
//! recorded while profiling is on is bracketed by two timestamps (top and bottom of the pipe;
//! the full barrier between commands keeps dispatches from overlapping, so the difference is
//! the kernel's own time); after the submission's fence the pairs are read back and summed
//! per kernel.

use crate::VulkanError;
use ash::vk;
use r4d_mpm::kernels::KernelTime;
use std::collections::BTreeMap;

/// Dispatches timed per submission; a submission with more is submitted early.
pub(crate) const PAIRS: u32 = 4096;

/// The query pool and what it has measured.
pub(crate) struct Profiler {
    pool: vk::QueryPool,
    /// Nanoseconds per timestamp tick (`VkPhysicalDeviceLimits::timestampPeriod`).
    period_ns: f64,
    /// The valid bits of a timestamp (`VkQueueFamilyProperties::timestampValidBits`).
    mask: u64,
    /// The kernel of each pair written into the pending command buffer, in order.
    pub pending: Vec<&'static str>,
    /// Dispatches and seconds per kernel so far.
    totals: BTreeMap<&'static str, (u64, f64)>,
}

impl Profiler {
    /// A profiler on `d`; `None` when the queue family has no timestamps.
    pub fn new(
        d: &ash::Device,
        period_ns: f32,
        valid_bits: u32,
    ) -> Result<Option<Self>, VulkanError> {
        if valid_bits == 0 || period_ns <= 0.0 {
            return Ok(None);
        }
        // SAFETY: a valid create info; destroyed by `destroy`.
        let pool = unsafe {
            d.create_query_pool(
                &vk::QueryPoolCreateInfo::default()
                    .query_type(vk::QueryType::TIMESTAMP)
                    .query_count(2 * PAIRS),
                None,
            )
        }
        .map_err(|result| VulkanError::Vk {
            what: "vkCreateQueryPool",
            result,
        })?;
        Ok(Some(Profiler {
            pool,
            period_ns: period_ns as f64,
            mask: if valid_bits >= 64 {
                u64::MAX
            } else {
                (1u64 << valid_bits) - 1
            },
            pending: Vec::new(),
            totals: BTreeMap::new(),
        }))
    }

    /// Records the pool's reset at the start of a command buffer.
    pub fn begin(&self, d: &ash::Device, cb: vk::CommandBuffer) {
        // SAFETY: cb is recording, outside any render pass.
        unsafe { d.cmd_reset_query_pool(cb, self.pool, 0, 2 * PAIRS) };
    }

    /// Room left in the pending command buffer, in pairs.
    pub fn room(&self) -> usize {
        PAIRS as usize - self.pending.len()
    }

    /// Writes the start (`end = false`) or end timestamp of pending pair `pair`.
    pub fn stamp(&self, d: &ash::Device, cb: vk::CommandBuffer, pair: usize, end: bool) {
        let stage = if end {
            vk::PipelineStageFlags::BOTTOM_OF_PIPE
        } else {
            vk::PipelineStageFlags::TOP_OF_PIPE
        };
        // SAFETY: cb is recording; the query was reset at its start and is written once.
        unsafe { d.cmd_write_timestamp(cb, stage, self.pool, 2 * pair as u32 + end as u32) };
    }

    /// Reads the pending pairs back (after the submission's fence) and adds them up.
    pub fn resolve(&mut self, d: &ash::Device) -> Result<(), VulkanError> {
        if self.pending.is_empty() {
            return Ok(());
        }
        let mut ticks = vec![0u64; 2 * self.pending.len()];
        // SAFETY: the submission that wrote these queries has completed.
        let read = unsafe {
            d.get_query_pool_results(
                self.pool,
                0,
                &mut ticks,
                vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
            )
        };
        if let Err(result) = read {
            self.pending.clear();
            return Err(VulkanError::Vk {
                what: "vkGetQueryPoolResults",
                result,
            });
        }
        for (k, name) in self.pending.drain(..).enumerate() {
            let dt = ticks[2 * k + 1].wrapping_sub(ticks[2 * k]) & self.mask;
            let e = self.totals.entry(name).or_default();
            e.0 += 1;
            e.1 += dt as f64 * self.period_ns * 1e-9;
        }
        Ok(())
    }

    /// What has been measured, slowest kernel first.
    pub fn times(&self) -> Vec<KernelTime> {
        let mut v: Vec<KernelTime> = self
            .totals
            .iter()
            .map(|(name, &(dispatches, seconds))| KernelTime {
                name: name.to_string(),
                dispatches,
                seconds,
            })
            .collect();
        v.sort_by(|a, b| b.seconds.total_cmp(&a.seconds));
        v
    }

    /// Destroys the pool (no submission may be pending).
    pub fn destroy(self, d: &ash::Device) {
        // SAFETY: nothing pending uses the pool.
        unsafe { d.destroy_query_pool(self.pool, None) };
    }
}
