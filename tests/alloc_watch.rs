//! Peak-memory watches with the counting allocator installed: concurrent watches each see the
//! process's peak over their own interval, and none resets another's or the global peak.

use resonance4d::alloc::{peak, Counting, Watch, LIVE};
use std::sync::atomic::Ordering;
use std::sync::{Arc, Barrier};

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn concurrent_watches_do_not_disturb_each_other() {
    const MB: usize = 1 << 20;
    let outer = Watch::start();
    let global_before = peak();
    let barrier = Arc::new(Barrier::new(2));
    let b2 = barrier.clone();
    // Thread A allocates 64 MiB inside its watch; thread B starts its watch after A freed it.
    let a = std::thread::spawn(move || {
        let w = Watch::start();
        let base = LIVE.load(Ordering::Relaxed);
        let v = vec![1u8; 64 * MB];
        std::hint::black_box(&v);
        drop(v);
        b2.wait();
        w.peak().saturating_sub(base)
    });
    barrier.wait();
    let b = std::thread::spawn(|| {
        let w = Watch::start();
        let base = LIVE.load(Ordering::Relaxed);
        let v = vec![1u8; 8 * MB];
        std::hint::black_box(&v);
        drop(v);
        w.peak().saturating_sub(base)
    });
    let (pa, pb) = (a.join().unwrap(), b.join().unwrap());
    assert!(pa >= 64 * MB, "{pa}");
    // B's interval began after A's 64 MiB were freed: it sees its own 8 MiB (and whatever the
    // test harness allocates meanwhile), not A's.
    assert!((8 * MB..40 * MB).contains(&pb), "{pb}");
    // The outer watch spans both; the global peak was never reset.
    assert!(outer.peak() >= pa.max(pb));
    assert!(peak() >= global_before.max(64 * MB));
}
