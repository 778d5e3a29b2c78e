// Moves the simulated Gaussians to a simulated frame (one thread per simulated particle):
// `r4d_splat::link::link_point` and `link_f` in f32, the same operation order. Positions and
// deformation gradients (row-major) come straight from the simulation's state buffers; every
// Gaussian no particle moves is left as it is.
#import lib/splat_structs.wgsl

@group(0) @binding(0) var<uniform> lc: LinkConsts;
@group(0) @binding(1) var<storage, read> simulated: array<u32>;
@group(0) @binding(2) var<storage, read> x: array<f32>;
@group(0) @binding(3) var<storage, read> f_sim: array<f32>;
@group(0) @binding(4) var<storage, read_write> means: array<f32>;
@group(0) @binding(5) var<storage, read_write> fw: array<f32>;

const WG: u32 = 64u;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let s = gid.x + gid.y * nwg.x * WG;
    if s >= lc.simulated {
        return;
    }
    let g = simulated[s];
    let p = vec3<f32>(x[3u * s], x[3u * s + 1u], x[3u * s + 2u]);
    for (var i = 0u; i < 3u; i++) {
        let a = lc.to_world[i];
        means[3u * g + i] = a.x * p.x + a.y * p.y + a.z * p.z + a.w;
    }
    // F R, then R^T (F R).
    var fr: array<vec3<f32>, 3>;
    for (var i = 0u; i < 3u; i++) {
        let f0 = f_sim[9u * s + 3u * i];
        let f1 = f_sim[9u * s + 3u * i + 1u];
        let f2 = f_sim[9u * s + 3u * i + 2u];
        fr[i] = f0 * lc.rot[0].xyz + f1 * lc.rot[1].xyz + f2 * lc.rot[2].xyz;
    }
    for (var i = 0u; i < 3u; i++) {
        for (var j = 0u; j < 3u; j++) {
            fw[9u * g + 3u * i + j] =
                lc.rot[0][i] * fr[0][j] + lc.rot[1][i] * fr[1][j] + lc.rot[2][i] * fr[2][j];
        }
    }
}
