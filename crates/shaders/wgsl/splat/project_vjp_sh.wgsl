// dL/dsh of `project_vjp`, one thread per Gaussian: `dL/dsh[k][c] = Y_k(d) g_c` with the unit
// direction d and the clamp-masked dL/dcolour g that `project_vjp.wgsl` left in its output
// sections (as `r4d_splat::sh::eval_vjp` adds them; zeros where g is 0, which covers culled
// Gaussians and a zero direction).
#import lib/splat_project.wgsl

@group(0) @binding(0) var<uniform> pp: SplatProjectParams;
@group(0) @binding(1) var<storage, read> packed: array<f32>;
@group(0) @binding(2) var<storage, read_write> d_sh: array<f32>;

const WG: u32 = 64u;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let g = gid.x + gid.y * nwg.x * WG;
    if g >= pp.n {
        return;
    }
    let di = PV_DIR * pp.n + 3u * g;
    let ci = PV_COLOR * pp.n + 3u * g;
    let gc = vec3<f32>(packed[ci], packed[ci + 1u], packed[ci + 2u]);
    if all(gc == vec3<f32>(0.0)) {
        return;
    }
    let b = sh_basis(pp.sh_degree, vec3<f32>(packed[di], packed[di + 1u], packed[di + 2u]));
    let k = sh_count(pp.sh_degree);
    let base = g * pp.sh_len;
    for (var kk = 0u; kk < k; kk++) {
        d_sh[base + 3u * kk] = b[kk] * gc.x;
        d_sh[base + 3u * kk + 1u] = b[kk] * gc.y;
        d_sh[base + 3u * kk + 2u] = b[kk] * gc.z;
    }
}
