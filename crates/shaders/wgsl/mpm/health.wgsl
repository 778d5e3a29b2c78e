// After g2p: moves the substep's first problem (lowest particle index) into the frame's health
// record unless an earlier substep already filled it, and re-arms `scratch[0]`.
#import lib/structs.wgsl

@group(0) @binding(0) var<uniform> c: StepConsts;
@group(0) @binding(1) var<storage, read_write> scratch: array<atomic<u32>>;
@group(0) @binding(2) var<storage, read_write> health: Health;

@compute @workgroup_size(1)
fn main() {
    let m = atomicLoad(&scratch[0]);
    if m == 0xffffffffu {
        return;
    }
    if atomicLoad(&health.code) == 0u {
        atomicStore(&health.code, atomicLoad(&scratch[1u + 2u * m]));
        health.substep = c.substep;
        health.particle = m;
        health.value_bits = atomicLoad(&scratch[2u + 2u * m]);
    }
    atomicStore(&scratch[0], 0xffffffffu);
}
