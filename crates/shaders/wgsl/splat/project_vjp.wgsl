// VJP of `project.wgsl`, one thread per Gaussian: `r4d_splat::project::project_vjp` in f32
// with the same operation order, from dL/dProjected (`rasterize_vjp`) back to the mean, the
// log-scales, the quaternion, the opacity logit and F (through F Sigma F^T and through the
// polar rotation that turns the SH view direction). Gaussians that `project` culls (the
// culling is recomputed with the same functions) or whose upstream gradient is 0 get zeros.
//
// At most 8 storage buffers per kernel (WebGPU's default), so the results go to one f32 buffer
// in sections laid out like the gradient buffers they are copied to (`[n][width]`): dL/dmean (3), dL/dlog_scale (3), dL/dquat (4), dL/dopacity_logit (1), then for
// `project_vjp_sh` the unit direction d the SH were evaluated at (3) and dL/dcolour masked
// where the colour was clamped at 0 (3, zero when the direction is 0), then dL/dF (9, when
// deformed). dL/dsh = Y(d) (x) masked dL/dcolour is written by `project_vjp_sh.wgsl`.
#import lib/splat_project.wgsl

@group(0) @binding(0) var<uniform> cam: CameraConsts;
@group(0) @binding(1) var<uniform> pp: SplatProjectParams;
@group(0) @binding(2) var<storage, read> means: array<f32>;
@group(0) @binding(3) var<storage, read> log_scales: array<f32>;
@group(0) @binding(4) var<storage, read> quats: array<f32>;
@group(0) @binding(5) var<storage, read> opacity_logits: array<f32>;
@group(0) @binding(6) var<storage, read> sh: array<f32>;
@group(0) @binding(7) var<storage, read> fmat: array<f32>;
@group(0) @binding(8) var<storage, read> d_proj: array<ProjectedGrad>;
@group(0) @binding(9) var<storage, read_write> out: array<f32>;

const WG: u32 = 64u;

// Writes component `c` of Gaussian `g` in section `sec` of `width` values per Gaussian
// (laid out `[n][width]`, like the buffer it is copied to).
fn put(sec: u32, width: u32, g: u32, c: u32, v: f32) {
    out[sec * pp.n + width * g + c] = v;
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let g = gid.x + gid.y * nwg.x * WG;
    if g >= pp.n {
        return;
    }
    let d = d_proj[g];
    let d_mean2d = vec2<f32>(d.mean_x, d.mean_y);
    let d_color = vec3<f32>(d.color_r, d.color_g, d.color_b);
    if all(d_mean2d == vec2<f32>(0.0)) && all(d_color == vec3<f32>(0.0)) && d.conic_a == 0.0
        && d.conic_b == 0.0 && d.conic_c == 0.0 && d.opacity == 0.0 {
        return;
    }
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
    if f.ok == 0u || splat_off_screen(cam, splat_mean2d(cam, f), splat_radii(f)) {
        return;
    }

    // Colour: the SH VJP at dir = R^T (mean - campos) (`r4d_splat::sh::eval_vjp`).
    let dir_w = vec3<f32>(mean.x - cam.campos.x, mean.y - cam.campos.y, mean.z - cam.campos.z);
    var polar = rows_identity();
    var dir = dir_w;
    if has_f {
        polar = polar_rotation(fm);
        dir = mat_t_vec_rows(polar, dir_w);
    }
    var d_dir = vec3<f32>(0.0);
    var unit = vec3<f32>(0.0);
    var g_col = vec3<f32>(0.0);
    let nrm = sqrt(dir.x * dir.x + dir.y * dir.y + dir.z * dir.z);
    if nrm > 0.0 {
        unit = dir / nrm;
        let b = sh_basis(pp.sh_degree, unit);
        let gb = sh_basis_grad(pp.sh_degree, unit);
        let k = sh_count(pp.sh_degree);
        let base = g * pp.sh_len;
        // Colour before the clamp: the gradient passes where it is >= 0.
        var raw = vec3<f32>(0.5);
        for (var kk = 0u; kk < k; kk++) {
            let o = base + kk * 3u;
            raw.x += b[kk] * sh[o];
            raw.y += b[kk] * sh[o + 1u];
            raw.z += b[kk] * sh[o + 2u];
        }
        g_col = select(vec3<f32>(0.0), d_color, raw >= vec3<f32>(0.0));
        var d_d = vec3<f32>(0.0);
        for (var kk = 0u; kk < k; kk++) {
            let o = base + kk * 3u;
            var w = 0.0;
            w += sh[o] * g_col.x;
            w += sh[o + 1u] * g_col.y;
            w += sh[o + 2u] * g_col.z;
            d_d += w * gb[kk];
        }
        let dd = unit.x * d_d.x + unit.y * d_d.y + unit.z * d_d.z;
        d_dir = (d_d - unit * dd) / nrm;
    }
    for (var c = 0u; c < 3u; c++) {
        put(PV_DIR, 3u, g, c, unit[c]);
        put(PV_COLOR, 3u, g, c, g_col[c]);
    }
    var g_mean = d_dir;
    if has_f {
        g_mean = mat_vec_rows(polar, d_dir);
    }

    // Opacity.
    let sig = sigmoid(opacity_logits[g]);
    let det0 = f.cov0.x * f.cov0.z - f.cov0.y * f.cov0.y;
    let ratio = det0 / f.det;
    let aa = cam.antialiased != 0u;
    var comp = 1.0;
    if aa {
        comp = sqrt(max(ratio, 0.0));
    }
    put(PV_OPACITY, 1u, g, 0u, d.opacity * comp * sig * (1.0 - sig));

    // Conic and compensation -> 2D covariance.
    let a2 = f.cov.x;
    let b2 = f.cov.y;
    let c2 = f.cov.z;
    let det = f.det;
    let ga = d.conic_a;
    let gb = d.conic_b;
    let gc = d.conic_c;
    var g_det = -(ga * c2 - gb * b2 + gc * a2) / (det * det);
    var g_det0 = 0.0;
    if aa && ratio > 0.0 {
        let g_ratio = d.opacity * sig * 0.5 / comp;
        g_det0 = g_ratio / det;
        g_det -= g_ratio * det0 / (det * det);
    }
    if f.det_clamped != 0u {
        g_det = 0.0;
    }
    var g_a = gc / det + g_det * c2 + g_det0 * f.cov0.z;
    var g_c = ga / det + g_det * a2 + g_det0 * f.cov0.x;
    var g_b = -gb / det - 2.0 * b2 * g_det - 2.0 * f.cov0.y * g_det0;
    if !(finite(g_a) && finite(g_b) && finite(g_c)) {
        g_a = 0.0;
        g_b = 0.0;
        g_c = 0.0;
    }

    // Mean 2D.
    let fx = cam.intrinsics.x;
    let fy = cam.intrinsics.y;
    let x = f.mc.x;
    let y = f.mc.y;
    let z = f.mc.z;
    var g_mc = vec3<f32>(
        d.mean_x * fx / z,
        d.mean_y * fy / z,
        -d.mean_x * fx * x / (z * z) - d.mean_y * fy * y / (z * z),
    );
    // cov2d = J sc J^T with G2 = [[g_a, g_b/2], [g_b/2, g_c]].
    let g2 = array<array<f32, 2>, 2>(array<f32, 2>(g_a, g_b * 0.5), array<f32, 2>(g_b * 0.5, g_c));
    let jm = f.j;
    var g_sc: Rows;
    for (var a = 0u; a < 3u; a++) {
        for (var b = 0u; b < 3u; b++) {
            var s = 0.0;
            for (var p = 0u; p < 2u; p++) {
                for (var q = 0u; q < 2u; q++) {
                    s += jm[p][a] * g2[p][q] * jm[q][b];
                }
            }
            g_sc[a][b] = s;
        }
    }
    // g_J = 2 G2 J sc.
    var g_j: Jac;
    for (var p = 0u; p < 2u; p++) {
        for (var a = 0u; a < 3u; a++) {
            var s = 0.0;
            for (var q = 0u; q < 2u; q++) {
                for (var b = 0u; b < 3u; b++) {
                    s += g2[p][q] * jm[q][b] * f.sc[b][a];
                }
            }
            g_j[p][a] = 2.0 * s;
        }
    }
    let z2 = z * z;
    let z3 = z2 * z;
    g_mc.z += -fx / z2 * g_j[0][0] - fy / z2 * g_j[1][1] + 2.0 * fx * f.xc / z3 * g_j[0][2]
        + 2.0 * fy * f.yc / z3 * g_j[1][2];
    let g_xc = -fx / z2 * g_j[0][2];
    let g_yc = -fy / z2 * g_j[1][2];
    if f.clamped_x != 0u {
        g_mc.z += g_xc * f.lim_x;
    } else {
        g_mc.x += g_xc;
    }
    if f.clamped_y != 0u {
        g_mc.z += g_yc * f.lim_y;
    } else {
        g_mc.y += g_yc;
    }
    let wrot = cam_rows(cam);
    g_mean += mat_t_vec_rows(wrot, g_mc);
    for (var c = 0u; c < 3u; c++) {
        put(PV_MEAN, 3u, g, c, g_mean[c]);
    }

    // sc = W Sigma' W^T.
    let g_sigma = mul3(mul_at3(wrot, g_sc), wrot);
    var g_sigma0 = g_sigma;
    if has_f {
        let dg = deform_covariance_vjp(fm, f.sigma0, g_sigma);
        // dL/dR of dir = R^T dir_w: dir_w (x) d_dir.
        let g_polar = Rows(
            array<f32, 3>(dir_w.x * d_dir.x, dir_w.x * d_dir.y, dir_w.x * d_dir.z),
            array<f32, 3>(dir_w.y * d_dir.x, dir_w.y * d_dir.y, dir_w.y * d_dir.z),
            array<f32, 3>(dir_w.z * d_dir.x, dir_w.z * d_dir.y, dir_w.z * d_dir.z),
        );
        let g_f = add3(dg.f, polar_rotation_vjp(fm, polar, g_polar));
        for (var r = 0u; r < 3u; r++) {
            for (var c = 0u; c < 3u; c++) {
                put(PV_F, 9u, g, 3u * r + c, g_f[r][c]);
            }
        }
        g_sigma0 = dg.sigma;
    }
    let cg = covariance_vjp(ls, quat, g_sigma0);
    for (var c = 0u; c < 3u; c++) {
        put(PV_LOG_SCALE, 3u, g, c, cg.log_scale[c]);
    }
    for (var c = 0u; c < 4u; c++) {
        put(PV_QUAT, 4u, g, c, cg.quat[c]);
    }
}
