//! The simulation link: which Gaussians are simulated particles, and the similarity transform
//! between the scene's world frame and the simulation's (normalised) space.
//!
//! A point maps as `x_sim = scale * (R x_world - centre) + shift`. Particle `s` of a simulated
//! frame moves Gaussian `simulated[s]`; particles past `simulated.len()` are interior filling
//! particles (simulated, never rendered). Gaussians not in `simulated` are static background:
//! rendered unchanged. A simulated deformation gradient `F_sim` becomes `R^T F_sim R` in the
//! world frame (the uniform scale cancels).

use crate::error::{Error, Result};
use crate::gaussians::{Deformation, GaussianGrads, Gaussians};
use crate::kernels::LinkConsts;
#[cfg(doc)]
use crate::kernels::SplatKernels;
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
        let text =
            r4d_fsio::read_to_string_bounded(path, r4d_fsio::MAX_TEXT_BYTES).map_err(|source| {
                Error::Io {
                    path: path.to_path_buf(),
                    source,
                }
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
        r4d_fsio::write_atomic(path, text.as_bytes()).map_err(|source| Error::Io {
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
        // Exactly the link's particles: a frame from another simulation (more or fewer
        // particles) would silently move the wrong Gaussians.
        if x.len() != need + self.filled {
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

    /// The VJP of [`SimLink::deformation`]: adds the gradient with respect to the particles'
    /// positions and row-major deformation gradients (simulation space) of a loss whose
    /// gradient with respect to the deformed Gaussians is `g` (`g.means`, `g.f`: the
    /// renderer's, world space) to `dx` and `df` (one entry per particle; filling particles
    /// get nothing). `x_world = R^T ((x_sim - shift) / scale + centre)` gives
    /// `dL/dx_sim = R dL/dx_world / scale`; `F_world = R^T F_sim R` gives
    /// `dL/dF_sim = R dL/dF_world R^T`.
    pub fn deformation_vjp(
        &self,
        g: &GaussianGrads,
        dx: &mut [[f32; 3]],
        df: &mut [[f32; 9]],
    ) -> Result<()> {
        let n = self.simulated.len();
        if g.means.len() != self.scene_gaussians
            || (!g.f.is_empty() && g.f.len() != self.scene_gaussians)
            || dx.len() < n
            || df.len() < n
        {
            return Err(Error::Mismatch(format!(
                "link VJP: gradients of {} Gaussians ({} F) into {} positions and {} F; the link maps {} of {} Gaussians",
                g.means.len(),
                g.f.len(),
                dx.len(),
                df.len(),
                n,
                self.scene_gaussians
            )));
        }
        let rot = self.rotation;
        for (p, &gi) in self.simulated.iter().enumerate() {
            let gm = g.means[gi as usize];
            for a in 0..3 {
                dx[p][a] +=
                    ((0..3).map(|b| rot[a][b] * gm[b] as f64).sum::<f64>() / self.scale) as f32;
            }
            let Some(gf) = g.f.get(gi as usize) else {
                continue;
            };
            for a in 0..3 {
                for b in 0..3 {
                    let mut v = 0.0;
                    for c in 0..3 {
                        for e in 0..3 {
                            v += rot[a][c] * gf[c][e] as f64 * rot[b][e];
                        }
                    }
                    df[p][a * 3 + b] += v as f32;
                }
            }
        }
        Ok(())
    }
}

impl SimLink {
    /// The link as the kernels take it ([`SplatKernels::deform`]).
    pub fn consts(&self) -> LinkConsts {
        let r = &self.rotation;
        // t = R^T (centre - shift / scale)
        let c: [f64; 3] = [0, 1, 2].map(|i| self.centre[i] - self.shift[i] / self.scale);
        LinkConsts {
            to_world: [0, 1, 2].map(|i| {
                let t: f64 = (0..3).map(|k| r[k][i] * c[k]).sum();
                [
                    (r[0][i] / self.scale) as f32,
                    (r[1][i] / self.scale) as f32,
                    (r[2][i] / self.scale) as f32,
                    t as f32,
                ]
            }),
            rot: [0, 1, 2].map(|i| [r[i][0] as f32, r[i][1] as f32, r[i][2] as f32, 0.0]),
            inv_scale: (1.0 / self.scale) as f32,
            simulated: self.simulated.len() as u32,
            particles: (self.simulated.len() + self.filled) as u32,
            _pad: 0,
        }
    }
}

/// A particle's position (simulation space) in the world, in f32 as the kernels compute it:
/// `A x + t` ([`LinkConsts::to_world`]).
#[inline]
pub fn link_point(c: &LinkConsts, x: [f32; 3]) -> [f32; 3] {
    c.to_world
        .map(|r| r[0] * x[0] + r[1] * x[1] + r[2] * x[2] + r[3])
}

/// A particle's deformation gradient (row-major, simulation space) in the world frame:
/// `R^T F R`.
#[inline]
pub fn link_f(c: &LinkConsts, f: [f32; 9]) -> [[f32; 3]; 3] {
    let r = &c.rot;
    let mut fr = [[0.0f32; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            fr[i][j] = f[3 * i] * r[0][j] + f[3 * i + 1] * r[1][j] + f[3 * i + 2] * r[2][j];
        }
    }
    let mut out = [[0.0f32; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            out[i][j] = r[0][i] * fr[0][j] + r[1][i] * fr[1][j] + r[2][i] * fr[2][j];
        }
    }
    out
}

/// VJP of [`link_point`]: `dL/dx = R dL/dmean / scale`.
#[inline]
pub fn link_point_vjp(c: &LinkConsts, g: [f32; 3]) -> [f32; 3] {
    c.rot
        .map(|r| (r[0] * g[0] + r[1] * g[1] + r[2] * g[2]) * c.inv_scale)
}

/// VJP of [`link_f`]: `dL/dF = R dL/dF_world R^T` (row-major).
#[inline]
pub fn link_f_vjp(c: &LinkConsts, g: [[f32; 3]; 3]) -> [f32; 9] {
    let r = &c.rot;
    // R G, then (R G) R^T.
    let mut rg = [[0.0f32; 3]; 3];
    for a in 0..3 {
        for e in 0..3 {
            rg[a][e] = r[a][0] * g[0][e] + r[a][1] * g[1][e] + r[a][2] * g[2][e];
        }
    }
    let mut out = [0.0f32; 9];
    for a in 0..3 {
        for b in 0..3 {
            out[3 * a + b] = rg[a][0] * r[b][0] + rg[a][1] * r[b][1] + rg[a][2] * r[b][2];
        }
    }
    out
}

/// [`SplatKernels::deform`] on host slices (the reference and CPU backends): sizes as the
/// kernel's contract says (`x`, `f_sim` one entry per particle, `means`, `f` per Gaussian).
pub fn deform_host(
    c: &LinkConsts,
    simulated: &[u32],
    x: &[[f32; 3]],
    f_sim: &[[f32; 9]],
    means: &mut [[f32; 3]],
    f: &mut [[[f32; 3]; 3]],
) {
    for (s, &g) in simulated.iter().enumerate().take(c.simulated as usize) {
        means[g as usize] = link_point(c, x[s]);
        f[g as usize] = link_f(c, f_sim[s]);
    }
}

/// [`SplatKernels::deform_vjp`] on host slices (adds into `dx`, `df_sim`).
pub fn deform_vjp_host(
    c: &LinkConsts,
    simulated: &[u32],
    d_means: &[[f32; 3]],
    d_f: &[[[f32; 3]; 3]],
    dx: &mut [[f32; 3]],
    df_sim: &mut [[f32; 9]],
) {
    for (s, &g) in simulated.iter().enumerate().take(c.simulated as usize) {
        let gx = link_point_vjp(c, d_means[g as usize]);
        for a in 0..3 {
            dx[s][a] += gx[a];
        }
        let gf = link_f_vjp(c, d_f[g as usize]);
        for a in 0..9 {
            df_sim[s][a] += gf[a];
        }
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

    /// `deformation_vjp` against finite differences of `<g, deformation(x, F)>` (the map is
    /// affine, so central differences are exact up to f32 rounding of the deformed values).
    #[test]
    fn deformation_vjp_matches_finite_differences() {
        let (c, s) = (0.6f64.cos(), 0.6f64.sin());
        let (c2, s2) = (0.3f64.cos(), 0.3f64.sin());
        // A rotation about z then x.
        let rz = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]];
        let rx = [[1.0, 0.0, 0.0], [0.0, c2, -s2], [0.0, s2, c2]];
        let mut rot = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                rot[i][j] = (0..3).map(|k| rx[i][k] * rz[k][j]).sum();
            }
        }
        let l = SimLink {
            scene_gaussians: 4,
            simulated: vec![2, 0, 3],
            filled: 1,
            rotation: rot,
            centre: [0.1, 0.2, 0.3],
            scale: 2.5,
            shift: [1.0, 1.0, 1.0],
        };
        let scene = Gaussians {
            means: vec![[0.0; 3]; 4],
            log_scales: vec![[0.0; 3]; 4],
            quats: vec![[1.0, 0.0, 0.0, 0.0]; 4],
            opacity_logits: vec![0.0; 4],
            sh: vec![0.0; 4 * 48],
            ..Default::default()
        };
        let x: Vec<[f32; 3]> = (0..4)
            .map(|i| [0.9 + 0.1 * i as f32, 1.1 - 0.05 * i as f32, 1.3])
            .collect();
        let f: Vec<[[f32; 3]; 3]> = (0..4)
            .map(|i| {
                let a = 0.1 * i as f32;
                [[1.0 + a, 0.2, -0.1], [0.05, 0.9, a], [0.3, -a, 1.1]]
            })
            .collect();
        let g = GaussianGrads {
            means: (0..4)
                .map(|i| [0.3 - 0.1 * i as f32, 0.7, -0.2 * i as f32])
                .collect(),
            f: (0..4)
                .map(|i| {
                    let b = 0.2 * i as f32;
                    [[0.5, -b, 0.1], [b, 0.25, -0.4], [0.6, 0.1, -b]]
                })
                .collect(),
            ..Default::default()
        };
        let objective = |x: &[[f32; 3]], f: &[[[f32; 3]; 3]]| -> f64 {
            let d = l.deformation(&scene, x, Some(f), "t").unwrap();
            let mut v = 0.0;
            for i in 0..4 {
                for a in 0..3 {
                    v += g.means[i][a] as f64 * d.means[i][a] as f64;
                    for b in 0..3 {
                        v += g.f[i][a][b] as f64 * d.f[i][a][b] as f64;
                    }
                }
            }
            v
        };
        let mut dx = vec![[0.0f32; 3]; 4];
        let mut df = vec![[0.0f32; 9]; 4];
        l.deformation_vjp(&g, &mut dx, &mut df).unwrap();
        let h = 1e-2f32;
        for p in 0..4 {
            for a in 0..3 {
                let (mut xp, mut xm) = (x.clone(), x.clone());
                xp[p][a] += h;
                xm[p][a] -= h;
                let fd = (objective(&xp, &f) - objective(&xm, &f)) / (2.0 * h as f64);
                assert!(
                    (fd - dx[p][a] as f64).abs() < 1e-4,
                    "x[{p}][{a}]: {fd} vs {}",
                    dx[p][a]
                );
                for b in 0..3 {
                    let (mut fp, mut fm) = (f.clone(), f.clone());
                    fp[p][a][b] += h;
                    fm[p][a][b] -= h;
                    let fd = (objective(&x, &fp) - objective(&x, &fm)) / (2.0 * h as f64);
                    let an = df[p][a * 3 + b] as f64;
                    assert!((fd - an).abs() < 1e-4, "F[{p}][{a}][{b}]: {fd} vs {an}");
                }
            }
        }
        // A frame from another simulation (one particle more) is refused, not mangled.
        let mut more = x.clone();
        more.push([1.0; 3]);
        assert!(l.deformation(&scene, &more, None, "t").is_err());
        assert!(l.deformation(&scene, &x[..3], None, "t").is_err());
        // The filling particle (index 3 of 4: simulated has 3 entries) gets nothing.
        assert_eq!(dx[3], [0.0; 3]);
        // Mismatched sizes are an error, not an out-of-bounds write.
        assert!(l.deformation_vjp(&g, &mut dx[..2], &mut df).is_err());
    }

    /// The kernels' f32 link ([`SimLink::consts`], [`deform_host`], [`deform_vjp_host`]) agrees
    /// with the f64 host link ([`SimLink::deformation`], [`SimLink::deformation_vjp`]) to f32
    /// rounding, leaves static Gaussians alone and gives filling particles nothing.
    #[test]
    fn kernel_link_matches_the_host_link() {
        let (c, s) = (0.4f64.cos(), 0.4f64.sin());
        let l = SimLink {
            scene_gaussians: 5,
            simulated: vec![3, 1, 4],
            filled: 2,
            rotation: [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]],
            centre: [0.2, -0.1, 0.5],
            scale: 1.7,
            shift: [1.0, 1.0, 1.0],
        };
        let scene = Gaussians {
            means: (0..5).map(|i| [i as f32, 0.5, -0.25]).collect(),
            log_scales: vec![[0.0; 3]; 5],
            quats: vec![[1.0, 0.0, 0.0, 0.0]; 5],
            opacity_logits: vec![0.0; 5],
            sh: vec![0.0; 5 * 48],
            ..Default::default()
        };
        let x: Vec<[f32; 3]> = (0..5)
            .map(|i| [0.8 + 0.1 * i as f32, 1.2, 0.9 - 0.03 * i as f32])
            .collect();
        let f: Vec<[[f32; 3]; 3]> = (0..5)
            .map(|i| {
                let a = 0.07 * i as f32;
                [[1.0 + a, 0.1, 0.0], [-0.2, 0.95, a], [0.05, -a, 1.02]]
            })
            .collect();
        let f9: Vec<[f32; 9]> = f
            .iter()
            .map(|m| [m[0], m[1], m[2]].concat().try_into().unwrap())
            .collect();
        let want = l.deformation(&scene, &x, Some(&f), "t").unwrap();
        let k = l.consts();
        let eye = [[1.0f32, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let (mut means, mut fw) = (scene.means.clone(), vec![eye; 5]);
        deform_host(&k, &l.simulated, &x, &f9, &mut means, &mut fw);
        for g in 0..5 {
            for a in 0..3 {
                assert!((means[g][a] - want.means[g][a]).abs() < 1e-6, "mean {g}");
                for b in 0..3 {
                    assert!((fw[g][a][b] - want.f[g][a][b]).abs() < 1e-6, "F {g}");
                }
            }
        }
        let gr = GaussianGrads {
            means: (0..5).map(|i| [0.3, -0.2 * i as f32, 0.7]).collect(),
            f: (0..5)
                .map(|i| {
                    [
                        [0.1 * i as f32, 0.2, -0.3],
                        [0.4, -0.5, 0.6],
                        [0.7, 0.8, -0.9],
                    ]
                })
                .collect(),
            ..Default::default()
        };
        let (mut dx, mut df) = (vec![[0.0f32; 3]; 5], vec![[0.0f32; 9]; 5]);
        l.deformation_vjp(&gr, &mut dx, &mut df).unwrap();
        let (mut kx, mut kf) = (vec![[0.0f32; 3]; 5], vec![[0.0f32; 9]; 5]);
        deform_vjp_host(&k, &l.simulated, &gr.means, &gr.f, &mut kx, &mut kf);
        for p in 0..5 {
            for a in 0..3 {
                assert!((kx[p][a] - dx[p][a]).abs() < 1e-6, "dx {p}");
            }
            for a in 0..9 {
                assert!((kf[p][a] - df[p][a]).abs() < 1e-6, "dF {p}");
            }
        }
        assert_eq!(kx[3], [0.0; 3]);
        assert_eq!(kf[4], [0.0; 9]);
    }
}
