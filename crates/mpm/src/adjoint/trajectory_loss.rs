//! Losses between simulated and target particle positions, with their gradients: a position
//! loss when particles correspond one to one, and a symmetric Chamfer loss when they do not
//! (PAC-NeRF's ground-truth clouds have other point counts).

use crate::math::Real;

/// Which trajectory loss to use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrajectoryLoss {
    /// Mean squared distance between corresponding particles: `(1/N) sum |x_p - y_p|^2`.
    Position,
    /// Symmetric Chamfer: `(1/N) sum_p min_q |x_p - y_q|^2 + (1/M) sum_q min_p |y_q - x_p|^2`.
    Chamfer,
}

fn d2<T: Real>(a: [T; 3], b: [f32; 3]) -> T {
    (0..3).fold(T::zero(), |s, i| {
        let d = a[i] - T::c(b[i] as f64);
        s + d * d
    })
}

/// Index of the point of `cloud` nearest to `p` (brute force; clouds here are small).
fn nearest<T: Real>(p: [T; 3], cloud: &[[f32; 3]]) -> usize {
    let mut best = (0usize, T::infinity());
    for (q, y) in cloud.iter().enumerate() {
        let d = d2(p, *y);
        if d < best.1 {
            best = (q, d);
        }
    }
    best.0
}

impl TrajectoryLoss {
    /// The loss of positions `x` against `target` and its gradient with respect to `x`
    /// (added to `grad`).
    pub fn value_and_grad<T: Real>(
        self,
        x: &[[T; 3]],
        target: &[[f32; 3]],
        grad: &mut [[T; 3]],
    ) -> T {
        let n = T::c(x.len() as f64);
        let two = T::c(2.0);
        match self {
            TrajectoryLoss::Position => {
                assert_eq!(
                    x.len(),
                    target.len(),
                    "position loss needs corresponding particles"
                );
                let mut l = T::zero();
                for (p, (xp, yp)) in x.iter().zip(target).enumerate() {
                    l += d2(*xp, *yp);
                    for a in 0..3 {
                        grad[p][a] += two * (xp[a] - T::c(yp[a] as f64)) / n;
                    }
                }
                l / n
            }
            TrajectoryLoss::Chamfer => {
                let m = T::c(target.len() as f64);
                let mut l = T::zero();
                for (p, xp) in x.iter().enumerate() {
                    let q = nearest(*xp, target);
                    l += d2(*xp, target[q]) / n;
                    for a in 0..3 {
                        grad[p][a] += two * (xp[a] - T::c(target[q][a] as f64)) / n;
                    }
                }
                for y in target {
                    let yp = y.map(|c| T::c(c as f64));
                    let mut best = (0usize, T::infinity());
                    for (p, xp) in x.iter().enumerate() {
                        let d =
                            (0..3).fold(T::zero(), |s, i| s + (xp[i] - yp[i]) * (xp[i] - yp[i]));
                        if d < best.1 {
                            best = (p, d);
                        }
                    }
                    l += best.1 / m;
                    for a in 0..3 {
                        grad[best.0][a] += two * (x[best.0][a] - yp[a]) / m;
                    }
                }
                l
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gradients_match_finite_differences() {
        let x: Vec<[f64; 3]> = vec![[0.1, 0.2, 0.3], [0.5, 0.4, 0.2], [0.9, 0.1, 0.7]];
        let y: Vec<[f32; 3]> = vec![
            [0.12, 0.19, 0.33],
            [0.52, 0.41, 0.18],
            [0.88, 0.12, 0.69],
            [0.3, 0.3, 0.3],
        ];
        for (loss, target) in [
            (TrajectoryLoss::Position, &y[..3]),
            (TrajectoryLoss::Chamfer, &y[..]),
        ] {
            let mut g = vec![[0.0; 3]; 3];
            let _ = loss.value_and_grad(&x, target, &mut g);
            for p in 0..3 {
                for a in 0..3 {
                    let f = |h: f64| {
                        let mut x2 = x.clone();
                        x2[p][a] += h;
                        loss.value_and_grad(&x2, target, &mut [[0.0; 3]; 3])
                    };
                    let fd = (f(1e-6) - f(-1e-6)) / 2e-6;
                    assert!(
                        (fd - g[p][a]).abs() < 1e-6,
                        "{loss:?} {p} {a}: {fd} vs {}",
                        g[p][a]
                    );
                }
            }
        }
    }
}
