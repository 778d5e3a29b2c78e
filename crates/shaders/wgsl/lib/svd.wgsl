// 3x3 singular value decomposition: a port of `svd3` in crates/math/src/svd.rs and
// `sym_eigen` in crates/math/src/eigen.rs (f32).
//
// F = U diag(sigma) V^T with McAdams et al.'s conventions: U and V are proper rotations
// (det = +1), sigma.x >= sigma.y >= |sigma.z|, and sigma.z carries the sign of det F.
//
// Algorithm (identical to the Rust one, step by step): cyclic Jacobi on F^T F for V (at most 12
// sweeps, stop when the off-diagonal mass is below eps^2 of the diagonal mass), sort the
// eigenvalues descending with V's columns, make V a rotation, then Gram-Schmidt QR of F V for U.
//
// Storage: the symmetric Jacobi matrix as its six distinct entries and the rotation V as an
// array of rows, `v[row][col]`, exactly as the Rust arrays are indexed, so every update happens
// in the same order. Infinities: for |tau| >= 2^64 Rust sets t = 0 (where 1 + tau * tau would
// overflow); WGSL does not promise IEEE infinities either, so the case is tested the same way.

struct Svd3 {
    u: mat3x3<f32>,
    sigma: vec3<f32>,
    v: mat3x3<f32>,
}

// f32::EPSILON and f32::MIN_POSITIVE (the Rust T::epsilon() / T::min_positive_value()).
const SVD_EPS: f32 = 1.1920929e-7;
const SVD_TINY: f32 = 1.1754944e-38;

// Dot product with the Rust operation order: a0 b0 + a1 b1 + a2 b2.
fn svd_dot(a: vec3<f32>, b: vec3<f32>) -> f32 {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}

fn svd_norm(a: vec3<f32>) -> f32 {
    return sqrt(svd_dot(a, a));
}

// A unit vector orthogonal to the unit vector `a` (Rust `any_orthogonal`).
fn svd_any_orthogonal(a: vec3<f32>) -> vec3<f32> {
    var e = vec3<f32>(0.0, 1.0, 0.0);
    if abs(a.x) < 0.6 {
        e = vec3<f32>(1.0, 0.0, 0.0);
    }
    let w = e - a * svd_dot(a, e);
    return w * (1.0 / svd_norm(w));
}

// One Jacobi rotation in the (p, q) plane (Rust `eigen::rotate`, one lane): the symmetric
// matrix is kept as its six distinct entries s = (a00, a11, a22, a01, a02, a12); pq, pr, qr
// are the positions of the off-diagonal entries (r the third axis). Only the entries the
// rotation changes are updated; a_pq becomes exactly zero. A tiny a_pq leaves s and v as
// they are.
fn svd_rotate(
    s: ptr<function, array<f32, 6>>,
    v: ptr<function, array<vec3<f32>, 3>>,
    p: u32,
    q: u32,
    pq: u32,
    pr: u32,
    qr: u32,
) {
    let apq = (*s)[pq];
    if abs(apq) <= SVD_TINY {
        return;
    }
    // Classic symmetric Schur rotation (Golub & Van Loan 8.4.2):
    // t = sign(tau) / (|tau| + sqrt(1 + tau^2)).
    let tau = ((*s)[q] - (*s)[p]) / (2.0 * apq);
    var t = 0.0;
    if abs(tau) < 18446744073709551616.0 {
        let sgn = select(-1.0, 1.0, tau >= 0.0);
        t = sgn / (abs(tau) + sqrt(1.0 + tau * tau));
    }
    let c = 1.0 / sqrt(1.0 + t * t);
    let sn = t * c;
    (*s)[p] = (*s)[p] - t * apq;
    (*s)[q] = (*s)[q] + t * apq;
    (*s)[pq] = 0.0;
    let arp = (*s)[pr];
    let arq = (*s)[qr];
    (*s)[pr] = c * arp - sn * arq;
    (*s)[qr] = sn * arp + c * arq;
    for (var r = 0u; r < 3u; r++) {
        let vp = (*v)[r][p];
        let vq = (*v)[r][q];
        (*v)[r][p] = c * vp - sn * vq;
        (*v)[r][q] = sn * vp + c * vq;
    }
}

fn svd3(f: mat3x3<f32>) -> Svd3 {
    // A = F^T F (symmetric), as its six distinct entries (off-diagonals: the average of the
    // two triangles, as in Rust).
    let a = transpose(f) * f;
    var s = array<f32, 6>(
        a[0][0],
        a[1][1],
        a[2][2],
        0.5 * (a[0][1] + a[1][0]),
        0.5 * (a[0][2] + a[2][0]),
        0.5 * (a[1][2] + a[2][1]),
    );
    var v = array<vec3<f32>, 3>(
        vec3<f32>(1.0, 0.0, 0.0),
        vec3<f32>(0.0, 1.0, 0.0),
        vec3<f32>(0.0, 0.0, 1.0),
    );
    for (var sweep = 0u; sweep < 12u; sweep++) {
        let off = s[3] * s[3] + s[4] * s[4] + s[5] * s[5];
        let diag = s[0] * s[0] + s[1] * s[1] + s[2] * s[2];
        if off <= SVD_EPS * SVD_EPS * diag || off <= SVD_TINY {
            break;
        }
        // Pairs (0, 1), (0, 2), (1, 2).
        svd_rotate(&s, &v, 0u, 1u, 3u, 4u, 5u);
        svd_rotate(&s, &v, 0u, 2u, 4u, 3u, 5u);
        svd_rotate(&s, &v, 1u, 2u, 5u, 3u, 4u);
    }
    // Sort eigenvalues descending together with the columns of V.
    var lam = vec3<f32>(s[0], s[1], s[2]);
    if lam.x < lam.y {
        lam = lam.yxz;
        v[0] = v[0].yxz;
        v[1] = v[1].yxz;
        v[2] = v[2].yxz;
    }
    if lam.x < lam.z {
        lam = lam.zyx;
        v[0] = v[0].zyx;
        v[1] = v[1].zyx;
        v[2] = v[2].zyx;
    }
    if lam.y < lam.z {
        lam = lam.xzy;
        v[0] = v[0].xzy;
        v[1] = v[1].xzy;
        v[2] = v[2].xzy;
    }
    // The matrix V (WGSL columns from the rows).
    var vm = mat3x3<f32>(
        vec3<f32>(v[0].x, v[1].x, v[2].x),
        vec3<f32>(v[0].y, v[1].y, v[2].y),
        vec3<f32>(v[0].z, v[1].z, v[2].z),
    );
    // Make V a proper rotation.
    if determinant(vm) < 0.0 {
        vm[2] = -vm[2];
    }
    // B = F V; QR by Gram-Schmidt: U = Q (a rotation), sigma = diag(R).
    let b = f * vm;
    let b0 = b[0];
    let b1 = b[1];
    let b2 = b[2];
    let n0 = svd_norm(b0);
    var u0 = vec3<f32>(1.0, 0.0, 0.0);
    if n0 > SVD_TINY {
        u0 = b0 * (1.0 / n0);
    }
    let r01 = svd_dot(u0, b1);
    let w1 = b1 - u0 * r01;
    let n1 = svd_norm(w1);
    var u1: vec3<f32>;
    if n1 > SVD_EPS * max(n0, 1.0) * 1e-3 && n1 > SVD_TINY {
        u1 = w1 * (1.0 / n1);
    } else {
        u1 = svd_any_orthogonal(u0);
    }
    let u2 = cross(u0, u1);
    let s2 = svd_dot(u2, b2);
    return Svd3(mat3x3<f32>(u0, u1, u2), vec3<f32>(n0, svd_dot(u1, b1), s2), vm);
}
