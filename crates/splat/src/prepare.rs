//! Preprocessing of a captured 3DGS scene into simulation space, as PhysGaussian's scene
//! configs describe it (`opacity_threshold`, `rotation_degree` / `rotation_axis`,
//! `sim_area`, `scale`, `particle_filling`), producing a [`SimLink`] and the particles.
//!
//! Steps, in PhysGaussian's order:
//!
//! 1. Keep Gaussians with `sigmoid(opacity) > opacity_threshold` (default 0.02); the others
//!    are dropped from the prepared scene (not rendered, as in PhysGaussian).
//! 2. Rotate positions by `R = R_n ... R_1` (`rotation_degree[i]` about axis
//!    `rotation_axis[i]`, 0 = x, 1 = y, 2 = z).
//! 3. `sim_area = [x0, x1, y0, y1, z0, z1]` (rotated frame, strict): Gaussians inside are
//!    simulated; the others are static background, rendered unchanged.
//! 4. Normalise: `c` = centre of the bounding box of the simulated centres, `D` its longest
//!    side, `x_sim = scale / D * (R x - c) + (1, 1, 1)` (PhysGaussian's `transform2origin` and
//!    `shift2center111`).
//! 5. Optional interior filling (`particle_filling`): a density field of the Gaussians on a
//!    grid of `n_grid^3` cells over `[0, grid_lim]^3`; cells denser than `density_threshold`
//!    with fewer than `max_particles_per_cell` Gaussian centres get particles; empty cells
//!    enclosed in five axis directions (all but `search_exclude_direction`) by cells denser
//!    than `search_threshold` and with an odd number of entries into dense cells along
//!    `ray_cast_direction` (0..5 = +x, -x, +y, -y, +z, -z) are interior and get particles.
//!    Points are placed uniformly at random (seeded) in their cell.
//!
//! Differences from PhysGaussian: its filling loop has no bound on a Gaussian's stencil; here
//! covariance eigenvalues are clamped to `>= 1e-8` (as PhysGaussian does) *and* the stencil
//! radius to `n_grid / 4` cells, so a huge or near-singular covariance cannot stall the run;
//! `max_particles_num` is enforced with an error; `smooth` and `visualize` are not supported
//! (reported as warnings; filled particles are never rendered); the SH rotation uses `F`
//! conjugated by `R` (PhysGaussian applies the simulation-space rotation to world-space view
//! directions, which is only right without `rotation_degree`).

use crate::covariance::covariance;
use crate::error::{Error, Result};
use crate::gaussians::Gaussians;
use crate::link::SimLink;
use serde::{Deserialize, Serialize};

/// The finest filling grid (`particle_filling.n_grid`, cells per axis): 400^3 cells of 16
/// bytes, about 1 GB. PhysGaussian's configs use 200 or less.
pub const MAX_FILL_GRID: usize = 400;

/// The most filling particles one may ask for (`max_particles_num`).
pub const MAX_FILL_PARTICLES: usize = 50_000_000;

/// The most particles per filled cell (`max_particles_per_cell`).
pub const MAX_PARTICLES_PER_CELL: usize = 64;

/// The smallest `scale` (simulation-space length of the simulated region's longest side):
/// half a cell of the finest simulation grid (`grid_lim` 2 over 1024 nodes). Smaller regions
/// collapse onto a few f32 positions (at `1e-300` every particle is one point).
pub const MIN_SCALE: f64 = 1e-3;

/// The largest `scale`: the region is centred at (1, 1, 1), so its longest side reaches the
/// domain's faces at 2 (beyond, positions leave `[0, 2]^3`; at `1e300` they are infinite).
pub const MAX_SCALE: f64 = 2.0;

/// PhysGaussian's `particle_filling` block (an unknown key in it is an error).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct Filling {
    /// Cells per axis of the filling grid.
    pub n_grid: usize,
    /// Density above which a cell counts as occupied.
    pub density_threshold: f64,
    /// Density above which a cell stops the interior search rays.
    #[serde(alias = "search_thres")]
    pub search_threshold: f64,
    /// Upper bound on filled particles (an error beyond).
    pub max_particles_num: usize,
    /// Particles per filled cell (PhysGaussian spells the key `max_partciels_per_cell`).
    #[serde(alias = "max_partciels_per_cell", alias = "max_particles_per_cell")]
    pub max_particles_per_cell: usize,
    /// Direction not searched (0..5 = +x, -x, +y, -y, +z, -z).
    pub search_exclude_direction: usize,
    /// Direction of the parity ray.
    pub ray_cast_direction: usize,
    /// Optional box `[x0, x1, y0, y1, z0, z1]` (simulation space) limiting the Gaussians used.
    pub boundary: Option<[f64; 6]>,
    /// Not supported (warning).
    pub smooth: bool,
    /// Not supported (warning).
    pub visualize: bool,
}

impl Default for Filling {
    fn default() -> Self {
        Filling {
            n_grid: 200,
            density_threshold: 5.0,
            search_threshold: 3.0,
            max_particles_num: 2_000_000,
            max_particles_per_cell: 1,
            search_exclude_direction: 5,
            ray_cast_direction: 4,
            boundary: None,
            smooth: false,
            visualize: false,
        }
    }
}

/// The preprocessing keys of a PhysGaussian scene config (other keys are ignored).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(default)]
pub struct PrepareConfig {
    /// Keep Gaussians with opacity strictly above this.
    pub opacity_threshold: f64,
    /// Rotation angles in degrees, applied in order.
    pub rotation_degree: Vec<f64>,
    /// Rotation axes (0 = x, 1 = y, 2 = z).
    pub rotation_axis: Vec<usize>,
    /// Crop box in the rotated frame.
    pub sim_area: Option<[f64; 6]>,
    /// Length of the longest side of the simulated region in simulation space.
    pub scale: f64,
    /// Simulation domain edge (for the filling grid).
    pub grid_lim: f64,
    /// Interior filling.
    pub particle_filling: Option<Filling>,
}

impl Default for PrepareConfig {
    fn default() -> Self {
        PrepareConfig {
            opacity_threshold: 0.02,
            rotation_degree: Vec::new(),
            rotation_axis: Vec::new(),
            sim_area: None,
            scale: 1.0,
            grid_lim: 2.0,
            particle_filling: None,
        }
    }
}

/// A prepared scene.
#[derive(Clone, Debug)]
pub struct Prepared {
    /// The Gaussians that survive the opacity threshold (world frame, original order).
    pub scene: Gaussians,
    /// Indices into the input scene of the Gaussians in `scene`.
    pub kept: Vec<u32>,
    /// The link between `scene` and the particles.
    pub link: SimLink,
    /// Particle positions in simulation space: simulated Gaussians, then filling particles.
    pub particles: Vec<[f32; 3]>,
    /// Notes on unsupported keys.
    pub warnings: Vec<String>,
}

fn axis_rotation(axis: usize, deg: f64) -> [[f64; 3]; 3] {
    let t = deg.to_radians();
    let (c, s) = (t.cos(), t.sin());
    match axis {
        0 => [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]],
        1 => [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]],
        _ => [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
    }
}

fn mul3(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut m = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    m
}

/// Runs the preprocessing; `what` names the config in errors.
pub fn prepare(input: &Gaussians, cfg: &PrepareConfig, what: &str) -> Result<Prepared> {
    prepare_with(input, cfg, None, what)
}

/// The world-to-simulation rotation of `rotation_degree` / `rotation_axis`: the rotations
/// applied in list order (`R = R_k ... R_1`), as PhysGaussian's and PhysFlow's
/// `apply_rotations` do.
pub fn rotation_of(degrees: &[f64], axes: &[usize]) -> [[f64; 3]; 3] {
    let mut rot = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for (&d, &a) in degrees.iter().zip(axes) {
        rot = mul3(&axis_rotation(a, d), &rot);
    }
    rot
}

/// [`prepare`] with an extra selection of the simulated Gaussians: `movable[i]` (one flag per
/// *input* Gaussian) must be true for Gaussian `i` to be simulated (PhysFlow's moving-part
/// rule); the others that pass the opacity threshold stay in the scene as static background.
/// The normalisation is computed over the simulated Gaussians only, as PhysFlow does.
pub fn prepare_with(
    input: &Gaussians,
    cfg: &PrepareConfig,
    movable: Option<&[bool]>,
    what: &str,
) -> Result<Prepared> {
    input.validate(what)?;
    if let Some(m) = movable {
        if m.len() != input.len() {
            return Err(Error::Mismatch(format!(
                "{what}: {} movable flags for {} Gaussians",
                m.len(),
                input.len()
            )));
        }
    }
    let bad = |m: String| Error::Mismatch(format!("{what}: {m}"));
    if cfg.rotation_degree.len() != cfg.rotation_axis.len() {
        return Err(bad(format!(
            "rotation_degree has {} entries, rotation_axis {}",
            cfg.rotation_degree.len(),
            cfg.rotation_axis.len()
        )));
    }
    if let Some(&a) = cfg.rotation_axis.iter().find(|&&a| a > 2) {
        return Err(bad(format!("rotation_axis {a} (0, 1 or 2)")));
    }
    if !(MIN_SCALE..=MAX_SCALE).contains(&cfg.scale) {
        return Err(bad(format!(
            "scale = {} must lie in [{MIN_SCALE}, {MAX_SCALE}] (MIN_SCALE, MAX_SCALE): the \
             simulated region, centred at (1, 1, 1), must fit in [0, 2]^3 and span more than \
             half a cell of the finest grid",
            cfg.scale
        )));
    }
    let rot = rotation_of(&cfg.rotation_degree, &cfg.rotation_axis);
    let kept: Vec<u32> = (0..input.len() as u32)
        .filter(|&i| {
            let o = 1.0 / (1.0 + (-(input.opacity_logits[i as usize] as f64)).exp());
            o > cfg.opacity_threshold
        })
        .collect();
    let scene = input.select(&kept.iter().map(|&i| i as usize).collect::<Vec<_>>());
    let rotated: Vec<[f64; 3]> = scene
        .means
        .iter()
        .map(|m| {
            let x = m.map(|v| v as f64);
            [0, 1, 2].map(|i| rot[i][0] * x[0] + rot[i][1] * x[1] + rot[i][2] * x[2])
        })
        .collect();
    let simulated: Vec<u32> = (0..scene.len() as u32)
        .filter(|&i| movable.is_none_or(|m| m[kept[i as usize] as usize]))
        .filter(|&i| match &cfg.sim_area {
            None => true,
            Some(b) => (0..3).all(|a| {
                let v = rotated[i as usize][a];
                b[2 * a] < v && v < b[2 * a + 1]
            }),
        })
        .collect();
    if simulated.is_empty() {
        return Err(bad(
            "no Gaussian passes the opacity threshold, lies inside sim_area and is movable".into(),
        ));
    }
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for &i in &simulated {
        for a in 0..3 {
            lo[a] = lo[a].min(rotated[i as usize][a]);
            hi[a] = hi[a].max(rotated[i as usize][a]);
        }
    }
    let extent = (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f64::max);
    let extent = if extent > 0.0 { extent } else { 1.0 };
    let link = SimLink {
        scene_gaussians: scene.len(),
        simulated: simulated.clone(),
        filled: 0,
        rotation: rot,
        centre: [0, 1, 2].map(|a| 0.5 * (lo[a] + hi[a])),
        scale: cfg.scale / extent,
        shift: [1.0; 3],
    };
    let mut particles: Vec<[f32; 3]> = simulated
        .iter()
        .map(|&i| {
            link.to_sim(scene.means[i as usize].map(|v| v as f64))
                .map(|v| v as f32)
        })
        .collect();
    let mut warnings = Vec::new();
    let mut link = link;
    if let Some(fill) = &cfg.particle_filling {
        if fill.smooth {
            warnings.push("particle_filling.smooth is not supported: ignored".into());
        }
        if fill.visualize {
            warnings.push(
                "particle_filling.visualize is not supported: filled particles are not rendered"
                    .into(),
            );
        }
        let extra = fill_interior(&scene, &simulated, &link, fill, cfg.grid_lim, what)?;
        link.filled = extra.len();
        particles.extend(extra);
    }
    Ok(Prepared {
        scene,
        kept,
        link,
        particles,
        warnings,
    })
}

/// Deterministic uniform numbers in [0, 1) (SplitMix64).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn fill_interior(
    scene: &Gaussians,
    simulated: &[u32],
    link: &SimLink,
    fill: &Filling,
    grid_lim: f64,
    what: &str,
) -> Result<Vec<[f32; 3]>> {
    let bad = |m: String| Error::Mismatch(format!("{what}: particle_filling: {m}"));
    let n = fill.n_grid;
    if !(2..=MAX_FILL_GRID).contains(&n) {
        return Err(bad(format!(
            "n_grid = {n} (2..={MAX_FILL_GRID}: the filling grid takes 16 bytes a cell, {} MB at the limit)",
            (MAX_FILL_GRID as u64).pow(3) * 16 / 1_000_000
        )));
    }
    if fill.max_particles_num > MAX_FILL_PARTICLES {
        return Err(bad(format!(
            "max_particles_num = {} (at most {MAX_FILL_PARTICLES})",
            fill.max_particles_num
        )));
    }
    if fill.max_particles_per_cell > MAX_PARTICLES_PER_CELL {
        return Err(bad(format!(
            "max_particles_per_cell = {} (at most {MAX_PARTICLES_PER_CELL})",
            fill.max_particles_per_cell
        )));
    }
    if fill.search_exclude_direction > 5 {
        return Err(bad("search_exclude_direction must be 0..5".into()));
    }
    if !(grid_lim.is_finite() && grid_lim > 0.0) {
        return Err(bad(format!("grid_lim = {grid_lim}")));
    }
    let (origin, dx) = match fill.boundary {
        Some(b) => {
            let ext = (0..3).map(|a| b[2 * a + 1] - b[2 * a]).fold(0.0, f64::max);
            if ext.is_nan() || ext <= 0.0 {
                return Err(bad("boundary box is empty".into()));
            }
            ([b[0], b[2], b[4]], ext / n as f64)
        }
        None => ([0.0; 3], grid_lim / n as f64),
    };
    let idx = |i: usize, j: usize, k: usize| (i * n + j) * n + k;
    let mut density = vec![0.0f64; n * n * n];
    let mut count = vec![0usize; n * n * n];
    let s2 = link.scale * link.scale;
    let r = &link.rotation;
    let max_r = (n / 4).max(1) as i64;
    for &g in simulated {
        let g = g as usize;
        let x = link.to_sim(scene.means[g].map(|v| v as f64));
        if let Some(b) = fill.boundary {
            if !(0..3).all(|a| b[2 * a] < x[a] && x[a] < b[2 * a + 1]) {
                continue;
            }
        }
        let p = [0, 1, 2].map(|a| (x[a] - origin[a]) / dx);
        let cell = p.map(|v| v.floor() as i64);
        if cell.iter().all(|&c| c >= 0 && c < n as i64) {
            count[idx(cell[0] as usize, cell[1] as usize, cell[2] as usize)] += 1;
        }
        // Covariance in simulation space: s^2 R Sigma R^T, in cell units.
        let sig: [[f64; 3]; 3] = covariance(
            &scene.log_scales[g].map(|v| v as f64),
            &scene.quats[g].map(|v| v as f64),
        );
        let rs = mul3(r, &sig);
        let mut c = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                c[i][j] = s2 * (0..3).map(|k| rs[i][k] * r[j][k]).sum::<f64>() / (dx * dx);
            }
        }
        let (inv, max_eig) = clamped_inverse(&c);
        let opacity = 1.0 / (1.0 + (-(scene.opacity_logits[g] as f64)).exp());
        let rad = (max_eig.sqrt().ceil() as i64).clamp(0, max_r);
        for di in -rad..=rad {
            for dj in -rad..=rad {
                for dk in -rad..=rad {
                    let q = [cell[0] + di, cell[1] + dj, cell[2] + dk];
                    if q.iter().any(|&v| v < 0 || v >= n as i64) {
                        continue;
                    }
                    let mut acc = 0.0;
                    for corner in 0..8 {
                        let d =
                            [0, 1, 2].map(|a| p[a] - (q[a] + ((corner >> a) & 1) as i64) as f64);
                        let mut e = 0.0;
                        for i in 0..3 {
                            for j in 0..3 {
                                e += d[i] * inv[i][j] * d[j];
                            }
                        }
                        acc += (-0.5 * e).exp();
                    }
                    density[idx(q[0] as usize, q[1] as usize, q[2] as usize)] +=
                        opacity * acc / 8.0;
                }
            }
        }
    }
    let m = fill.max_particles_per_cell.max(1);
    let mut rng = Rng(0x5EED);
    let mut out: Vec<[f32; 3]> = Vec::new();
    let push = |out: &mut Vec<[f32; 3]>, rng: &mut Rng, c: [usize; 3], k: usize| -> Result<()> {
        for _ in 0..k {
            if out.len() >= fill.max_particles_num {
                return Err(bad(format!(
                    "more than max_particles_num = {} filling particles",
                    fill.max_particles_num
                )));
            }
            out.push([0, 1, 2].map(|a| (origin[a] + (c[a] as f64 + rng.next()) * dx) as f32));
        }
        Ok(())
    };
    // Dense cells without enough Gaussian centres.
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let c = idx(i, j, k);
                if density[c] > fill.density_threshold && count[c] < m {
                    push(&mut out, &mut rng, [i, j, k], m - count[c])?;
                    count[c] = m;
                }
            }
        }
    }
    // Enclosed empty cells.
    let dense = |c: [i64; 3]| density[idx(c[0] as usize, c[1] as usize, c[2] as usize)];
    const DIRS: [[i64; 3]; 6] = [
        [1, 0, 0],
        [-1, 0, 0],
        [0, 1, 0],
        [0, -1, 0],
        [0, 0, 1],
        [0, 0, -1],
    ];
    let inside = |c: [i64; 3]| c.iter().all(|&v| v >= 0 && v < n as i64);
    let ray = fill.ray_cast_direction.min(5);
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                if count[idx(i, j, k)] != 0 {
                    continue;
                }
                let start = [i as i64, j as i64, k as i64];
                let enclosed = (0..6)
                    .filter(|&d| d != fill.search_exclude_direction)
                    .all(|d| {
                        let mut c = start;
                        loop {
                            c = [0, 1, 2].map(|a| c[a] + DIRS[d][a]);
                            if !inside(c) {
                                return false;
                            }
                            if dense(c) > fill.search_threshold {
                                return true;
                            }
                        }
                    });
                if !enclosed {
                    continue;
                }
                let mut crossings = 0;
                let mut prev = dense(start) > fill.search_threshold;
                let mut c = start;
                loop {
                    c = [0, 1, 2].map(|a| c[a] + DIRS[ray][a]);
                    if !inside(c) {
                        break;
                    }
                    let now = dense(c) > fill.search_threshold;
                    if now && !prev {
                        crossings += 1;
                    }
                    prev = now;
                }
                if crossings % 2 == 1 {
                    push(&mut out, &mut rng, [i, j, k], m)?;
                }
            }
        }
    }
    Ok(out)
}

/// Inverse of a symmetric 3x3 matrix with eigenvalues clamped to `>= 1e-8`, and the largest
/// eigenvalue.
fn clamped_inverse(c: &[[f64; 3]; 3]) -> ([[f64; 3]; 3], f64) {
    let (lam, v) = r4d_math::sym_eigen(*c);
    let l = lam.map(|x| x.max(1e-8));
    let mut inv = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            inv[i][j] = (0..3).map(|k| v[i][k] * v[j][k] / l[k]).sum();
        }
    }
    (inv, l[0])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hollow shell of Gaussians: filling must put particles inside and none outside.
    #[test]
    fn fills_the_inside_of_a_closed_shell_only() {
        let mut g = Gaussians::default();
        let n: usize = 2000;
        for i in 0..n {
            // Fibonacci sphere of radius 0.5 around (0.2, -0.1, 0.3).
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - y * y).sqrt();
            let phi = i as f64 * 2.399_963_229_728_653;
            g.means.push([
                (0.2 + 0.5 * r * phi.cos()) as f32,
                (-0.1 + 0.5 * y) as f32,
                (0.3 + 0.5 * r * phi.sin()) as f32,
            ]);
            g.log_scales.push([(0.03f32).ln(); 3]);
            g.quats.push([1.0, 0.0, 0.0, 0.0]);
            g.opacity_logits.push(if i % 97 == 0 { -6.0 } else { 3.0 });
            g.sh.extend_from_slice(&[0.5, 0.5, 0.5]);
        }
        let cfg: PrepareConfig = serde_json::from_str(
            r#"{"rotation_degree": [90.0], "rotation_axis": [0], "scale": 1.0,
                "particle_filling": {"n_grid": 48, "density_threshold": 0.5,
                "search_thres": 0.5, "max_partciels_per_cell": 1}}"#,
        )
        .unwrap();
        let p = prepare(&g, &cfg, "shell").unwrap();
        // Opacity threshold removed every 97th Gaussian.
        assert_eq!(p.scene.len(), n - n.div_ceil(97));
        assert_eq!(p.link.simulated.len(), p.scene.len());
        assert!(p.link.filled > 500, "filled {}", p.link.filled);
        // Filled particles lie inside the sphere (simulation space: centre (1,1,1), the
        // sphere's diameter maps to `scale` = 1, so radius 0.5) or in the shell's dense
        // cells (within 3 sigma = 0.09 plus a cell diagonal = 0.072 of it); the interior
        // (about 3700 cells of radius < 0.4) is filled.
        let mut deep = 0;
        for x in &p.particles[p.link.simulated.len()..] {
            let d = (0..3)
                .map(|a| (x[a] as f64 - 1.0).powi(2))
                .sum::<f64>()
                .sqrt();
            assert!(d < 0.5 + 0.09 + 0.072, "filled particle at distance {d}");
            deep += (d < 0.4) as usize;
        }
        assert!(deep > 3000, "{deep} particles deep inside");
        // Simulated Gaussians map back to their world positions.
        for (s, &gi) in p.link.simulated.iter().enumerate() {
            let w = p.link.to_world(p.particles[s].map(|v| v as f64));
            let m = p.scene.means[gi as usize];
            assert!((0..3).all(|a| (w[a] - m[a] as f64).abs() < 1e-5));
        }
    }

    #[test]
    fn huge_and_degenerate_covariances_do_not_stall_filling() {
        let mut g = Gaussians::default();
        for (i, ls) in [[5.0f32; 3], [-40.0, -40.0, -40.0], [0.0, -60.0, 2.0]]
            .iter()
            .enumerate()
        {
            g.means.push([i as f32 * 0.1, 0.0, 0.0]);
            g.log_scales.push(*ls);
            g.quats.push([1.0, 0.0, 0.0, 0.0]);
            g.opacity_logits.push(3.0);
            g.sh.extend_from_slice(&[0.5; 3]);
        }
        let cfg: PrepareConfig =
            serde_json::from_str(r#"{"particle_filling": {"n_grid": 64}}"#).unwrap();
        prepare(&g, &cfg, "degenerate").unwrap();
    }

    /// `scale` 1e300 made infinite positions and 1e-300 a single point: both are refused
    /// with the limits; the limits themselves are accepted.
    #[test]
    fn scale_is_bounded() {
        let mut g = Gaussians::default();
        for i in 0..3 {
            g.means.push([i as f32 * 0.1, 0.0, 0.0]);
            g.log_scales.push([(0.03f32).ln(); 3]);
            g.quats.push([1.0, 0.0, 0.0, 0.0]);
            g.opacity_logits.push(3.0);
            g.sh.extend_from_slice(&[0.5; 3]);
        }
        for scale in [1e300, 1e-300, 0.0, -1.0, f64::NAN, 2.5, 5e-4] {
            let cfg = PrepareConfig {
                scale,
                ..Default::default()
            };
            let e = prepare(&g, &cfg, "p.json").unwrap_err().to_string();
            assert!(
                e.contains("p.json") && e.contains("scale") && e.contains("MAX_SCALE"),
                "{e}"
            );
        }
        for scale in [MIN_SCALE, 1.0, MAX_SCALE] {
            let cfg = PrepareConfig {
                scale,
                ..Default::default()
            };
            let p = prepare(&g, &cfg, "p.json").unwrap();
            assert!(p
                .particles
                .iter()
                .flatten()
                .all(|c| c.is_finite() && (0.0..=2.0).contains(c)));
            assert!(
                p.particles[0] != p.particles[2],
                "distinct positions at scale {scale}"
            );
        }
    }
}
