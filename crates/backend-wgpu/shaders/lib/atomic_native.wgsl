// Scatter-add with native float atomics (adapter feature SHADER_FLOAT32_ATOMIC).
alias AtomicF32 = atomic<f32>;

fn atomic_add_f32(p: ptr<storage, atomic<f32>, read_write>, v: f32) {
    atomicAdd(p, v);
}
