//! Small fixed-size linear algebra for the per-particle kernels: 3-vectors, 3x3 matrices and a
//! robust 3x3 SVD.
//!
//! Everything is generic over [`Real`] (`f32` for the simulation state, `f64` for finite-difference
//! checks) and written with plain arrays so the compiler can keep it in registers. Matrices are
//! row-major: `m[i][j]` is row `i`, column `j`; for a deformation gradient `F[i][j] = dx_i / dX_j`.

use num_traits::Float;
use std::fmt::Debug;
use std::ops::{Add, AddAssign, Index, IndexMut, Mul, Neg, Sub};

/// Floating-point scalar used by the kernels (`f32` or `f64`).
pub trait Real: Float + Default + Debug + Send + Sync + AddAssign + 'static {
    /// Converts an `f64` constant.
    fn c(x: f64) -> Self;
    /// Converts to `f64` (for diagnostics).
    fn f64(self) -> f64;
}
impl Real for f32 {
    #[inline(always)]
    fn c(x: f64) -> Self {
        x as f32
    }
    #[inline(always)]
    fn f64(self) -> f64 {
        self as f64
    }
}
impl Real for f64 {
    #[inline(always)]
    fn c(x: f64) -> Self {
        x
    }
    #[inline(always)]
    fn f64(self) -> f64 {
        self
    }
}

/// A 3-vector.
pub type Vec3<T> = [T; 3];

/// Dot product.
#[inline(always)]
pub fn dot<T: Real>(a: Vec3<T>, b: Vec3<T>) -> T {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
/// Euclidean norm.
#[inline(always)]
pub fn norm<T: Real>(a: Vec3<T>) -> T {
    dot(a, a).sqrt()
}
/// Cross product.
#[inline(always)]
pub fn cross<T: Real>(a: Vec3<T>, b: Vec3<T>) -> Vec3<T> {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
/// `a * s`.
#[inline(always)]
pub fn scale<T: Real>(a: Vec3<T>, s: T) -> Vec3<T> {
    [a[0] * s, a[1] * s, a[2] * s]
}
/// `a + b`.
#[inline(always)]
pub fn add<T: Real>(a: Vec3<T>, b: Vec3<T>) -> Vec3<T> {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
/// `a - b`.
#[inline(always)]
pub fn sub<T: Real>(a: Vec3<T>, b: Vec3<T>) -> Vec3<T> {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// A 3x3 matrix, row-major.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Mat3<T>(pub [[T; 3]; 3]);

impl<T: Real> Mat3<T> {
    /// The zero matrix.
    #[inline(always)]
    pub fn zero() -> Self {
        Mat3([[T::zero(); 3]; 3])
    }
    /// The identity.
    #[inline(always)]
    pub fn identity() -> Self {
        Self::diag([T::one(); 3])
    }
    /// A diagonal matrix.
    #[inline(always)]
    pub fn diag(d: Vec3<T>) -> Self {
        let z = T::zero();
        Mat3([[d[0], z, z], [z, d[1], z], [z, z, d[2]]])
    }
    /// From a row-major array of 9 entries.
    #[inline(always)]
    pub fn from_array(a: [T; 9]) -> Self {
        Mat3([[a[0], a[1], a[2]], [a[3], a[4], a[5]], [a[6], a[7], a[8]]])
    }
    /// To a row-major array of 9 entries.
    #[inline(always)]
    pub fn to_array(self) -> [T; 9] {
        let m = self.0;
        [
            m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2], m[2][0], m[2][1], m[2][2],
        ]
    }
    /// Outer product `a b^T`.
    #[inline(always)]
    pub fn outer(a: Vec3<T>, b: Vec3<T>) -> Self {
        Mat3([
            [a[0] * b[0], a[0] * b[1], a[0] * b[2]],
            [a[1] * b[0], a[1] * b[1], a[1] * b[2]],
            [a[2] * b[0], a[2] * b[1], a[2] * b[2]],
        ])
    }
    /// Transpose.
    #[inline(always)]
    pub fn transpose(self) -> Self {
        let m = self.0;
        Mat3([
            [m[0][0], m[1][0], m[2][0]],
            [m[0][1], m[1][1], m[2][1]],
            [m[0][2], m[1][2], m[2][2]],
        ])
    }
    /// Determinant.
    #[inline(always)]
    pub fn det(self) -> T {
        let m = self.0;
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    }
    /// Trace.
    #[inline(always)]
    pub fn trace(self) -> T {
        self.0[0][0] + self.0[1][1] + self.0[2][2]
    }
    /// Matrix-vector product.
    #[inline(always)]
    pub fn mul_vec(self, v: Vec3<T>) -> Vec3<T> {
        let m = self.0;
        [
            m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
            m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
            m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2],
        ]
    }
    /// Column `j`.
    #[inline(always)]
    pub fn col(self, j: usize) -> Vec3<T> {
        [self.0[0][j], self.0[1][j], self.0[2][j]]
    }
    /// Builds a matrix from its three columns.
    #[inline(always)]
    pub fn from_cols(a: Vec3<T>, b: Vec3<T>, c: Vec3<T>) -> Self {
        Mat3([[a[0], b[0], c[0]], [a[1], b[1], c[1]], [a[2], b[2], c[2]]])
    }
    /// `self * s`.
    #[inline(always)]
    pub fn scaled(self, s: T) -> Self {
        let mut m = self.0;
        for row in m.iter_mut() {
            for x in row.iter_mut() {
                *x = *x * s;
            }
        }
        Mat3(m)
    }
    /// `self * diag(d)` (scales columns).
    #[inline(always)]
    pub fn mul_diag(self, d: Vec3<T>) -> Self {
        let mut m = self.0;
        for row in m.iter_mut() {
            for j in 0..3 {
                row[j] = row[j] * d[j];
            }
        }
        Mat3(m)
    }
    /// `(self + self^T) / 2`.
    #[inline(always)]
    pub fn sym(self) -> Self {
        let h = T::c(0.5);
        (self + self.transpose()).scaled(h)
    }
    /// Frobenius norm.
    pub fn frobenius(self) -> T {
        self.to_array()
            .iter()
            .fold(T::zero(), |a, &x| a + x * x)
            .sqrt()
    }
    /// Converts the scalar type.
    pub fn cast<U: Real>(self) -> Mat3<U> {
        let mut out = Mat3::<U>::zero();
        for i in 0..3 {
            for j in 0..3 {
                out.0[i][j] = U::c(self.0[i][j].f64());
            }
        }
        out
    }
    /// True when every entry is finite.
    pub fn is_finite(self) -> bool {
        self.to_array().iter().all(|x| x.is_finite())
    }
}

impl<T: Real> Add for Mat3<T> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        let mut m = self.0;
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += o.0[i][j];
            }
        }
        Mat3(m)
    }
}
impl<T: Real> Sub for Mat3<T> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        let mut m = self.0;
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] = m[i][j] - o.0[i][j];
            }
        }
        Mat3(m)
    }
}
impl<T: Real> Neg for Mat3<T> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        self.scaled(-T::one())
    }
}
impl<T: Real> Mul for Mat3<T> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        let a = self.0;
        let b = o.0;
        let mut m = [[T::zero(); 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
            }
        }
        Mat3(m)
    }
}
impl<T> Index<(usize, usize)> for Mat3<T> {
    type Output = T;
    #[inline(always)]
    fn index(&self, (i, j): (usize, usize)) -> &T {
        &self.0[i][j]
    }
}
impl<T> IndexMut<(usize, usize)> for Mat3<T> {
    #[inline(always)]
    fn index_mut(&mut self, (i, j): (usize, usize)) -> &mut T {
        &mut self.0[i][j]
    }
}

/// Singular value decomposition `F = U diag(sigma) V^T` of a 3x3 matrix.
///
/// Conventions (those of McAdams et al. 2011, which PhysGaussian's Warp `svd3` follows):
/// `U` and `V` are proper rotations (det = +1), `sigma[0] >= sigma[1] >= |sigma[2]|`, and
/// `sigma[2]` carries the sign of `det F` (it is negative for an inverted element).
#[derive(Clone, Copy, Debug)]
pub struct Svd3<T> {
    /// Left rotation.
    pub u: Mat3<T>,
    /// Singular values, see the type docs for order and sign.
    pub sigma: Vec3<T>,
    /// Right rotation.
    pub v: Mat3<T>,
}

impl<T: Real> Svd3<T> {
    /// Reassembles `U diag(s) V^T` with other singular values.
    #[inline(always)]
    pub fn compose(&self, s: Vec3<T>) -> Mat3<T> {
        self.u.mul_diag(s) * self.v.transpose()
    }
    /// The rotation `U V^T` (the polar rotation of `F`).
    #[inline(always)]
    pub fn rotation(&self) -> Mat3<T> {
        self.u * self.v.transpose()
    }
}

/// Computes the SVD of `f`: cyclic Jacobi on `F^T F` for `V`, then a Gram-Schmidt QR of `F V`
/// for `U` (robust when `F` is rank-deficient: `U` stays a rotation).
///
/// The Jacobi iteration runs until the off-diagonal mass is below `T::epsilon()` relative to
/// the diagonal, at most 12 sweeps; 3x3 Jacobi converges quadratically, so 4-5 sweeps is usual.
pub fn svd3<T: Real>(f: Mat3<T>) -> Svd3<T> {
    let a = f.transpose() * f;
    let mut s = [
        [a.0[0][0], a.0[0][1], a.0[0][2]],
        [a.0[1][0], a.0[1][1], a.0[1][2]],
        [a.0[2][0], a.0[2][1], a.0[2][2]],
    ];
    let mut v = Mat3::<T>::identity().0;
    let eps = T::epsilon();
    let tiny = T::min_positive_value();
    for _sweep in 0..12 {
        let off = s[0][1] * s[0][1] + s[0][2] * s[0][2] + s[1][2] * s[1][2];
        let diag = s[0][0] * s[0][0] + s[1][1] * s[1][1] + s[2][2] * s[2][2];
        if off <= eps * eps * diag || off <= tiny {
            break;
        }
        for &(p, q) in &[(0usize, 1usize), (0, 2), (1, 2)] {
            let apq = s[p][q];
            if apq.abs() <= tiny {
                continue;
            }
            // Classic symmetric Schur rotation (Golub & Van Loan 8.4.2).
            let tau = (s[q][q] - s[p][p]) / (T::c(2.0) * apq);
            let t = if tau >= T::zero() {
                T::one() / (tau + (T::one() + tau * tau).sqrt())
            } else {
                -T::one() / (-tau + (T::one() + tau * tau).sqrt())
            };
            let c = T::one() / (T::one() + t * t).sqrt();
            let sn = t * c;
            // S <- J^T S J with J the rotation in the (p, q) plane.
            for k in 0..3 {
                let skp = s[k][p];
                let skq = s[k][q];
                s[k][p] = c * skp - sn * skq;
                s[k][q] = sn * skp + c * skq;
            }
            for k in 0..3 {
                let spk = s[p][k];
                let sqk = s[q][k];
                s[p][k] = c * spk - sn * sqk;
                s[q][k] = sn * spk + c * sqk;
            }
            for row in v.iter_mut() {
                let vp = row[p];
                let vq = row[q];
                row[p] = c * vp - sn * vq;
                row[q] = sn * vp + c * vq;
            }
        }
    }
    // Sort eigenvalues descending together with the columns of V.
    let mut lam = [s[0][0], s[1][1], s[2][2]];
    let mut vm = Mat3(v);
    let swap = |lam: &mut [T; 3], vm: &mut Mat3<T>, i: usize, j: usize| {
        lam.swap(i, j);
        for r in 0..3 {
            vm.0[r].swap(i, j);
        }
    };
    if lam[0] < lam[1] {
        swap(&mut lam, &mut vm, 0, 1);
    }
    if lam[0] < lam[2] {
        swap(&mut lam, &mut vm, 0, 2);
    }
    if lam[1] < lam[2] {
        swap(&mut lam, &mut vm, 1, 2);
    }
    // Make V a proper rotation.
    if vm.det() < T::zero() {
        for r in 0..3 {
            vm.0[r][2] = -vm.0[r][2];
        }
    }
    // B = F V; QR by Gram-Schmidt: U = Q (a rotation), sigma = diag(R).
    let b = f * vm;
    let b0 = b.col(0);
    let b1 = b.col(1);
    let b2 = b.col(2);
    let n0 = norm(b0);
    let u0 = if n0 > tiny {
        scale(b0, T::one() / n0)
    } else {
        [T::one(), T::zero(), T::zero()]
    };
    let r01 = dot(u0, b1);
    let w1 = sub(b1, scale(u0, r01));
    let n1 = norm(w1);
    let u1 = if n1 > eps * n0.max(T::one()) * T::c(1e-3) && n1 > tiny {
        scale(w1, T::one() / n1)
    } else {
        any_orthogonal(u0)
    };
    let u2 = cross(u0, u1);
    let s2 = dot(u2, b2);
    Svd3 {
        u: Mat3::from_cols(u0, u1, u2),
        sigma: [n0, dot(u1, b1), s2],
        v: vm,
    }
}

/// A unit vector orthogonal to the unit vector `a`.
fn any_orthogonal<T: Real>(a: Vec3<T>) -> Vec3<T> {
    let e = if a[0].abs() < T::c(0.6) {
        [T::one(), T::zero(), T::zero()]
    } else {
        [T::zero(), T::one(), T::zero()]
    };
    let w = sub(e, scale(a, dot(a, e)));
    scale(w, T::one() / norm(w))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(f: Mat3<f64>, tol: f64) {
        let s = svd3(f);
        let r = s.compose(s.sigma);
        assert!(
            (r - f).frobenius() <= tol * f.frobenius().max(1.0),
            "{f:?} -> {s:?}"
        );
        assert!((s.u.det() - 1.0).abs() < 1e-9);
        assert!((s.v.det() - 1.0).abs() < 1e-9);
        assert!((s.u.transpose() * s.u - Mat3::identity()).frobenius() < 1e-9);
        assert!(s.sigma[0] >= s.sigma[1] - 1e-12 && s.sigma[1] >= s.sigma[2].abs() - 1e-12);
        assert_eq!(s.sigma[2] < 0.0, f.det() < 0.0, "{f:?} {s:?}");
    }

    #[test]
    fn svd_reconstructs_general_degenerate_and_inverted_matrices() {
        check(Mat3::identity(), 1e-12);
        check(Mat3::zero(), 1e-12);
        check(Mat3::diag([2.0, 2.0, 2.0]), 1e-12);
        check(Mat3::diag([1.0, -1.0, 1.0]), 1e-12);
        check(Mat3::diag([3.0, 1e-9, 0.0]), 1e-12);
        check(
            Mat3::from_array([1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 1.0, 0.0, 1.0]),
            1e-12,
        );
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        for _ in 0..2000 {
            let f = Mat3::from_array(std::array::from_fn(|_| rnd()));
            check(f, 1e-11);
            let near = Mat3::identity() + Mat3::from_array(std::array::from_fn(|_| 1e-4 * rnd()));
            check(near, 1e-12);
        }
    }

    #[test]
    fn svd_f32_is_accurate_near_identity() {
        let f = Mat3::<f32>::from_array([1.001, 0.002, 0.0, -0.001, 0.999, 0.0005, 0.0, 0.0, 1.0]);
        let s = svd3(f);
        let r = s.compose(s.sigma);
        assert!((r - f).frobenius() < 1e-6);
    }
}
