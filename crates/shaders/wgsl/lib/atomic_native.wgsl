// Scatter-add with native float atomics (adapter feature SHADER_FLOAT32_ATOMIC). The kernel
// declares `grid_atomic: array<AtomicF32>`.
alias AtomicF32 = atomic<f32>;

fn grid_add(i: u32, v: f32) {
    atomicAdd(&grid_atomic[i], v);
}
