// Projects every Gaussian (one thread each): `r4d_splat::project::project` in f32, with the
// same operation order. 3D covariance from the normalised quaternion and log-scales,
// optionally deformed (`F Sigma F^T`, SH evaluated at `R^T d` with R the polar rotation of F,
// from a cyclic-Jacobi eigen-decomposition of `F^T F` as in `r4d_splat::covariance`, here in
// f32), camera transform, Jacobian with the frustum clamp, 2D covariance + 0.3, det clamp,
// conic, radii `ceil(3.33 sqrt)`, culling, opacity (antialiased compensation) and SH colour.
// Culled Gaussians get an all-zero record (radii (0, 0)).
//
// Matrices are WGSL `mat3x3<f32>` holding the same mathematical matrix as the Rust row-major
// `[[f32; 3]; 3]` (column j = `m[j]`).
#import lib/splat_structs.wgsl

struct SplatProjectParams {
    n: u32,
    has_f: u32,
    sh_degree: u32,
    // SH values per Gaussian (K * 3).
    sh_len: u32,
}

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
const EPS2D: f32 = 0.3;
const RADIUS_SIGMAS: f32 = 3.33;

const SH_C0: f32 = 0.28209479177387814;
const SH_C1: f32 = 0.4886025119029199;
const SH_C2A: f32 = 1.0925484305920792;
const SH_C6: f32 = 0.31539156525252005;
const SH_C8: f32 = 0.5462742152960396;
const SH_C9: f32 = 0.5900435899266435;
const SH_C10: f32 = 2.890611442640554;
const SH_C11: f32 = 0.4570457994644658;
const SH_C12: f32 = 0.3731763325901154;
const SH_C14: f32 = 1.445305721320277;

// Row-major 3x3 in function memory (dynamic indexing by the Jacobi sweep).
alias Rows = array<array<f32, 3>, 3>;

// `a b` with the reference's summation order.
fn mul3(a: Rows, b: Rows) -> Rows {
    var m: Rows;
    for (var i = 0u; i < 3u; i++) {
        for (var j = 0u; j < 3u; j++) {
            var s = 0.0;
            for (var k = 0u; k < 3u; k++) {
                s += a[i][k] * b[k][j];
            }
            m[i][j] = s;
        }
    }
    return m;
}

fn transpose3(a: Rows) -> Rows {
    var m: Rows;
    for (var i = 0u; i < 3u; i++) {
        for (var j = 0u; j < 3u; j++) {
            m[i][j] = a[j][i];
        }
    }
    return m;
}

fn det_rows(m: Rows) -> f32 {
    return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
}

fn mat_vec_rows(m: Rows, v: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(
        m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z,
        m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z,
        m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z,
    );
}

fn mat_t_vec_rows(m: Rows, v: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(
        m[0][0] * v.x + m[1][0] * v.y + m[2][0] * v.z,
        m[0][1] * v.x + m[1][1] * v.y + m[2][1] * v.z,
        m[0][2] * v.x + m[1][2] * v.y + m[2][2] * v.z,
    );
}

fn quat_to_rot(q: vec4<f32>) -> Rows {
    let w = q.x;
    let x = q.y;
    let y = q.z;
    let z = q.w;
    return Rows(
        array<f32, 3>(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)),
        array<f32, 3>(2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)),
        array<f32, 3>(2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)),
    );
}

// Sigma = R diag(exp s)^2 R^T.
fn covariance(ls: vec3<f32>, quat: vec4<f32>) -> Rows {
    let n = sqrt(quat.x * quat.x + quat.y * quat.y + quat.z * quat.z + quat.w * quat.w);
    let r = quat_to_rot(quat / n);
    let s = array<f32, 3>(exp(ls.x), exp(ls.y), exp(ls.z));
    var m = r;
    for (var i = 0u; i < 3u; i++) {
        for (var j = 0u; j < 3u; j++) {
            m[i][j] = r[i][j] * s[j];
        }
    }
    return mul3(m, transpose3(m));
}

// Rust `f32::signum`: +1 for +0, -1 for -0.
fn signum(x: f32) -> f32 {
    return select(1.0, -1.0, (bitcast<u32>(x) & 0x80000000u) != 0u);
}

// One Jacobi rotation zeroing a[p][q].
fn jacobi_rotate(a: ptr<function, Rows>, v: ptr<function, Rows>, p: u32, q: u32) {
    let apq = (*a)[p][q];
    if apq == 0.0 {
        return;
    }
    let theta = ((*a)[q][q] - (*a)[p][p]) / (2.0 * apq);
    let t = signum(theta) / (abs(theta) + sqrt(theta * theta + 1.0));
    let c = 1.0 / sqrt(t * t + 1.0);
    let s = t * c;
    for (var k = 0u; k < 3u; k++) {
        let akp = (*a)[k][p];
        let akq = (*a)[k][q];
        (*a)[k][p] = c * akp - s * akq;
        (*a)[k][q] = s * akp + c * akq;
    }
    for (var k = 0u; k < 3u; k++) {
        let apk = (*a)[p][k];
        let aqk = (*a)[q][k];
        (*a)[p][k] = c * apk - s * aqk;
        (*a)[q][k] = s * apk + c * aqk;
    }
    for (var k = 0u; k < 3u; k++) {
        let vkp = (*v)[k][p];
        let vkq = (*v)[k][q];
        (*v)[k][p] = c * vkp - s * vkq;
        (*v)[k][q] = s * vkp + c * vkq;
    }
}

// The polar rotation R of F = R S (det R = +1), as `r4d_splat::covariance::polar_rotation`:
// eigenvectors V of F^T F (descending eigenvalues, a proper rotation), u0 = F v0 / s0,
// u1 = F v1 orthogonalised against u0, u2 = u0 x u1, R = U V^T. In f32, so the Jacobi sweep
// stops at f32 rounding level instead of the reference's f64 threshold.
fn polar_rotation(f: Rows) -> Rows {
    var a = mul3(transpose3(f), f);
    var v = Rows(array<f32, 3>(1.0, 0.0, 0.0), array<f32, 3>(0.0, 1.0, 0.0), array<f32, 3>(0.0, 0.0, 1.0));
    var scale = 0.0;
    for (var i = 0u; i < 3u; i++) {
        for (var j = 0u; j < 3u; j++) {
            scale = max(scale, abs(a[i][j]));
        }
    }
    for (var sweep = 0u; sweep < 60u; sweep++) {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        if !(off > max(1e-15 * scale * scale, 1.1754944e-38)) {
            break;
        }
        jacobi_rotate(&a, &v, 0u, 1u);
        jacobi_rotate(&a, &v, 0u, 2u);
        jacobi_rotate(&a, &v, 1u, 2u);
    }
    // Stable sort of the indices by descending eigenvalue.
    var idx = array<u32, 3>(0u, 1u, 2u);
    for (var i = 1u; i < 3u; i++) {
        var j = i;
        loop {
            if j == 0u {
                break;
            }
            let cur = idx[j];
            let prev = idx[j - 1u];
            if a[cur][cur] > a[prev][prev] {
                idx[j] = prev;
                idx[j - 1u] = cur;
                j -= 1u;
            } else {
                break;
            }
        }
    }
    var lam: array<f32, 3>;
    var vs: Rows;
    for (var c = 0u; c < 3u; c++) {
        let i = idx[c];
        lam[c] = a[i][i];
        for (var r = 0u; r < 3u; r++) {
            vs[r][c] = v[r][i];
        }
    }
    if det_rows(vs) < 0.0 {
        for (var r = 0u; r < 3u; r++) {
            vs[r][2] = -vs[r][2];
        }
    }
    let sig0 = sqrt(max(lam[0], 0.0));
    let sig0_bits = bitcast<u32>(sig0) & 0x7fffffffu;
    if sig0_bits >= 0x7f800000u || sig0 <= 0.0 {
        return Rows(array<f32, 3>(1.0, 0.0, 0.0), array<f32, 3>(0.0, 1.0, 0.0), array<f32, 3>(0.0, 0.0, 1.0));
    }
    let v0 = vec3<f32>(vs[0][0], vs[1][0], vs[2][0]);
    let v1 = vec3<f32>(vs[0][1], vs[1][1], vs[2][1]);
    let u0 = mat_vec_rows(f, v0) / sig0;
    var u1 = mat_vec_rows(f, v1);
    let d = u1.x * u0.x + u1.y * u0.y + u1.z * u0.z;
    u1 = u1 - d * u0;
    let n1 = sqrt(u1.x * u1.x + u1.y * u1.y + u1.z * u1.z);
    if n1 > 1e-12 * sig0 {
        u1 = u1 / n1;
    } else {
        // Rank 1: any unit vector orthogonal to u0.
        var e = vec3<f32>(0.0, 1.0, 0.0);
        if abs(u0.x) < 0.9 {
            e = vec3<f32>(1.0, 0.0, 0.0);
        }
        let c = cross(u0, e);
        u1 = c / sqrt(c.x * c.x + c.y * c.y + c.z * c.z);
    }
    let u2 = cross(u0, u1);
    let u = Rows(
        array<f32, 3>(u0.x, u1.x, u2.x),
        array<f32, 3>(u0.y, u1.y, u2.y),
        array<f32, 3>(u0.z, u1.z, u2.z),
    );
    return mul3(u, transpose3(vs));
}

// max(sum_k Y_k(normalize(dir)) sh[k][c] + 0.5, 0) for Gaussian `g`.
fn sh_color(g: u32, dir: vec3<f32>) -> vec3<f32> {
    let nrm = sqrt(dir.x * dir.x + dir.y * dir.y + dir.z * dir.z);
    var dd = vec3<f32>(0.0);
    if nrm > 0.0 {
        dd = dir / nrm;
    }
    let x = dd.x;
    let y = dd.y;
    let z = dd.z;
    let deg = pp.sh_degree;
    var b: array<f32, 16>;
    b[0] = SH_C0;
    if deg >= 1u {
        b[1] = -SH_C1 * y;
        b[2] = SH_C1 * z;
        b[3] = -SH_C1 * x;
    }
    if deg >= 2u {
        let xx = x * x;
        let yy = y * y;
        let zz = z * z;
        b[4] = SH_C2A * x * y;
        b[5] = -SH_C2A * y * z;
        b[6] = SH_C6 * (2.0 * zz - xx - yy);
        b[7] = -SH_C2A * x * z;
        b[8] = SH_C8 * (xx - yy);
    }
    if deg >= 3u {
        let xx = x * x;
        let yy = y * y;
        let zz = z * z;
        b[9] = -SH_C9 * y * (3.0 * xx - yy);
        b[10] = SH_C10 * x * y * z;
        b[11] = -SH_C11 * y * (4.0 * zz - xx - yy);
        b[12] = SH_C12 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
        b[13] = -SH_C11 * x * (4.0 * zz - xx - yy);
        b[14] = SH_C14 * z * (xx - yy);
        b[15] = -SH_C9 * x * (xx - 3.0 * yy);
    }
    let k = min((deg + 1u) * (deg + 1u), 16u);
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

fn finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7fffffffu) < 0x7f800000u;
}

fn project_one(g: u32) -> Projected {
    var culled: Projected;
    let mean = vec3<f32>(means[3u * g], means[3u * g + 1u], means[3u * g + 2u]);
    let wrot = Rows(
        array<f32, 3>(cam.rot0.x, cam.rot0.y, cam.rot0.z),
        array<f32, 3>(cam.rot1.x, cam.rot1.y, cam.rot1.z),
        array<f32, 3>(cam.rot2.x, cam.rot2.y, cam.rot2.z),
    );
    let r = mat_vec_rows(wrot, mean);
    let x = r.x + cam.trans.x;
    let y = r.y + cam.trans.y;
    let z = r.z + cam.trans.z;
    if !(z > cam.near_far.x && z < cam.near_far.y) {
        return culled;
    }
    let ls = vec3<f32>(log_scales[3u * g], log_scales[3u * g + 1u], log_scales[3u * g + 2u]);
    let quat = vec4<f32>(quats[4u * g], quats[4u * g + 1u], quats[4u * g + 2u], quats[4u * g + 3u]);
    var sigma = covariance(ls, quat);
    var fm: Rows;
    let has_f = pp.has_f != 0u;
    if has_f {
        for (var i = 0u; i < 3u; i++) {
            for (var j = 0u; j < 3u; j++) {
                fm[i][j] = fmat[9u * g + 3u * i + j];
            }
        }
        sigma = mul3(mul3(fm, sigma), transpose3(fm));
    }
    let sc = mul3(mul3(wrot, sigma), transpose3(wrot));
    let fx = cam.intrinsics.x;
    let fy = cam.intrinsics.y;
    let cx = cam.intrinsics.z;
    let cy = cam.intrinsics.w;
    let w = f32(cam.size.x);
    let h = f32(cam.size.y);
    let tan_x = 0.5 * w / fx;
    let tan_y = 0.5 * h / fy;
    let lim_xp = (w - cx) / fx + 0.3 * tan_x;
    let lim_xn = cx / fx + 0.3 * tan_x;
    let lim_yp = (h - cy) / fy + 0.3 * tan_y;
    let lim_yn = cy / fy + 0.3 * tan_y;
    var xc = x;
    let rxz = x / z;
    if rxz < -lim_xn {
        xc = z * -lim_xn;
    } else if rxz > lim_xp {
        xc = z * lim_xp;
    }
    var yc = y;
    let ryz = y / z;
    if ryz < -lim_yn {
        yc = z * -lim_yn;
    } else if ryz > lim_yp {
        yc = z * lim_yp;
    }
    let j = array<array<f32, 3>, 2>(
        array<f32, 3>(fx / z, 0.0, -fx * xc / (z * z)),
        array<f32, 3>(0.0, fy / z, -fy * yc / (z * z)),
    );
    var cov0 = vec3<f32>(0.0);
    for (var a = 0u; a < 3u; a++) {
        for (var b = 0u; b < 3u; b++) {
            cov0.x += j[0][a] * sc[a][b] * j[0][b];
            cov0.y += j[0][a] * sc[a][b] * j[1][b];
            cov0.z += j[1][a] * sc[a][b] * j[1][b];
        }
    }
    let cov = vec3<f32>(cov0.x + EPS2D, cov0.y, cov0.z + EPS2D);
    let det_raw = cov.x * cov.z - cov.y * cov.y;
    var det = det_raw;
    if det_raw < 1e-10 {
        det = 1e-10;
    }
    let u = fx * x / z + cx;
    let v = fy * y / z + cy;
    let rx = ceil(RADIUS_SIGMAS * sqrt(cov.x));
    let ry = ceil(RADIUS_SIGMAS * sqrt(cov.z));
    if !(finite(rx) && finite(ry)) || u + rx <= 0.0 || u - rx >= w || v + ry <= 0.0 || v - ry >= h {
        return culled;
    }
    var opacity = 1.0 / (1.0 + exp(-opacity_logits[g]));
    if cam.antialiased != 0u {
        let det0 = cov0.x * cov0.z - cov0.y * cov0.y;
        let ratio = det0 / det;
        opacity *= sqrt(select(0.0, ratio, ratio > 0.0));
    }
    var dir = vec3<f32>(mean.x - cam.campos.x, mean.y - cam.campos.y, mean.z - cam.campos.z);
    if has_f {
        dir = mat_t_vec_rows(polar_rotation(fm), dir);
    }
    let col = sh_color(g, dir);
    var p: Projected;
    p.mean_x = u;
    p.mean_y = v;
    p.conic_a = cov.z / det;
    p.conic_b = -cov.y / det;
    p.conic_c = cov.x / det;
    p.depth = z;
    p.opacity = opacity;
    p.color_r = col.x;
    p.color_g = col.y;
    p.color_b = col.z;
    // `to_u32` fails (-> 0) above u32::MAX.
    p.radius_x = select(u32(rx), 0u, rx >= 4294967296.0);
    p.radius_y = select(u32(ry), 0u, ry >= 4294967296.0);
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
