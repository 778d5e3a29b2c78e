// VJP of `link_deform` (one thread per simulated particle): `r4d_splat::link::link_point_vjp`
// and `link_f_vjp` in f32, added to the particle gradients `dx`, `df_sim` (row-major; each
// particle is written by its own thread only, filling particles not at all).
#import lib/splat_structs.wgsl

@group(0) @binding(0) var<uniform> lc: LinkConsts;
@group(0) @binding(1) var<storage, read> simulated: array<u32>;
@group(0) @binding(2) var<storage, read> d_means: array<f32>;
@group(0) @binding(3) var<storage, read> d_f: array<f32>;
@group(0) @binding(4) var<storage, read_write> dx: array<f32>;
@group(0) @binding(5) var<storage, read_write> df_sim: array<f32>;

const WG: u32 = 64u;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let s = gid.x + gid.y * nwg.x * WG;
    if s >= lc.simulated {
        return;
    }
    let g = simulated[s];
    let gm = vec3<f32>(d_means[3u * g], d_means[3u * g + 1u], d_means[3u * g + 2u]);
    for (var a = 0u; a < 3u; a++) {
        let r = lc.rot[a];
        dx[3u * s + a] += (r.x * gm.x + r.y * gm.y + r.z * gm.z) * lc.inv_scale;
    }
    // R G, then (R G) R^T.
    var rg: array<vec3<f32>, 3>;
    for (var a = 0u; a < 3u; a++) {
        var row = vec3<f32>(0.0);
        for (var e = 0u; e < 3u; e++) {
            row[e] = lc.rot[a].x * d_f[9u * g + e] + lc.rot[a].y * d_f[9u * g + 3u + e]
                + lc.rot[a].z * d_f[9u * g + 6u + e];
        }
        rg[a] = row;
    }
    for (var a = 0u; a < 3u; a++) {
        for (var b = 0u; b < 3u; b++) {
            df_sim[9u * s + 3u * a + b] +=
                rg[a].x * lc.rot[b].x + rg[a].y * lc.rot[b].y + rg[a].z * lc.rot[b].z;
        }
    }
}
