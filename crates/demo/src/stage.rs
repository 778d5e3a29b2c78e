//! What every demo scene shares: the Gaussians of the simulated object (one per particle,
//! coloured in a 3D checker so motion inside the silhouette is visible), the static stage
//! (tiled floor, striped back wall) and the cameras.

use r4d_mpm::ParticleSet;
use r4d_splat::{Camera, Gaussians};

/// SH DC coefficient of an RGB colour.
fn dc(c: [f32; 3]) -> [f32; 3] {
    c.map(|v| (v - 0.5) / 0.282_094_8)
}

/// Two colours per part, alternating on a 0.0625-m 3D checker.
pub type Palette = [[f32; 3]; 2];

/// Green stem, red-gold head, steel, sand, foam, clay, paste, water.
pub const GREEN: Palette = [[0.16, 0.55, 0.22], [0.78, 0.86, 0.30]];
/// The plant's head.
pub const RED_GOLD: Palette = [[0.86, 0.20, 0.36], [0.98, 0.78, 0.22]];
/// Metal.
pub const STEEL: Palette = [[0.25, 0.32, 0.45], [0.70, 0.76, 0.86]];
/// Sand.
pub const SAND: Palette = [[0.62, 0.45, 0.20], [0.95, 0.82, 0.50]];
/// Foam.
pub const FOAM: Palette = [[0.90, 0.55, 0.15], [0.98, 0.93, 0.70]];
/// Plasticine.
pub const CLAY: Palette = [[0.50, 0.20, 0.70], [0.35, 0.80, 0.75]];
/// Paste.
pub const PASTE: Palette = [[0.92, 0.92, 0.95], [0.20, 0.55, 0.85]];
/// Fluid.
pub const WATER: Palette = [[0.10, 0.35, 0.75], [0.45, 0.80, 0.95]];

struct Builder(Gaussians);

impl Builder {
    fn push(&mut self, m: [f32; 3], s: [f32; 3], q: [f32; 4], o: f32, c: [f32; 3]) {
        let g = &mut self.0;
        g.means.push(m);
        g.log_scales.push(s.map(f32::ln));
        g.quats.push(q);
        g.opacity_logits.push(o);
        g.sh.extend(dc(c));
    }
}

/// The scene: one isotropic Gaussian per particle (the first `particles.len()` Gaussians, in
/// particle order), then the floor at height `floor_z` and the back wall at `y = 0.95`.
pub fn scene(p: &ParticleSet, dx: f64, palettes: &[Palette], floor_z: f32) -> Gaussians {
    let mut b = Builder(Gaussians {
        sh_degree: 0,
        ..Default::default()
    });
    let sigma = (0.5 * dx / 2.0) as f32;
    for (x, &part) in p.x.iter().zip(&p.part) {
        let cell = x.map(|v| (v / 0.0625).floor() as i64);
        let odd = (cell[0] + cell[1] + cell[2]).rem_euclid(2) as usize;
        let pal = palettes[part as usize % palettes.len()];
        b.push(*x, [sigma; 3], [1.0, 0.0, 0.0, 0.0], 3.0, pal[odd]);
    }
    // Static floor (grey tiles) and back wall (stripes): flat discs on a 0.03-m lattice.
    let step = 0.03f32;
    for i in 0..44 {
        for j in 0..34 {
            let (x, y) = (-0.15 + i as f32 * step, -0.05 + j as f32 * step);
            let tile = ((x / 0.125).floor() + (y / 0.125).floor()) as i64 & 1;
            let c = if tile == 0 { 0.55 } else { 0.72 };
            b.push(
                [x, y, floor_z],
                [0.022, 0.022, 0.003],
                [1.0, 0.0, 0.0, 0.0],
                4.0,
                [c, c, c * 0.95],
            );
        }
    }
    let rows = ((1.0 - floor_z) / step).ceil() as usize;
    for i in 0..44 {
        for k in 0..rows {
            let (x, z) = (-0.15 + i as f32 * step, floor_z + 0.005 + k as f32 * step);
            let stripe = (((x + z) / 0.1).floor() as i64) & 1;
            let c = if stripe == 0 {
                [0.62, 0.72, 0.90]
            } else {
                [0.93, 0.80, 0.86]
            };
            // Disc in the x-z plane: rotate z onto y (90 degrees about x).
            let h = std::f32::consts::FRAC_1_SQRT_2;
            b.push(
                [x, 0.95, z],
                [0.022, 0.022, 0.003],
                [h, h, 0.0, 0.0],
                4.0,
                c,
            );
        }
    }
    b.0
}

/// A camera named `name` of `width x height` pixels with a 40-degree horizontal field of
/// view, at `eye` looking at `target`, z up.
pub fn camera(name: &str, (width, height): (u32, u32), eye: [f64; 3], target: [f64; 3]) -> Camera {
    let mut c = Camera::look_at(width, height, 40.0, eye, target, [0.0, 0.0, 1.0]);
    c.name = name.into();
    c
}
