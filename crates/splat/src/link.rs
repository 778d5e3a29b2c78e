//! The simulation link: which Gaussians are simulated particles, and the similarity transform
//! between the scene's world frame and the simulation's (normalised) space.
//!
//! A point maps as `x_sim = scale * (R x_world - centre) + shift`. Particle `s` of a simulated
//! frame moves Gaussian `simulated[s]`; particles past `simulated.len()` are interior filling
//! particles (simulated, never rendered). Gaussians not in `simulated` are static background:
//! rendered unchanged. A simulated deformation gradient `F_sim` becomes `R^T F_sim R` in the
//! world frame (the uniform scale cancels).

use crate::error::{Error, Result};
use crate::gaussians::{Deformation, Gaussians};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// How a scene's Gaussians map to simulation particles (`link.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SimLink {
    /// Gaussians in the scene file.
    pub scene_gaussians: usize,
    /// Scene indices of the simulated Gaussians, in particle order.
    pub simulated: Vec<u32>,
    /// Number of filling particles after the simulated Gaussians.
    #[serde(default)]
    pub filled: usize,
    /// World-to-simulation rotation `R` (row-major).
    pub rotation: [[f64; 3]; 3],
    /// Centre subtracted after the rotation.
    pub centre: [f64; 3],
    /// Uniform scale.
    pub scale: f64,
    /// Offset added last.
    pub shift: [f64; 3],
}

impl SimLink {
    /// Every Gaussian simulated in world coordinates (particle `i` = Gaussian `i`).
    pub fn identity(n: usize) -> Self {
        SimLink {
            scene_gaussians: n,
            simulated: (0..n as u32).collect(),
            filled: 0,
            rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            centre: [0.0; 3],
            scale: 1.0,
            shift: [0.0; 3],
        }
    }

    /// Reads `link.json`.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let l: SimLink = serde_json::from_str(&text).map_err(|e| {
            Error::Mismatch(format!("{}: not a simulation link: {e}", path.display()))
        })?;
        l.validate(&path.display().to_string())?;
        Ok(l)
    }

    /// Writes `link.json`.
    pub fn save(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string_pretty(self).expect("serialisable");
        std::fs::write(path, text).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })
    }

    /// Checks indices, the rotation and the scale.
    pub fn validate(&self, what: &str) -> Result<()> {
        let bad = |m: String| Err(Error::Mismatch(format!("{what}: {m}")));
        if let Some(&i) = self
            .simulated
            .iter()
            .find(|&&i| i as usize >= self.scene_gaussians)
        {
            return bad(format!(
                "simulated Gaussian {i} is past the scene's {} Gaussians",
                self.scene_gaussians
            ));
        }
        if !(self.scale.is_finite() && self.scale > 0.0) {
            return bad(format!("scale {} must be positive", self.scale));
        }
        let r = &self.rotation;
        for i in 0..3 {
            for j in 0..3 {
                let d: f64 = (0..3).map(|k| r[i][k] * r[j][k]).sum();
                if (d - (i == j) as u8 as f64).abs() > 1e-6 {
                    return bad("rotation is not orthonormal".into());
                }
            }
        }
        Ok(())
    }

    /// World point -> simulation space.
    pub fn to_sim(&self, x: [f64; 3]) -> [f64; 3] {
        let r = &self.rotation;
        [0, 1, 2].map(|i| {
            let rx = r[i][0] * x[0] + r[i][1] * x[1] + r[i][2] * x[2];
            self.scale * (rx - self.centre[i]) + self.shift[i]
        })
    }

    /// Simulation point -> world.
    pub fn to_world(&self, x: [f64; 3]) -> [f64; 3] {
        let r = &self.rotation;
        let y = [0, 1, 2].map(|i| (x[i] - self.shift[i]) / self.scale + self.centre[i]);
        [0, 1, 2].map(|j| r[0][j] * y[0] + r[1][j] * y[1] + r[2][j] * y[2])
    }

    /// A simulated deformation gradient in the world frame: `R^T F R`.
    pub fn f_to_world(&self, f: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
        let r = &self.rotation;
        let mut fr = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                fr[i][j] = (0..3).map(|k| f[i][k] * r[k][j]).sum();
            }
        }
        let mut out = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                out[i][j] = (0..3).map(|k| r[k][i] * fr[k][j]).sum();
            }
        }
        out
    }

    /// The deformation of `scene` by one simulated frame: particle positions (simulation
    /// space) and, when given, their deformation gradients. Static Gaussians keep their place
    /// and get `F = I`.
    pub fn deformation(
        &self,
        scene: &Gaussians,
        x: &[[f32; 3]],
        f: Option<&[[[f32; 3]; 3]]>,
        what: &str,
    ) -> Result<Deformation> {
        if scene.len() != self.scene_gaussians {
            return Err(Error::Mismatch(format!(
                "{what}: the link is for {} Gaussians, the scene has {}",
                self.scene_gaussians,
                scene.len()
            )));
        }
        let need = self.simulated.len();
        if x.len() < need || x.len() != need + self.filled && self.filled > 0 {
            return Err(Error::Mismatch(format!(
                "{what}: {} particles, the link expects {} simulated Gaussians{}",
                x.len(),
                need,
                if self.filled > 0 {
                    format!(" + {} filling particles", self.filled)
                } else {
                    String::new()
                }
            )));
        }
        if let Some(f) = f {
            if f.len() != x.len() {
                return Err(Error::Mismatch(format!(
                    "{what}: {} positions but {} deformation gradients",
                    x.len(),
                    f.len()
                )));
            }
        }
        let eye = [[1.0f32, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let mut d = Deformation {
            means: scene.means.clone(),
            f: vec![eye; scene.len()],
        };
        for (s, &g) in self.simulated.iter().enumerate() {
            let p = self.to_world(x[s].map(|v| v as f64));
            if p.iter().any(|v| !v.is_finite()) {
                return Err(Error::Mismatch(format!(
                    "{what}: particle {s} has a non-finite position"
                )));
            }
            d.means[g as usize] = p.map(|v| v as f32);
            if let Some(f) = f {
                let fw = self.f_to_world(&f[s].map(|r| r.map(|v| v as f64)));
                if fw.iter().flatten().any(|v| !v.is_finite()) {
                    return Err(Error::Mismatch(format!(
                        "{what}: particle {s} has a non-finite deformation gradient"
                    )));
                }
                d.f[g as usize] = fw.map(|r| r.map(|v| v as f32));
            }
        }
        Ok(d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn maps_round_trip_and_conjugate_f() {
        let (c, s) = (0.6f64.cos(), 0.6f64.sin());
        let l = SimLink {
            scene_gaussians: 3,
            simulated: vec![2, 0],
            filled: 1,
            rotation: [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
            centre: [0.1, 0.2, 0.3],
            scale: 2.5,
            shift: [1.0, 1.0, 1.0],
        };
        l.validate("t").unwrap();
        let x = [0.3, -0.7, 1.9];
        let y = l.to_world(l.to_sim(x));
        assert!((0..3).all(|i| (x[i] - y[i]).abs() < 1e-12));
        // A rotation about world z by F in sim space (about sim z) is the same rotation.
        let f = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        let fw = l.f_to_world(&f);
        assert!((fw[0][1] + 1.0).abs() < 1e-12 && (fw[1][0] - 1.0).abs() < 1e-12);
    }
}
