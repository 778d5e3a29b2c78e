// Scatter-add without float atomics: a compare-exchange loop on the bit pattern. The kernel
// declares `grid_atomic: array<AtomicF32>`.
alias AtomicF32 = atomic<u32>;

fn grid_add(i: u32, v: f32) {
    var old = atomicLoad(&grid_atomic[i]);
    loop {
        let r = atomicCompareExchangeWeak(&grid_atomic[i], old, bitcast<u32>(bitcast<f32>(old) + v));
        if r.exchanged {
            break;
        }
        old = r.old_value;
    }
}
