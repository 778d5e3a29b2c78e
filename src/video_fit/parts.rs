//! Part labels of a scene's Gaussians (the file `r4d segment` writes, or a PLY with a `part`
//! property) and their transfer onto simulation particles.

use super::FitError;
use r4d_splat::SimLink;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Part labels per Gaussian: `{"num_parts": M, "class_names": [...], "labels": [...],
/// "confidence": [...], "counts": [...]}`; label -1 is static background.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PartLabels {
    /// Number of parts `M` (labels are in `-1 .. M`).
    pub num_parts: usize,
    /// Part names (may be empty).
    #[serde(default)]
    pub class_names: Vec<String>,
    /// One label per Gaussian, -1 for static.
    pub labels: Vec<i32>,
    /// Confidence per Gaussian (may be empty).
    #[serde(default)]
    pub confidence: Vec<f32>,
    /// Gaussians per part (may be empty).
    #[serde(default)]
    pub counts: Vec<usize>,
}

impl PartLabels {
    /// Reads the JSON file or a PLY with an integer-valued `part` property (negative: static).
    pub fn load(path: &Path) -> Result<PartLabels, FitError> {
        let file = path.display();
        let is_ply = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("ply"));
        let labels = if is_ply {
            let ply = r4d_mpm::ply::read_ply(path)?;
            let col = ply.get("part").ok_or_else(|| {
                FitError::Input(format!(
                    "{file}: no 'part' property (one label per Gaussian)"
                ))
            })?;
            let mut labels = Vec::with_capacity(col.len());
            for (i, &v) in col.iter().enumerate() {
                if !v.is_finite() || v.fract() != 0.0 {
                    return Err(FitError::Input(format!(
                        "{file}: vertex {i}: part {v} is not an integer"
                    )));
                }
                labels.push(if v < 0.0 { -1 } else { v as i32 });
            }
            let num_parts = labels.iter().map(|&l| l + 1).max().unwrap_or(0).max(0) as usize;
            PartLabels {
                num_parts,
                labels,
                ..Default::default()
            }
        } else {
            let text = std::fs::read_to_string(path)
                .map_err(|e| FitError::Input(format!("{file}: {e}")))?;
            serde_json::from_str(&text)
                .map_err(|e| FitError::Input(format!("{file}: not a parts file: {e}")))?
        };
        labels
            .validate()
            .map_err(|m| FitError::Input(format!("{file}: {m}")))?;
        Ok(labels)
    }

    /// Checks labels against `num_parts`.
    pub fn validate(&self) -> Result<(), String> {
        if let Some((i, &l)) = self
            .labels
            .iter()
            .enumerate()
            .find(|(_, &l)| l < -1 || l >= self.num_parts as i32)
        {
            return Err(format!(
                "labels[{i}] = {l} is outside -1 .. {} (num_parts {})",
                self.num_parts as i32 - 1,
                self.num_parts
            ));
        }
        if !self.confidence.is_empty() && self.confidence.len() != self.labels.len() {
            return Err(format!(
                "{} confidences for {} labels",
                self.confidence.len(),
                self.labels.len()
            ));
        }
        Ok(())
    }

    /// A link that simulates every labelled Gaussian, in scene order, in world coordinates.
    pub fn identity_link(&self) -> SimLink {
        let mut l = SimLink::identity(self.labels.len());
        l.simulated = (0..self.labels.len() as u32)
            .filter(|&i| self.labels[i as usize] >= 0)
            .collect();
        l
    }

    /// The part of every particle: simulated Gaussian `link.simulated[s]` gives particle `s`
    /// its label; filling particles take the label of the nearest labelled particle (by rest
    /// position, kd-tree). A simulated Gaussian labelled static is an error.
    pub fn particle_parts(&self, link: &SimLink, x: &[[f32; 3]]) -> Result<Vec<u32>, FitError> {
        if self.labels.len() != link.scene_gaussians {
            return Err(FitError::Input(format!(
                "the parts file labels {} Gaussians, the scene has {}",
                self.labels.len(),
                link.scene_gaussians
            )));
        }
        let ns = link.simulated.len();
        if x.len() < ns {
            return Err(FitError::Input(format!(
                "{} particles for {ns} simulated Gaussians",
                x.len()
            )));
        }
        let mut out = Vec::with_capacity(x.len());
        for (s, &g) in link.simulated.iter().enumerate() {
            let l = self.labels[g as usize];
            if l < 0 {
                return Err(FitError::Input(format!(
                    "Gaussian {g} (particle {s}) is simulated but labelled static (-1)"
                )));
            }
            out.push(l as u32);
        }
        if x.len() > ns {
            if ns == 0 {
                return Err(FitError::Input(
                    "filling particles but no labelled particle to copy a label from".into(),
                ));
            }
            let pts: Vec<[f64; 3]> = x[..ns].iter().map(|p| p.map(|v| v as f64)).collect();
            let tree: kiddo::ImmutableKdTree<f64, 3> = kiddo::ImmutableKdTree::new_from_slice(&pts);
            for p in &x[ns..] {
                let nn = tree.nearest_one::<kiddo::SquaredEuclidean>(&p.map(|v| v as f64));
                out.push(out[nn.item as usize]);
            }
        }
        Ok(out)
    }
}
