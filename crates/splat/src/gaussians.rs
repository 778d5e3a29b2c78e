//! The Gaussian scene: raw, unconstrained parameters as an INRIA 3DGS PLY stores them, and an
//! optional per-Gaussian deformation (the simulation's positions and deformation gradients).

use crate::error::{Error, Result};

/// Number of SH coefficients per channel for a degree: `(degree + 1)^2`.
pub fn sh_coeffs(degree: u32) -> usize {
    ((degree + 1) * (degree + 1)) as usize
}

/// Gaussians with the raw values the renderer differentiates (see the crate docs for the
/// activations): positions, natural-log scales, unnormalised quaternions `(w, x, y, z)`,
/// opacity logits and SH coefficients `sh[n][k][c]` (`k < (degree + 1)^2`, `c` = r, g, b).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Gaussians {
    /// SH degree (0..=3).
    pub sh_degree: u32,
    /// Centres, world frame.
    pub means: Vec<[f32; 3]>,
    /// Natural logarithms of the three scales.
    pub log_scales: Vec<[f32; 3]>,
    /// Rotation quaternions `(w, x, y, z)`, not necessarily unit length.
    pub quats: Vec<[f32; 4]>,
    /// Opacity logits (opacity = sigmoid(logit)).
    pub opacity_logits: Vec<f32>,
    /// SH coefficients, `[n][k][c]` flattened: `sh[(n * K + k) * 3 + c]`.
    pub sh: Vec<f32>,
}

impl Gaussians {
    /// Appends one Gaussian of SH degree 0 (the scene's degree must be 0): centre `mean`,
    /// standard deviations `scales` along the axes rotated by `quat` (`(w, x, y, z)`),
    /// `opacity` in (0, 1) and colour `rgb` in [0, 1].
    pub fn push_rgb(
        &mut self,
        mean: [f32; 3],
        scales: [f32; 3],
        quat: [f32; 4],
        opacity: f32,
        rgb: [f32; 3],
    ) {
        debug_assert_eq!(self.sh_degree, 0, "push_rgb appends degree-0 Gaussians");
        self.means.push(mean);
        self.log_scales.push(scales.map(f32::ln));
        self.quats.push(quat);
        let o = opacity.clamp(1e-6, 1.0 - 1e-6);
        self.opacity_logits.push((o / (1.0 - o)).ln());
        self.sh
            .extend(rgb.map(|v| (v - 0.5) / crate::sh::SH_C0 as f32));
    }

    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.means.len()
    }

    /// True when there are no Gaussians.
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// SH coefficients per channel.
    pub fn k(&self) -> usize {
        sh_coeffs(self.sh_degree)
    }

    /// The SH coefficients of Gaussian `i`, `[k][c]` flattened.
    pub fn sh_of(&self, i: usize) -> &[f32] {
        let k = self.k() * 3;
        &self.sh[i * k..(i + 1) * k]
    }

    /// Checks array lengths, the degree and finiteness; `what` names the source in errors.
    pub fn validate(&self, what: &str) -> Result<()> {
        let n = self.len();
        if self.sh_degree > 3 {
            return Err(Error::Mismatch(format!(
                "{what}: SH degree {} (at most 3)",
                self.sh_degree
            )));
        }
        let lens = [
            ("log_scales", self.log_scales.len(), n),
            ("quats", self.quats.len(), n),
            ("opacity_logits", self.opacity_logits.len(), n),
            ("sh", self.sh.len(), n * self.k() * 3),
        ];
        for (name, got, want) in lens {
            if got != want {
                return Err(Error::Mismatch(format!(
                    "{what}: {name} has {got} values, expected {want}"
                )));
            }
        }
        let bad = |field: &str, i: usize| {
            Err(Error::Mismatch(format!(
                "{what}: Gaussian {i}: {field} is not finite"
            )))
        };
        for i in 0..n {
            if self.means[i].iter().any(|v| !v.is_finite()) {
                return bad("position", i);
            }
            if self.log_scales[i].iter().any(|v| !v.is_finite()) {
                return bad("scale", i);
            }
            if self.quats[i].iter().any(|v| !v.is_finite()) {
                return bad("rotation", i);
            }
            if self.quats[i].iter().all(|v| *v == 0.0) {
                return Err(Error::Mismatch(format!(
                    "{what}: Gaussian {i}: rotation quaternion is zero"
                )));
            }
            if !self.opacity_logits[i].is_finite() {
                return bad("opacity", i);
            }
            if self.sh_of(i).iter().any(|v| !v.is_finite()) {
                return bad("SH coefficient", i);
            }
        }
        Ok(())
    }

    /// The Gaussians at `idx`, in that order.
    pub fn select(&self, idx: &[usize]) -> Gaussians {
        let k = self.k() * 3;
        Gaussians {
            sh_degree: self.sh_degree,
            means: idx.iter().map(|&i| self.means[i]).collect(),
            log_scales: idx.iter().map(|&i| self.log_scales[i]).collect(),
            quats: idx.iter().map(|&i| self.quats[i]).collect(),
            opacity_logits: idx.iter().map(|&i| self.opacity_logits[i]).collect(),
            sh: idx
                .iter()
                .flat_map(|&i| self.sh[i * k..(i + 1) * k].iter().copied())
                .collect(),
        }
    }
}

/// A per-Gaussian deformation, PhysGaussian style: Gaussian `i` is drawn at `means[i]` with
/// covariance `F_i Sigma_i F_i^T`, and its SH is evaluated at `R_i^T d`, `F_i = R_i S_i` (polar
/// decomposition). `f[i][r][c] = d x'_r / d X_c`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Deformation {
    /// Current centres (replace [`Gaussians::means`]).
    pub means: Vec<[f32; 3]>,
    /// Deformation gradients, row-major.
    pub f: Vec<[[f32; 3]; 3]>,
}

impl Deformation {
    /// Checks lengths against `n` Gaussians and finiteness.
    pub fn validate(&self, n: usize, what: &str) -> Result<()> {
        if self.means.len() != n || self.f.len() != n {
            return Err(Error::Mismatch(format!(
                "{what}: deformation has {} positions and {} F for {n} Gaussians",
                self.means.len(),
                self.f.len()
            )));
        }
        for i in 0..n {
            if self.means[i].iter().any(|v| !v.is_finite())
                || self.f[i].iter().flatten().any(|v| !v.is_finite())
            {
                return Err(Error::Mismatch(format!(
                    "{what}: deformed Gaussian {i}: position or F is not finite"
                )));
            }
        }
        Ok(())
    }
}

/// Gradients of a scalar loss with respect to the raw parameters of [`Gaussians`] (and the
/// deformation, when one was used). Same layouts as the inputs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GaussianGrads {
    /// dL/d(position); with a deformation: dL/d(deformed position).
    pub means: Vec<[f32; 3]>,
    /// dL/d(log scale).
    pub log_scales: Vec<[f32; 3]>,
    /// dL/d(unnormalised quaternion).
    pub quats: Vec<[f32; 4]>,
    /// dL/d(opacity logit).
    pub opacity_logits: Vec<f32>,
    /// dL/d(SH coefficient), `[n][k][c]`.
    pub sh: Vec<f32>,
    /// dL/dF, row-major (empty without a deformation).
    pub f: Vec<[[f32; 3]; 3]>,
}
