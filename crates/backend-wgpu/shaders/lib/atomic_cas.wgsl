// Scatter-add without float atomics: a compare-exchange loop on the bit pattern.
alias AtomicF32 = atomic<u32>;

fn atomic_add_f32(p: ptr<storage, atomic<u32>, read_write>, v: f32) {
    var old = atomicLoad(p);
    loop {
        let r = atomicCompareExchangeWeak(p, old, bitcast<u32>(bitcast<f32>(old) + v));
        if r.exchanged {
            break;
        }
        old = r.old_value;
    }
}
