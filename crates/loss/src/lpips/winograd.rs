//! Winograd minimal-filtering convolution `F(m x m, r x r)` (Lavin & Gray 2016) for the
//! stride-1 layers of the LPIPS backbones: `F(2x2, 3x3)` needs 16 products per 4 outputs
//! instead of 36, `F(2x2, 5x5)` 36 instead of 100, and the products are `alpha^2` GEMMs
//! (`Cout x Cin` times `Cin x tiles`) that run at the GEMM's speed.
//!
//! The transforms are built here by the Cook-Toom construction from the interpolation points
//! `0, 1, -1, 2, -2, 1/2, -1/2, ...` and infinity: `A^T[i][j] = p_j^i`, `G[j][k] = p_j^k / prod_{l != j}
//! (p_j - p_l)` (infinity: the last rows/columns select the leading coefficient), and `B^T`
//! solved (f64 least squares, exact for these points) from the bilinear identity
//! `sum_j A^T[i][j] G[j][k] B^T[j][n] = [n == i + k]`; a unit test checks the identity.

/// The 1-D transform matrices of `F(m, r)`, `alpha = m + r - 1` (row-major, f64).
#[derive(Clone, Debug)]
pub(crate) struct Transform {
    pub m: usize,
    pub r: usize,
    pub alpha: usize,
    /// `m x alpha`.
    pub at: Vec<f64>,
    /// `alpha x r`.
    pub g: Vec<f64>,
    /// `alpha x alpha`.
    pub bt: Vec<f64>,
}

impl Transform {
    /// `F(m, r)`; `m + r - 1 <= 8`.
    pub fn new(m: usize, r: usize) -> Transform {
        let alpha = m + r - 1;
        assert!((2..=8).contains(&alpha) && m >= 1 && r >= 1);
        // Finite points (alpha - 1 of them), then infinity. Small points keep the
        // transforms' entries, and so the f32 round-off, small (Barabasz et al. 2020).
        const POINTS: [f64; 9] = [0.0, 1.0, -1.0, 2.0, -2.0, 0.5, -0.5, 3.0, -3.0];
        let pts: Vec<f64> = POINTS[..alpha - 1].to_vec();
        let mut at = vec![0.0; m * alpha];
        let mut g = vec![0.0; alpha * r];
        for (j, &p) in pts.iter().enumerate() {
            let norm: f64 = pts
                .iter()
                .enumerate()
                .filter(|&(l, _)| l != j)
                .map(|(_, &q)| p - q)
                .product();
            for i in 0..m {
                at[i * alpha + j] = p.powi(i as i32);
            }
            for k in 0..r {
                g[j * r + k] = p.powi(k as i32) / norm;
            }
        }
        at[(m - 1) * alpha + alpha - 1] = 1.0;
        g[(alpha - 1) * r + r - 1] = 1.0;
        // Solve B^T column by column: K b = e, K[(i, k), j] = A^T[i][j] G[j][k].
        let rows = m * r;
        let mut kmat = vec![0.0; rows * alpha];
        for i in 0..m {
            for k in 0..r {
                for j in 0..alpha {
                    kmat[(i * r + k) * alpha + j] = at[i * alpha + j] * g[j * r + k];
                }
            }
        }
        let mut bt = vec![0.0; alpha * alpha];
        for n in 0..alpha {
            let rhs: Vec<f64> = (0..rows)
                .map(|ik| if ik / r + ik % r == n { 1.0 } else { 0.0 })
                .collect();
            let b = least_squares(&kmat, rows, alpha, &rhs);
            for j in 0..alpha {
                // The entries are small rationals; snap away the solver's round-off.
                let snapped = (b[j] * 720.0).round() / 720.0;
                bt[j * alpha + n] = if (snapped - b[j]).abs() < 1e-9 {
                    snapped
                } else {
                    b[j]
                };
            }
        }
        Transform {
            m,
            r,
            alpha,
            at,
            g,
            bt,
        }
    }
}

/// `argmin |K x - y|` for a full-column-rank `rows x cols` K (normal equations, Gaussian
/// elimination with partial pivoting, f64; the systems here are at most 8 x 8).
fn least_squares(k: &[f64], rows: usize, cols: usize, y: &[f64]) -> Vec<f64> {
    let mut a = vec![0.0; cols * (cols + 1)];
    for i in 0..cols {
        for j in 0..cols {
            a[i * (cols + 1) + j] = (0..rows).map(|r| k[r * cols + i] * k[r * cols + j]).sum();
        }
        a[i * (cols + 1) + cols] = (0..rows).map(|r| k[r * cols + i] * y[r]).sum();
    }
    let w = cols + 1;
    for c in 0..cols {
        let p = (c..cols)
            .max_by(|&x, &z| a[x * w + c].abs().total_cmp(&a[z * w + c].abs()))
            .unwrap();
        for j in 0..w {
            a.swap(c * w + j, p * w + j);
        }
        for r in 0..cols {
            if r != c {
                let f = a[r * w + c] / a[c * w + c];
                for j in c..w {
                    a[r * w + j] -= f * a[c * w + j];
                }
            }
        }
    }
    (0..cols).map(|c| a[c * w + cols] / a[c * w + c]).collect()
}

/// `out (p x q) = left (p x n) * mid (n x n) * right^T (q x n)`, f32 scratch-free for n <= 8.
#[inline]
pub(crate) fn sandwich(left: &[f32], p: usize, mid: &[f32], n: usize, out: &mut [f32]) {
    // tmp = left * mid (p x n), out = tmp * left^T (p x p).
    let mut tmp = [0.0f32; 64];
    for i in 0..p {
        for j in 0..n {
            let mut s = 0.0;
            for l in 0..n {
                s += left[i * n + l] * mid[l * n + j];
            }
            tmp[i * n + j] = s;
        }
    }
    for i in 0..p {
        for j in 0..p {
            let mut s = 0.0;
            for l in 0..n {
                s += tmp[i * n + l] * left[j * n + l];
            }
            out[i * p + j] = s;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transforms_satisfy_the_bilinear_identity() {
        for (m, r) in [(2, 3), (2, 5), (4, 3), (3, 3)] {
            let t = Transform::new(m, r);
            let a = t.alpha;
            for i in 0..m {
                for k in 0..r {
                    for n in 0..a {
                        let s: f64 = (0..a)
                            .map(|j| t.at[i * a + j] * t.g[j * r + k] * t.bt[j * a + n])
                            .sum();
                        let want = if n == i + k { 1.0 } else { 0.0 };
                        assert!((s - want).abs() < 1e-12, "F({m},{r}) ({i},{k},{n}): {s}");
                    }
                }
            }
        }
        // F(2, 3) from these points is Lavin's: B^T rows (1,0,-1,0), (0,1,1,0), (0,-1,1,0), (0,-1,0,1) up to sign.
        let t = Transform::new(2, 3);
        assert!(t.bt.iter().all(|v| v.fract() == 0.0), "{:?}", t.bt);
    }

    #[test]
    fn one_dimensional_correlation_is_exact() {
        for (m, r) in [(2, 3), (2, 5)] {
            let t = Transform::new(m, r);
            let d: Vec<f64> = (0..t.alpha).map(|i| (i as f64 * 0.7).sin()).collect();
            let g: Vec<f64> = (0..r).map(|i| (i as f64 * 1.3).cos()).collect();
            let u: Vec<f64> = (0..t.alpha)
                .map(|j| (0..r).map(|k| t.g[j * r + k] * g[k]).sum())
                .collect();
            let v: Vec<f64> = (0..t.alpha)
                .map(|j| (0..t.alpha).map(|n| t.bt[j * t.alpha + n] * d[n]).sum())
                .collect();
            for i in 0..m {
                let y: f64 = (0..t.alpha)
                    .map(|j| t.at[i * t.alpha + j] * u[j] * v[j])
                    .sum();
                let want: f64 = (0..r).map(|k| g[k] * d[i + k]).sum();
                assert!((y - want).abs() < 1e-12);
            }
        }
    }
}
