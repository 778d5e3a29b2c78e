// Projects every Gaussian (one thread each): `r4d_splat::project::project` in f32, with the
// same operation order. 3D covariance from the normalised quaternion and log-scales,
// optionally deformed (`F Sigma F^T`, SH evaluated at `R^T d` with R the polar rotation of F,
// from a cyclic-Jacobi eigen-decomposition of `F^T F` as in `r4d_splat::covariance`, here in
// f32), camera transform, Jacobian with the frustum clamp, 2D covariance + 0.3, det clamp,
// conic, radii `ceil(3.33 sqrt)`, culling, opacity (antialiased compensation) and SH colour.
// Culled Gaussians get an all-zero record (radii (0, 0)). The math is in
// lib/splat_project.wgsl, shared with `project_vjp.wgsl`.
#import lib/splat_project.wgsl

@group(0) @binding(0) var<uniform> cam: CameraConsts;
@group(0) @binding(1) var<uniform> pp: SplatProjectParams;
@group(0) @binding(2) var<storage, read> means: array<f32>;
@group(0) @binding(3) var<storage, read> log_scales: array<f32>;
@group(0) @binding(4) var<storage, read> quats: array<f32>;
@group(0) @binding(5) var<storage, read> opacity_logits: array<f32>;
@group(0) @binding(6) var<storage, read> sh: array<f32>;
@group(0) @binding(7) var<storage, read> fmat: array<f32>;
@group(0) @binding(8) var<storage, read_write> out: array<Projected>;

const WG: u32 = 64u;

// max(sum_k Y_k(normalize(dir)) sh[k][c] + 0.5, 0) for Gaussian `g`.
fn sh_color(g: u32, dir: vec3<f32>) -> vec3<f32> {
    let nrm = sqrt(dir.x * dir.x + dir.y * dir.y + dir.z * dir.z);
    var dd = vec3<f32>(0.0);
    if nrm > 0.0 {
        dd = dir / nrm;
    }
    let b = sh_basis(pp.sh_degree, dd);
    let k = sh_count(pp.sh_degree);
    let base = g * pp.sh_len;
    var col = vec3<f32>(0.5);
    for (var kk = 0u; kk < k; kk++) {
        let o = base + kk * 3u;
        col.x += b[kk] * sh[o];
        col.y += b[kk] * sh[o + 1u];
        col.z += b[kk] * sh[o + 2u];
    }
    return max(col, vec3<f32>(0.0));
}

fn project_one(g: u32) -> Projected {
    var culled: Projected;
    let mean = vec3<f32>(means[3u * g], means[3u * g + 1u], means[3u * g + 2u]);
    let ls = vec3<f32>(log_scales[3u * g], log_scales[3u * g + 1u], log_scales[3u * g + 2u]);
    let quat = vec4<f32>(quats[4u * g], quats[4u * g + 1u], quats[4u * g + 2u], quats[4u * g + 3u]);
    var fm = rows_identity();
    let has_f = pp.has_f != 0u;
    if has_f {
        for (var i = 0u; i < 3u; i++) {
            for (var j = 0u; j < 3u; j++) {
                fm[i][j] = fmat[9u * g + 3u * i + j];
            }
        }
    }
    let f = splat_forward(cam, mean, ls, quat, has_f, fm);
    if f.ok == 0u {
        return culled;
    }
    let uv = splat_mean2d(cam, f);
    let r = splat_radii(f);
    if splat_off_screen(cam, uv, r) {
        return culled;
    }
    var opacity = sigmoid(opacity_logits[g]);
    if cam.antialiased != 0u {
        let det0 = f.cov0.x * f.cov0.z - f.cov0.y * f.cov0.y;
        let ratio = det0 / f.det;
        opacity *= sqrt(select(0.0, ratio, ratio > 0.0));
    }
    var dir = vec3<f32>(mean.x - cam.campos.x, mean.y - cam.campos.y, mean.z - cam.campos.z);
    if has_f {
        dir = mat_t_vec_rows(polar_rotation(fm), dir);
    }
    let col = sh_color(g, dir);
    var p: Projected;
    p.mean_x = uv.x;
    p.mean_y = uv.y;
    p.conic_a = f.cov.z / f.det;
    p.conic_b = -f.cov.y / f.det;
    p.conic_c = f.cov.x / f.det;
    p.depth = f.mc.z;
    p.opacity = opacity;
    p.color_r = col.x;
    p.color_g = col.y;
    p.color_b = col.z;
    // `to_u32` fails (-> 0) above u32::MAX.
    p.radius_x = select(u32(r.x), 0u, r.x >= 4294967296.0);
    p.radius_y = select(u32(r.y), 0u, r.y >= 4294967296.0);
    return p;
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let g = gid.x + gid.y * nwg.x * WG;
    if g >= pp.n {
        return;
    }
    out[g] = project_one(g);
}
