// The per-Gaussian math of `project.wgsl` and `project_vjp.wgsl`, in f32 and in the operation
// order of `r4d_splat::covariance`, `r4d_splat::sh` and `r4d_splat::project` (names follow the
// Rust functions): the 3D covariance and its VJP, `F Sigma F^T` and its VJP, the polar rotation
// of F and its VJP, the SH basis and its derivative, and `splat_forward` (the Rust `forward`:
// camera transform, covariance, Jacobian with the frustum clamp, 2D covariance, det clamp).
//
// Matrices are row-major `Rows` (`m[row][col]`, like the Rust `[[f32; 3]; 3]`), so dynamic
// indexing reads like the reference loops.
#import lib/splat_structs.wgsl

const EPS2D: f32 = 0.3;
const RADIUS_SIGMAS: f32 = 3.33;
// f32::MIN_POSITIVE.
const MIN_NORMAL: f32 = 1.1754944e-38;

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

// Sections of `project_vjp.wgsl`'s output buffer (`SECTION_*` in `src/splat.rs`): starts in
// multiples of n, each laid out `[n][width]`: dL/dmean (3), dL/dlog_scale (3), dL/dquat (4),
// dL/dopacity_logit (1), the SH direction (3), the masked dL/dcolour (3), dL/dF (9).
const PV_MEAN: u32 = 0u;
const PV_LOG_SCALE: u32 = 3u;
const PV_QUAT: u32 = 6u;
const PV_OPACITY: u32 = 10u;
const PV_DIR: u32 = 11u;
const PV_COLOR: u32 = 14u;
const PV_F: u32 = 17u;

// Row-major 3x3 in function memory.
alias Rows = array<array<f32, 3>, 3>;
// The 2x3 Jacobian of the projection.
alias Jac = array<array<f32, 3>, 2>;

fn rows_identity() -> Rows {
    return Rows(array<f32, 3>(1.0, 0.0, 0.0), array<f32, 3>(0.0, 1.0, 0.0), array<f32, 3>(0.0, 0.0, 1.0));
}

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

// `a b^T`.
fn mul_bt3(a: Rows, b: Rows) -> Rows {
    return mul3(a, transpose3(b));
}

// `a^T b`.
fn mul_at3(a: Rows, b: Rows) -> Rows {
    return mul3(transpose3(a), b);
}

fn add3(a: Rows, b: Rows) -> Rows {
    var m = a;
    for (var i = 0u; i < 3u; i++) {
        for (var j = 0u; j < 3u; j++) {
            m[i][j] += b[i][j];
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

fn finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7fffffffu) < 0x7f800000u;
}

// The camera's world-to-camera rotation.
fn cam_rows(cam: CameraConsts) -> Rows {
    return Rows(
        array<f32, 3>(cam.rot0.x, cam.rot0.y, cam.rot0.z),
        array<f32, 3>(cam.rot1.x, cam.rot1.y, cam.rot1.z),
        array<f32, 3>(cam.rot2.x, cam.rot2.y, cam.rot2.z),
    );
}

// ---- covariance ---------------------------------------------------------------------------

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

// dL/dq (unit q treated as free) from dL/dR.
fn quat_to_rot_vjp(q: vec4<f32>, g: Rows) -> vec4<f32> {
    let w = q.x;
    let x = q.y;
    let y = q.z;
    let z = q.w;
    let gw = 2.0 * (-z * g[0][1] + y * g[0][2] + z * g[1][0] - x * g[1][2] - y * g[2][0] + x * g[2][1]);
    let gx = 2.0 * (y * g[0][1] + z * g[0][2] + y * g[1][0] - w * g[1][2] + z * g[2][0] + w * g[2][1])
        - 4.0 * x * (g[1][1] + g[2][2]);
    let gy = 2.0 * (x * g[0][1] + w * g[0][2] + x * g[1][0] + z * g[1][2] - w * g[2][0] + z * g[2][1])
        - 4.0 * y * (g[0][0] + g[2][2]);
    let gz = 2.0 * (-w * g[0][1] + x * g[0][2] + w * g[1][0] + y * g[1][2] + x * g[2][0] + y * g[2][1])
        - 4.0 * z * (g[0][0] + g[1][1]);
    return vec4<f32>(gw, gx, gy, gz);
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

struct CovarianceGrad {
    log_scale: vec3<f32>,
    quat: vec4<f32>,
}

// (dL/dlog_scale, dL/dquat) from dL/dSigma.
fn covariance_vjp(ls: vec3<f32>, quat: vec4<f32>, g_sigma: Rows) -> CovarianceGrad {
    let n = sqrt(quat.x * quat.x + quat.y * quat.y + quat.z * quat.z + quat.w * quat.w);
    let q = quat / n;
    let r = quat_to_rot(q);
    let s = array<f32, 3>(exp(ls.x), exp(ls.y), exp(ls.z));
    var m = r;
    for (var i = 0u; i < 3u; i++) {
        for (var j = 0u; j < 3u; j++) {
            m[i][j] = r[i][j] * s[j];
        }
    }
    // Sigma = M M^T: dL/dM = (G + G^T) M.
    let g_m = mul3(add3(g_sigma, transpose3(g_sigma)), m);
    var g_r: Rows;
    var g_ls = array<f32, 3>(0.0, 0.0, 0.0);
    for (var i = 0u; i < 3u; i++) {
        for (var j = 0u; j < 3u; j++) {
            g_r[i][j] = g_m[i][j] * s[j];
            g_ls[j] += g_m[i][j] * r[i][j] * s[j];
        }
    }
    let g_qn = quat_to_rot_vjp(q, g_r);
    let d = g_qn.x * q.x + g_qn.y * q.y + g_qn.z * q.z + g_qn.w * q.w;
    var out: CovarianceGrad;
    out.log_scale = vec3<f32>(g_ls[0], g_ls[1], g_ls[2]);
    out.quat = (g_qn - q * d) / n;
    return out;
}

struct DeformGrad {
    sigma: Rows,
    f: Rows,
}

// VJP of `F Sigma F^T`: (dL/dSigma, dL/dF) from dL/dSigma'.
fn deform_covariance_vjp(f: Rows, sigma: Rows, g: Rows) -> DeformGrad {
    var out: DeformGrad;
    out.sigma = mul3(mul_at3(f, g), f);
    // d/dF tr(G^T F S F^T) = G F S^T + G^T F S.
    out.f = add3(mul_bt3(mul3(g, f), sigma), mul3(mul_at3(g, f), sigma));
    return out;
}

// ---- polar rotation -----------------------------------------------------------------------

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
    var v = rows_identity();
    var scale = 0.0;
    for (var i = 0u; i < 3u; i++) {
        for (var j = 0u; j < 3u; j++) {
            scale = max(scale, abs(a[i][j]));
        }
    }
    for (var sweep = 0u; sweep < 60u; sweep++) {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        if !(off > max(1e-15 * scale * scale, MIN_NORMAL)) {
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
    if !finite(sig0) || sig0 <= 0.0 {
        return rows_identity();
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

// dL/dF from dL/dR (`r` the forward result), as `r4d_splat::covariance::polar_rotation_vjp`:
// with S = sym(R^T F) and m the axial vector of R^T dL/dR, solve (tr(S) I - S) y = m by the
// adjugate, |det| clamped at 1e-12 tr(S)^3 (and at least f32::MIN_POSITIVE: the reference's
// f64 floor underflows in f32), and return R [y]x. In f32 (the reference solves in f64).
fn polar_rotation_vjp(f: Rows, r: Rows, g_r: Rows) -> Rows {
    let s0 = mul_at3(r, f);
    var s: Rows;
    for (var i = 0u; i < 3u; i++) {
        for (var j = 0u; j < 3u; j++) {
            s[i][j] = 0.5 * (s0[i][j] + s0[j][i]);
        }
    }
    let m = mul_at3(r, g_r);
    let mv = vec3<f32>(m[2][1] - m[1][2], m[0][2] - m[2][0], m[1][0] - m[0][1]);
    let tr = s[0][0] + s[1][1] + s[2][2];
    var k: Rows;
    for (var i = 0u; i < 3u; i++) {
        for (var j = 0u; j < 3u; j++) {
            k[i][j] = -s[i][j];
        }
        k[i][i] += tr;
    }
    var dk = det_rows(k);
    let atr = abs(tr);
    let floor = max(1e-12 * max(atr * atr * atr, MIN_NORMAL), MIN_NORMAL);
    if abs(dk) < floor {
        dk = select(floor, -floor, dk < 0.0);
    }
    let adj = Rows(
        array<f32, 3>(
            k[1][1] * k[2][2] - k[1][2] * k[2][1],
            k[0][2] * k[2][1] - k[0][1] * k[2][2],
            k[0][1] * k[1][2] - k[0][2] * k[1][1],
        ),
        array<f32, 3>(
            k[1][2] * k[2][0] - k[1][0] * k[2][2],
            k[0][0] * k[2][2] - k[0][2] * k[2][0],
            k[0][2] * k[1][0] - k[0][0] * k[1][2],
        ),
        array<f32, 3>(
            k[1][0] * k[2][1] - k[1][1] * k[2][0],
            k[0][1] * k[2][0] - k[0][0] * k[2][1],
            k[0][0] * k[1][1] - k[0][1] * k[1][0],
        ),
    );
    let y = mat_vec_rows(adj, mv) / dk;
    let yx = Rows(
        array<f32, 3>(0.0, -y.z, y.y),
        array<f32, 3>(y.z, 0.0, -y.x),
        array<f32, 3>(-y.y, y.x, 0.0),
    );
    return mul3(r, yx);
}

// ---- spherical harmonics ------------------------------------------------------------------

// The basis Y_0 .. Y_15 at the unit direction d (entries past (deg + 1)^2 are 0).
fn sh_basis(deg: u32, d: vec3<f32>) -> array<f32, 16> {
    let x = d.x;
    let y = d.y;
    let z = d.z;
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
    return b;
}

// dY_k/dd at d (d treated as a free 3-vector), as the `grad` output of `r4d_splat::sh::basis`.
fn sh_basis_grad(deg: u32, d: vec3<f32>) -> array<vec3<f32>, 16> {
    let x = d.x;
    let y = d.y;
    let z = d.z;
    var g: array<vec3<f32>, 16>;
    if deg >= 1u {
        g[1] = vec3<f32>(0.0, -SH_C1, 0.0);
        g[2] = vec3<f32>(0.0, 0.0, SH_C1);
        g[3] = vec3<f32>(-SH_C1, 0.0, 0.0);
    }
    if deg >= 2u {
        g[4] = vec3<f32>(SH_C2A * y, SH_C2A * x, 0.0);
        g[5] = vec3<f32>(0.0, -SH_C2A * z, -SH_C2A * y);
        g[6] = vec3<f32>(-(2.0 * SH_C6) * x, -(2.0 * SH_C6) * y, (4.0 * SH_C6) * z);
        g[7] = vec3<f32>(-SH_C2A * z, 0.0, -SH_C2A * x);
        g[8] = vec3<f32>((2.0 * SH_C8) * x, -(2.0 * SH_C8) * y, 0.0);
    }
    if deg >= 3u {
        let xx = x * x;
        let yy = y * y;
        let zz = z * z;
        g[9] = vec3<f32>(-(6.0 * SH_C9) * x * y, -SH_C9 * (3.0 * xx - 3.0 * yy), 0.0);
        g[10] = vec3<f32>(SH_C10 * y * z, SH_C10 * x * z, SH_C10 * x * y);
        g[11] = vec3<f32>(
            (2.0 * SH_C11) * x * y,
            -SH_C11 * (4.0 * zz - xx - 3.0 * yy),
            -(8.0 * SH_C11) * y * z,
        );
        g[12] = vec3<f32>(
            -(6.0 * SH_C12) * x * z,
            -(6.0 * SH_C12) * y * z,
            SH_C12 * (6.0 * zz - 3.0 * xx - 3.0 * yy),
        );
        g[13] = vec3<f32>(
            -SH_C11 * (4.0 * zz - 3.0 * xx - yy),
            (2.0 * SH_C11) * x * y,
            -(8.0 * SH_C11) * x * z,
        );
        g[14] = vec3<f32>((2.0 * SH_C14) * x * z, -(2.0 * SH_C14) * y * z, SH_C14 * (xx - yy));
        g[15] = vec3<f32>(-SH_C9 * (3.0 * xx - 3.0 * yy), (6.0 * SH_C9) * x * y, 0.0);
    }
    return g;
}

// Number of SH coefficients per channel of a degree (at most 16).
fn sh_count(deg: u32) -> u32 {
    return min((deg + 1u) * (deg + 1u), 16u);
}

// ---- projection ---------------------------------------------------------------------------

// Everything of the forward projection the VJP needs again (the Rust `Fwd`, without the
// polar rotation and view direction, which the callers compute only when they need them).
struct SplatFwd {
    // 0 when culled by the near/far planes (the other fields are then unset).
    ok: u32,
    sigma0: Rows,
    // Camera-space centre (x, y, z).
    mc: vec3<f32>,
    // Camera-space covariance W Sigma' W^T.
    sc: Rows,
    j: Jac,
    xc: f32,
    yc: f32,
    // 1 when x/z (y/z) was clamped, at the limit `lim_x` (`lim_y`).
    clamped_x: u32,
    lim_x: f32,
    clamped_y: u32,
    lim_y: f32,
    // J sc J^T (a, b, c) before and after the 0.3 px dilation.
    cov0: vec3<f32>,
    cov: vec3<f32>,
    det: f32,
    det_clamped: u32,
}

// `r4d_splat::project::forward`: `fm` is F when `has_f`.
fn splat_forward(cam: CameraConsts, mean: vec3<f32>, ls: vec3<f32>, quat: vec4<f32>, has_f: bool, fm: Rows) -> SplatFwd {
    var o: SplatFwd;
    let wrot = cam_rows(cam);
    let r = mat_vec_rows(wrot, mean);
    let x = r.x + cam.trans.x;
    let y = r.y + cam.trans.y;
    let z = r.z + cam.trans.z;
    o.mc = vec3<f32>(x, y, z);
    if !(z > cam.near_far.x && z < cam.near_far.y) {
        return o;
    }
    o.ok = 1u;
    o.sigma0 = covariance(ls, quat);
    var sigma = o.sigma0;
    if has_f {
        sigma = mul3(mul3(fm, sigma), transpose3(fm));
    }
    o.sc = mul3(mul3(wrot, sigma), transpose3(wrot));
    let fx = cam.intrinsics.x;
    let fy = cam.intrinsics.y;
    let cx = cam.intrinsics.z;
    let cy = cam.intrinsics.w;
    let lim_xp = cam.lims.x;
    let lim_xn = cam.lims.y;
    let lim_yp = cam.lims.z;
    let lim_yn = cam.lims.w;
    o.xc = x;
    let rxz = x / z;
    if rxz < -lim_xn {
        o.xc = z * -lim_xn;
        o.clamped_x = 1u;
        o.lim_x = -lim_xn;
    } else if rxz > lim_xp {
        o.xc = z * lim_xp;
        o.clamped_x = 1u;
        o.lim_x = lim_xp;
    }
    o.yc = y;
    let ryz = y / z;
    if ryz < -lim_yn {
        o.yc = z * -lim_yn;
        o.clamped_y = 1u;
        o.lim_y = -lim_yn;
    } else if ryz > lim_yp {
        o.yc = z * lim_yp;
        o.clamped_y = 1u;
        o.lim_y = lim_yp;
    }
    o.j = Jac(
        array<f32, 3>(fx / z, 0.0, -fx * o.xc / (z * z)),
        array<f32, 3>(0.0, fy / z, -fy * o.yc / (z * z)),
    );
    var cov0 = vec3<f32>(0.0);
    for (var a = 0u; a < 3u; a++) {
        for (var b = 0u; b < 3u; b++) {
            cov0.x += o.j[0][a] * o.sc[a][b] * o.j[0][b];
            cov0.y += o.j[0][a] * o.sc[a][b] * o.j[1][b];
            cov0.z += o.j[1][a] * o.sc[a][b] * o.j[1][b];
        }
    }
    o.cov0 = cov0;
    o.cov = vec3<f32>(cov0.x + EPS2D, cov0.y, cov0.z + EPS2D);
    let det_raw = o.cov.x * o.cov.z - o.cov.y * o.cov.y;
    o.det = det_raw;
    if det_raw < 1e-10 {
        o.det = 1e-10;
        o.det_clamped = 1u;
    }
    return o;
}

// The projected centre (u, v).
fn splat_mean2d(cam: CameraConsts, f: SplatFwd) -> vec2<f32> {
    return vec2<f32>(
        cam.intrinsics.x * f.mc.x / f.mc.z + cam.intrinsics.z,
        cam.intrinsics.y * f.mc.y / f.mc.z + cam.intrinsics.w,
    );
}

// The pixel radii as floats, `ceil(3.33 sqrt(a))`, `ceil(3.33 sqrt(c))`.
fn splat_radii(f: SplatFwd) -> vec2<f32> {
    return vec2<f32>(ceil(RADIUS_SIGMAS * sqrt(f.cov.x)), ceil(RADIUS_SIGMAS * sqrt(f.cov.z)));
}

// The screen-space culling of `r4d_splat::project::project`: true when the Gaussian (not
// culled by `splat_forward`) is dropped.
fn splat_off_screen(cam: CameraConsts, uv: vec2<f32>, r: vec2<f32>) -> bool {
    let w = f32(cam.size.x);
    let h = f32(cam.size.y);
    return !(finite(r.x) && finite(r.y)) || uv.x + r.x <= 0.0 || uv.x - r.x >= w || uv.y + r.y <= 0.0
        || uv.y - r.y >= h;
}

fn sigmoid(x: f32) -> f32 {
    return 1.0 / (1.0 + exp(-x));
}
