//! A counting global allocator for peak-memory figures (the `r4d` binary and the benches
//! install it; an embedding program may too). Without it installed the counters stay 0 and
//! [`installed`] is false.
//!
//! Library code measures a stretch of work with a [`Watch`] (up to [`WATCHES`] at once, each
//! with its own peak, none resetting another's or the global one): concurrent measurements —
//! initialisation candidates evaluated in parallel — each see the process's true peak over
//! their own interval. [`reset_peak`] (benches, one measurement at a time) resets the global
//! peak only.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

/// How many [`Watch`]es can run at once.
pub const WATCHES: usize = 64;
/// Peak live bytes of each running [`Watch`].
static WATCH_PEAK: [AtomicUsize; WATCHES] = [const { AtomicUsize::new(0) }; WATCHES];
/// Bit `i` set: watch slot `i` is running.
static ACTIVE: AtomicU64 = AtomicU64::new(0);

/// Counts live and peak heap bytes.
pub struct Counting;
/// Bytes currently allocated.
pub static LIVE: AtomicUsize = AtomicUsize::new(0);
/// Highest value of `LIVE` since the last [`reset_peak`].
pub static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        // SAFETY: forwarded to the system allocator with the caller's layout.
        let p = unsafe { System.alloc(l) };
        if !p.is_null() {
            let now = LIVE.fetch_add(l.size(), Ordering::Relaxed) + l.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
            let mut m = ACTIVE.load(Ordering::Relaxed);
            while m != 0 {
                WATCH_PEAK[m.trailing_zeros() as usize].fetch_max(now, Ordering::Relaxed);
                m &= m - 1;
            }
        }
        p
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        // SAFETY: `p` was allocated by `alloc` above with this layout.
        unsafe { System.dealloc(p, l) };
        LIVE.fetch_sub(l.size(), Ordering::Relaxed);
    }
}

/// Starts a new peak measurement; returns the live bytes it is relative to.
pub fn reset_peak() -> usize {
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    base
}

/// Peak bytes above `base` since the last [`reset_peak`].
pub fn peak_since(base: usize) -> usize {
    PEAK.load(Ordering::Relaxed).saturating_sub(base)
}

/// True when [`Counting`] is the global allocator (something has been counted).
pub fn installed() -> bool {
    PEAK.load(Ordering::Relaxed) > 0 || LIVE.load(Ordering::Relaxed) > 0
}

/// Peak live bytes since program start or the last [`reset_peak`].
pub fn peak() -> usize {
    PEAK.load(Ordering::Relaxed)
}

/// A running peak measurement ([`Watch::start`]); its slot is freed when dropped.
#[derive(Debug)]
pub struct Watch {
    slot: Option<usize>,
    base: usize,
}

impl Watch {
    /// Starts measuring the peak of live heap bytes from now on (starting at the live bytes
    /// now). When [`WATCHES`] are already running this one measures nothing ([`Watch::peak`]
    /// gives 0) rather than disturbing the others.
    pub fn start() -> Watch {
        let mut cur = ACTIVE.load(Ordering::Relaxed);
        loop {
            let free = (!cur).trailing_zeros() as usize;
            let base = LIVE.load(Ordering::Relaxed);
            if free >= WATCHES {
                return Watch { slot: None, base };
            }
            WATCH_PEAK[free].store(base, Ordering::Relaxed);
            match ACTIVE.compare_exchange_weak(
                cur,
                cur | (1 << free),
                Ordering::AcqRel,
                Ordering::Relaxed,
            ) {
                Ok(_) => {
                    // Allocations between the store and the claim are covered by this max.
                    WATCH_PEAK[free].fetch_max(LIVE.load(Ordering::Relaxed), Ordering::Relaxed);
                    return Watch {
                        slot: Some(free),
                        base,
                    };
                }
                Err(now) => cur = now,
            }
        }
    }

    /// The live heap bytes when the watch started.
    pub fn base(&self) -> usize {
        self.base
    }

    /// The highest live heap bytes (absolute, not relative to the start) since
    /// [`Watch::start`]; 0 when the counting allocator is not installed or no slot was free.
    pub fn peak(&self) -> usize {
        self.slot
            .map_or(0, |i| WATCH_PEAK[i].load(Ordering::Relaxed))
    }
}

impl r4d_optim::HeapSpan for Watch {
    fn base(&self) -> usize {
        self.base
    }
    fn peak(&self) -> usize {
        Watch::peak(self)
    }
}

/// The [`r4d_optim::HeapProbe`] of the counting allocator: each measurement is a [`Watch`]
/// (0 when the allocator is not installed).
#[derive(Clone, Copy, Debug, Default)]
pub struct CountingProbe;

impl r4d_optim::HeapProbe for CountingProbe {
    fn start(&self) -> Box<dyn r4d_optim::HeapSpan> {
        Box::new(Watch::start())
    }
}

impl Drop for Watch {
    fn drop(&mut self) {
        if let Some(i) = self.slot {
            ACTIVE.fetch_and(!(1 << i), Ordering::AcqRel);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn watches_are_independent_and_freed() {
        let a = Watch::start();
        let b = Watch::start();
        assert_ne!(a.slot, b.slot);
        let (sa, sb) = (a.slot.unwrap(), b.slot.unwrap());
        drop(a);
        assert_eq!(ACTIVE.load(Ordering::Relaxed) & (1 << sa), 0);
        assert_ne!(ACTIVE.load(Ordering::Relaxed) & (1 << sb), 0);
        // All slots taken: a further watch measures nothing and disturbs nobody.
        let many: Vec<Watch> = (0..WATCHES).map(|_| Watch::start()).collect();
        assert!(many.iter().filter(|w| w.slot.is_none()).count() >= 1);
        drop(many);
        drop(b);
    }
}
