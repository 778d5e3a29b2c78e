// Grid node update: momentum to velocity, gravity, damping, boundary conditions in order.
// Mirrors `r4d_mpm::transfer::grid_node_update`.
#import lib/transfer.wgsl

@group(0) @binding(0) var<uniform> c: StepConsts;
@group(0) @binding(1) var<uniform> counts: Counts;
@group(0) @binding(2) var<storage, read> bcs: array<GridBc>;
@group(0) @binding(3) var<storage, read_write> nodes: array<vec4<f32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let idx = linear_id(gid, nwg, 64u);
    let n = counts.n_grid;
    if idx >= n * n * n {
        return;
    }
    let ijk = vec3<u32>(idx / (n * n), (idx / n) % n, idx % n);
    let node = nodes[idx];
    let m = node.w;
    var v = vec3<f32>(0.0);
    if m > 1e-15 {
        let inv = 1.0 / m;
        v = node.xyz * inv + c.dt * c.gravity;
    }
    if c.grid_v_damping < 1.0 {
        v = v * c.grid_v_damping;
    }
    for (var b = 0u; b < c.n_grid_bcs; b++) {
        v = apply_grid_bc(ijk, v, bcs[b], c);
    }
    nodes[idx] = vec4<f32>(v, m);
}
