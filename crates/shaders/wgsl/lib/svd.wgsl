// 3x3 singular value decomposition: a port of `svd3` in crates/mpm/src/math.rs (f32).
//
// F = U diag(sigma) V^T with McAdams et al.'s conventions: U and V are proper rotations
// (det = +1), sigma.x >= sigma.y >= |sigma.z|, and sigma.z carries the sign of det F.
//
// Algorithm (identical to the Rust one, step by step): cyclic Jacobi on F^T F for V (at most 12
// sweeps, stop when the off-diagonal mass is below eps^2 of the diagonal mass), sort the
// eigenvalues descending with V's columns, make V a rotation, then Gram-Schmidt QR of F V for U.
//
// Storage: the Jacobi matrix S and the rotation V are kept as arrays of rows, `s[row][col]`,
// exactly as the Rust arrays are indexed, so every update happens in the same order.
// Infinities: for |tau| >= 2^64 the Rust `1 + tau * tau` overflows to +inf and IEEE arithmetic
// gives t = 1 / (tau + inf) = 0. WGSL does not promise IEEE infinities, so that case is tested
// explicitly (t = 0, as in Rust); below 2^64 nothing overflows and the formula is the same.

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

fn svd3(f: mat3x3<f32>) -> Svd3 {
    // A = F^T F, as rows (A is symmetric: row i = column i).
    let a = transpose(f) * f;
    var s = array<vec3<f32>, 3>(a[0], a[1], a[2]);
    var v = array<vec3<f32>, 3>(
        vec3<f32>(1.0, 0.0, 0.0),
        vec3<f32>(0.0, 1.0, 0.0),
        vec3<f32>(0.0, 0.0, 1.0),
    );
    for (var sweep = 0u; sweep < 12u; sweep++) {
        let off = s[0][1] * s[0][1] + s[0][2] * s[0][2] + s[1][2] * s[1][2];
        let diag = s[0][0] * s[0][0] + s[1][1] * s[1][1] + s[2][2] * s[2][2];
        if off <= SVD_EPS * SVD_EPS * diag || off <= SVD_TINY {
            break;
        }
        // Pairs (0, 1), (0, 2), (1, 2).
        for (var k = 0u; k < 3u; k++) {
            let p = select(0u, 1u, k == 2u);
            let q = select(1u, 2u, k > 0u);
            let apq = s[p][q];
            if abs(apq) <= SVD_TINY {
                continue;
            }
            // Classic symmetric Schur rotation (Golub & Van Loan 8.4.2).
            let tau = (s[q][q] - s[p][p]) / (2.0 * apq);
            var t: f32;
            if abs(tau) >= 18446744073709551616.0 {
                t = 0.0;
            } else if tau >= 0.0 {
                t = 1.0 / (tau + sqrt(1.0 + tau * tau));
            } else {
                t = -1.0 / (-tau + sqrt(1.0 + tau * tau));
            }
            let c = 1.0 / sqrt(1.0 + t * t);
            let sn = t * c;
            // S <- J^T S J with J the rotation in the (p, q) plane: columns, then rows.
            for (var r = 0u; r < 3u; r++) {
                let skp = s[r][p];
                let skq = s[r][q];
                s[r][p] = c * skp - sn * skq;
                s[r][q] = sn * skp + c * skq;
            }
            let sp = s[p];
            let sq = s[q];
            s[p] = c * sp - sn * sq;
            s[q] = sn * sp + c * sq;
            for (var r = 0u; r < 3u; r++) {
                let vp = v[r][p];
                let vq = v[r][q];
                v[r][p] = c * vp - sn * vq;
                v[r][q] = sn * vp + c * vq;
            }
        }
    }
    // Sort eigenvalues descending together with the columns of V.
    var lam = vec3<f32>(s[0][0], s[1][1], s[2][2]);
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
