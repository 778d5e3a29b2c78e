//! A synthetic test scene with analytic geometry: three parts that touch and occlude each
//! other on a static floor, covered by flat Gaussians (surfels, as a 3DGS capture has them),
//! and masks computed by **ray casting the analytic solids** (not from the renderer's
//! weights), so that lifting is checked against an independent ground truth. Used by the
//! tests, the bench and the docs' examples.
//!
//! * Floor (static, label -1): the square `[-1, 1]^2` at `z = 0`.
//! * Part 0, `box`: `[-0.55, 0.25] x [-0.4, 0.4] x [0, 0.6]`.
//! * Part 1, `ball`: a sphere of radius 0.28 at `(-0.15, 0, 0.76)`, sunk into the box's top.
//! * Part 2, `post`: a vertical cylinder of radius 0.25 at `(0.47, 0.1)`, height 0.9, cutting
//!   0.03 into the box's `+x` side.
//!
//! Gaussians are sampled on the visible surface of the union (a stratified grid per face; a
//! sample whose point just outside its face lies inside another solid is dropped, as is every
//! face resting on the floor), each a disc of standard deviation `0.7 x spacing` in the face
//! and `1/20` of that along the normal, opacity 0.99, coloured by part. Like the Gaussians of
//! a fitted capture, they do not overhang edges: near a face's edge or another solid the
//! in-plane scale across it shrinks until 1.5 standard deviations stay on the free face.

pub mod plant;

use crate::labels::part_colour;
use crate::mask::{InMemoryMasks, Mask, MaskData};
use r4d_splat::{Camera, Gaussians};

/// An analytic solid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Solid {
    /// The floor square `[-half, half]^2` at `z = 0` (a surface, not a solid).
    Floor {
        /// Half the side.
        half: f64,
    },
    /// An axis-aligned box.
    Box {
        /// Lower corner.
        min: [f64; 3],
        /// Upper corner.
        max: [f64; 3],
    },
    /// A sphere.
    Sphere {
        /// Centre.
        centre: [f64; 3],
        /// Radius.
        radius: f64,
    },
    /// A cylinder along z.
    Cylinder {
        /// Axis position `(x, y)`.
        axis: [f64; 2],
        /// Radius.
        radius: f64,
        /// Bottom and top heights.
        z: [f64; 2],
    },
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl Solid {
    /// Strictly inside (the floor has no inside).
    pub fn contains(&self, p: [f64; 3]) -> bool {
        match *self {
            Solid::Floor { .. } => false,
            Solid::Box { min, max } => (0..3).all(|a| p[a] > min[a] && p[a] < max[a]),
            Solid::Sphere { centre, radius } => {
                let d = sub(p, centre);
                dot(d, d) < radius * radius
            }
            Solid::Cylinder { axis, radius, z } => {
                let (dx, dy) = (p[0] - axis[0], p[1] - axis[1]);
                dx * dx + dy * dy < radius * radius && p[2] > z[0] && p[2] < z[1]
            }
        }
    }

    /// The smallest `t > 0` where the ray `o + t d` meets the solid's surface.
    pub fn hit(&self, o: [f64; 3], d: [f64; 3]) -> Option<f64> {
        const EPS: f64 = 1e-9;
        match *self {
            Solid::Floor { half } => {
                if d[2].abs() < EPS {
                    return None;
                }
                let t = -o[2] / d[2];
                let p = [o[0] + t * d[0], o[1] + t * d[1]];
                (t > EPS && p[0].abs() <= half && p[1].abs() <= half).then_some(t)
            }
            Solid::Box { min, max } => {
                let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
                for a in 0..3 {
                    if d[a].abs() < EPS {
                        if o[a] < min[a] || o[a] > max[a] {
                            return None;
                        }
                        continue;
                    }
                    let (ta, tb) = ((min[a] - o[a]) / d[a], (max[a] - o[a]) / d[a]);
                    t0 = t0.max(ta.min(tb));
                    t1 = t1.min(ta.max(tb));
                }
                (t0 <= t1 && t0 > EPS).then_some(t0)
            }
            Solid::Sphere { centre, radius } => {
                let oc = sub(o, centre);
                let (a, b, c) = (dot(d, d), dot(oc, d), dot(oc, oc) - radius * radius);
                let disc = b * b - a * c;
                if disc < 0.0 {
                    return None;
                }
                let t = (-b - disc.sqrt()) / a;
                (t > EPS).then_some(t)
            }
            Solid::Cylinder { axis, radius, z } => {
                let mut best: Option<f64> = None;
                let mut keep = |t: f64| {
                    if t > EPS && best.is_none_or(|b| t < b) {
                        best = Some(t);
                    }
                };
                let (ox, oy) = (o[0] - axis[0], o[1] - axis[1]);
                let a = d[0] * d[0] + d[1] * d[1];
                if a > EPS {
                    let b = ox * d[0] + oy * d[1];
                    let c = ox * ox + oy * oy - radius * radius;
                    let disc = b * b - a * c;
                    if disc >= 0.0 {
                        let t = (-b - disc.sqrt()) / a;
                        let zz = o[2] + t * d[2];
                        if zz >= z[0] && zz <= z[1] {
                            keep(t);
                        }
                    }
                }
                if d[2].abs() > EPS {
                    for zc in z {
                        let t = (zc - o[2]) / d[2];
                        let (px, py) = (ox + t * d[0], oy + t * d[1]);
                        if px * px + py * py <= radius * radius {
                            keep(t);
                        }
                    }
                }
                best
            }
        }
    }
}

/// The three-part scene (see the module docs).
#[derive(Clone, Debug)]
pub struct SyntheticScene {
    /// The Gaussians.
    pub gaussians: Gaussians,
    /// The true label of every Gaussian (-1: floor).
    pub truth: Vec<i32>,
    /// The solids with their labels (-1: floor), in the order `[floor, box, ball, post]`.
    pub solids: Vec<(Solid, i32)>,
    /// The part names.
    pub class_names: Vec<String>,
}

/// Small deterministic generator (splitmix64).
#[derive(Clone, Debug)]
pub struct Rng(pub u64);

impl Rng {
    /// Uniform in [0, 1).
    pub fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `[a, b)`.
    pub fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.next_f64()
    }

    /// Uniform in `0 .. n`.
    pub fn below(&mut self, n: usize) -> usize {
        ((self.next_f64() * n as f64) as usize).min(n.saturating_sub(1))
    }
}

/// Quaternion `(w, x, y, z)` of the rotation whose columns are `a, b, c`.
fn quat_from_axes(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [f32; 4] {
    let m = [[a[0], b[0], c[0]], [a[1], b[1], c[1]], [a[2], b[2], c[2]]];
    let tr = m[0][0] + m[1][1] + m[2][2];
    let q = if tr > 0.0 {
        let s = (tr + 1.0).sqrt() * 2.0;
        [
            0.25 * s,
            (m[2][1] - m[1][2]) / s,
            (m[0][2] - m[2][0]) / s,
            (m[1][0] - m[0][1]) / s,
        ]
    } else if m[0][0] > m[1][1] && m[0][0] > m[2][2] {
        let s = (1.0 + m[0][0] - m[1][1] - m[2][2]).sqrt() * 2.0;
        [
            (m[2][1] - m[1][2]) / s,
            0.25 * s,
            (m[0][1] + m[1][0]) / s,
            (m[0][2] + m[2][0]) / s,
        ]
    } else if m[1][1] > m[2][2] {
        let s = (1.0 + m[1][1] - m[0][0] - m[2][2]).sqrt() * 2.0;
        [
            (m[0][2] - m[2][0]) / s,
            (m[0][1] + m[1][0]) / s,
            0.25 * s,
            (m[1][2] + m[2][1]) / s,
        ]
    } else {
        let s = (1.0 + m[2][2] - m[0][0] - m[1][1]).sqrt() * 2.0;
        [
            (m[1][0] - m[0][1]) / s,
            (m[0][2] + m[2][0]) / s,
            (m[1][2] + m[2][1]) / s,
            0.25 * s,
        ]
    };
    q.map(|v| v as f32)
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn normalize(a: [f64; 3]) -> [f64; 3] {
    let l = dot(a, a).sqrt();
    a.map(|v| v / l)
}

/// A face of the scene's surface, for sampling and for keeping each Gaussian within it.
#[derive(Clone, Copy, Debug)]
enum Face {
    /// `o + a eu + b ev`, `a in [0, lu]`, `b in [0, lv]` (unit `eu`, `ev`; normal `eu x ev`).
    Rect {
        o: [f64; 3],
        eu: [f64; 3],
        ev: [f64; 3],
        lu: f64,
        lv: f64,
    },
    /// A sphere.
    Sphere,
    /// The side of a vertical cylinder between two heights.
    CylSide { z: [f64; 2] },
    /// A horizontal disc (a cylinder's top).
    Cap { c: [f64; 3], r: f64 },
}

impl Face {
    /// Whether an in-plane offset `q` of a sample is still on the face (curvature ignored).
    fn on(&self, q: [f64; 3]) -> bool {
        match *self {
            Face::Rect { o, eu, ev, lu, lv } => {
                let w = sub(q, o);
                let (a, b) = (dot(w, eu), dot(w, ev));
                (0.0..=lu).contains(&a) && (0.0..=lv).contains(&b)
            }
            Face::Sphere => true,
            Face::CylSide { z } => (z[0]..=z[1]).contains(&q[2]),
            Face::Cap { c, r } => {
                let (dx, dy) = (q[0] - c[0], q[1] - c[1]);
                dx * dx + dy * dy <= r * r
            }
        }
    }
}

/// A surface sample: position, outward normal, in-plane axes, label, face.
type Sample = ([f64; 3], [f64; 3], [[f64; 3]; 2], i32, Face);

/// Stratified samples of a planar rectangle (`Face::Rect`): one per cell of a grid of
/// spacing about `s`, jittered within the middle 70% of the cell.
fn rect(out: &mut Vec<Sample>, r: &mut Rng, face: Face, s: f64, label: i32) {
    let Face::Rect { o, eu, ev, lu, lv } = face else {
        unreachable!("a rectangle")
    };
    let n = cross(eu, ev);
    let (nu, nv) = (
        (lu / s).round().max(1.0) as usize,
        (lv / s).round().max(1.0) as usize,
    );
    for a in 0..nu {
        for b in 0..nv {
            let u = (a as f64 + r.range(0.15, 0.85)) * lu / nu as f64;
            let v = (b as f64 + r.range(0.15, 0.85)) * lv / nv as f64;
            let p = [0, 1, 2].map(|k| o[k] + u * eu[k] + v * ev[k]);
            out.push((p, n, [eu, ev], label, face));
        }
    }
}

/// The three-part scene with about `n` Gaussians (before dropping hidden samples).
pub fn three_parts(n: usize, seed: u64) -> SyntheticScene {
    let floor = Solid::Floor { half: 1.0 };
    let (bmin, bmax) = ([-0.55, -0.4, 0.0], [0.25, 0.4, 0.6]);
    let boxs = Solid::Box {
        min: bmin,
        max: bmax,
    };
    let (sc, sr) = ([-0.15, 0.0, 0.76], 0.28);
    let ball = Solid::Sphere {
        centre: sc,
        radius: sr,
    };
    let (ca, cr, cz) = ([0.47, 0.1], 0.25, [0.0, 0.9]);
    let post = Solid::Cylinder {
        axis: ca,
        radius: cr,
        z: cz,
    };
    let solids = vec![(floor, -1), (boxs, 0), (ball, 1), (post, 2)];
    let pi = std::f64::consts::PI;
    let d = sub(bmax, bmin);
    let area = 4.0
        + d[0] * d[1]
        + 2.0 * d[2] * (d[0] + d[1])
        + 4.0 * pi * sr * sr
        + 2.0 * pi * cr * (cz[1] - cz[0])
        + pi * cr * cr;
    let s = (area / n.max(1) as f64).sqrt();
    let mut r = Rng(seed);
    let mut samples: Vec<Sample> = Vec::new();
    let (ex, ey, ez) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
    let rf = |o, eu, ev, lu, lv| Face::Rect { o, eu, ev, lu, lv };
    // Floor.
    rect(
        &mut samples,
        &mut r,
        rf([-1.0, -1.0, 0.0], ex, ey, 2.0, 2.0),
        s,
        -1,
    );
    // Box: top and four sides (the bottom rests on the floor); normal = eu x ev, outwards.
    let (x0, y0, z0) = (bmin[0], bmin[1], bmin[2]);
    let (x1, y1, z1) = (bmax[0], bmax[1], bmax[2]);
    for f in [
        rf([x0, y0, z1], ex, ey, d[0], d[1]),
        rf([x0, y0, z0], ex, ez, d[0], d[2]), // -y
        rf([x0, y1, z0], ez, ex, d[2], d[0]), // +y
        rf([x0, y0, z0], ez, ey, d[2], d[1]), // -x
        rf([x1, y0, z0], ey, ez, d[1], d[2]), // +x
    ] {
        rect(&mut samples, &mut r, f, s, 0);
    }
    // Ball: a Fibonacci lattice.
    let nb = (4.0 * pi * sr * sr / (s * s)).round() as usize;
    let golden = pi * (3.0 - 5f64.sqrt());
    for i in 0..nb {
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / nb as f64;
        let rho = (1.0 - z * z).sqrt();
        let phi = golden * i as f64 + r.range(-0.3, 0.3) * golden;
        let nrm = [rho * phi.cos(), rho * phi.sin(), z];
        let helper = if nrm[2].abs() < 0.9 { ez } else { ex };
        let t1 = normalize(cross(helper, nrm));
        let p = [0, 1, 2].map(|k| sc[k] + sr * nrm[k]);
        samples.push((p, nrm, [t1, cross(nrm, t1)], 1, Face::Sphere));
    }
    // Post: side (arc length x height) and top cap.
    let (nphi, nz) = (
        ((2.0 * pi * cr / s).round() as usize).max(3),
        ((cz[1] - cz[0]) / s).round().max(1.0) as usize,
    );
    for a in 0..nphi {
        for b in 0..nz {
            let phi = (a as f64 + r.range(0.15, 0.85)) * 2.0 * pi / nphi as f64;
            let z = cz[0] + (b as f64 + r.range(0.15, 0.85)) * (cz[1] - cz[0]) / nz as f64;
            let nrm = [phi.cos(), phi.sin(), 0.0];
            let p = [ca[0] + cr * nrm[0], ca[1] + cr * nrm[1], z];
            let tang = [-phi.sin(), phi.cos(), 0.0];
            samples.push((p, nrm, [tang, ez], 2, Face::CylSide { z: cz }));
        }
    }
    let nc = (2.0 * cr / s).round().max(1.0) as usize;
    let cap = Face::Cap {
        c: [ca[0], ca[1], cz[1]],
        r: cr,
    };
    for a in 0..nc {
        for b in 0..nc {
            let u = -cr + (a as f64 + r.range(0.15, 0.85)) * 2.0 * cr / nc as f64;
            let v = -cr + (b as f64 + r.range(0.15, 0.85)) * 2.0 * cr / nc as f64;
            if u * u + v * v <= cr * cr {
                samples.push(([ca[0] + u, ca[1] + v, cz[1]], ez, [ex, ey], 2, cap));
            }
        }
    }
    // A point of the surface is free when it, and the point just outside it, lie in no other
    // solid (and, for in-plane offsets, on its own face).
    let free = |q: [f64; 3], nrm: [f64; 3], label: i32| {
        let out = [0, 1, 2].map(|k| q[k] + 1e-4 * nrm[k]);
        !solids
            .iter()
            .any(|(so, l)| so.contains(out) || (*l != label && so.contains(q)))
    };
    samples.retain(|(p, nrm, _, label, _)| free(*p, *nrm, *label));
    let sigma = 0.7 * s;
    let mut g = Gaussians {
        sh_degree: 0,
        ..Default::default()
    };
    let mut truth = Vec::with_capacity(samples.len());
    const Y0: f32 = 0.282_094_8;
    for (p, nrm, axes, label, face) in samples {
        // As a fitted scene has them: a Gaussian does not reach over its face's edge or into
        // another solid. Along each in-plane axis the scale shrinks until the points 1.5
        // standard deviations away are still free surface (down to a fifth).
        let sc = axes.map(|a| {
            let mut sa = sigma;
            let ok = |sa: f64| {
                [-1.5, 1.5].iter().all(|&t| {
                    let q = [0, 1, 2].map(|k| p[k] + t * sa * a[k]);
                    face.on(q) && free(q, nrm, label)
                })
            };
            while sa > sigma / 5.0 && !ok(sa) {
                sa *= 0.8;
            }
            sa as f32
        });
        g.means.push(p.map(|x| x as f32));
        g.log_scales
            .push([sc[0].ln(), sc[1].ln(), (sigma as f32 / 20.0).ln()]);
        g.quats.push(quat_from_axes(axes[0], axes[1], nrm));
        g.opacity_logits.push(4.6);
        let c = part_colour(label);
        let shade = 0.85 + 0.15 * r.next_f64() as f32;
        g.sh.extend(c.map(|x| (x * shade - 0.5) / Y0));
        truth.push(label);
    }
    SyntheticScene {
        gaussians: g,
        truth,
        solids,
        class_names: vec!["box".into(), "ball".into(), "post".into()],
    }
}

/// `n` cameras on a ring around the scene at distance 3 from `(0, 0, 0.35)`, elevations
/// alternating 30 and 55 degrees, horizontal field of view 50 degrees.
pub fn ring_cameras(n: usize, width: u32, height: u32) -> Vec<Camera> {
    let target = [0.0, 0.0, 0.35];
    (0..n)
        .map(|k| {
            let az = (15.0 + 360.0 * k as f64 / n as f64).to_radians();
            let el = if k % 2 == 0 { 30f64 } else { 55.0 }.to_radians();
            let eye = [
                target[0] + 3.0 * el.cos() * az.cos(),
                target[1] + 3.0 * el.cos() * az.sin(),
                target[2] + 3.0 * el.sin(),
            ];
            let mut c = Camera::look_at(width, height, 50.0, eye, target, [0.0, 0.0, 1.0]);
            c.name = format!("view_{k:02}.png");
            c
        })
        .collect()
}

impl SyntheticScene {
    /// The label map the camera sees, by ray casting the solids through every pixel centre:
    /// 0 where the nearest hit is the floor or nothing, `k + 1` where it is part `k`.
    pub fn label_mask(&self, cam: &Camera) -> Vec<u16> {
        let rot = cam.rotation();
        let o = cam.position();
        let mut out = vec![0u16; (cam.width * cam.height) as usize];
        for j in 0..cam.height {
            for i in 0..cam.width {
                let dc = [
                    (i as f64 + 0.5 - cam.cx) / cam.fx,
                    (j as f64 + 0.5 - cam.cy) / cam.fy,
                    1.0,
                ];
                // World direction: R^T d_cam.
                let d =
                    [0, 1, 2].map(|k| rot[0][k] * dc[0] + rot[1][k] * dc[1] + rot[2][k] * dc[2]);
                let mut best: Option<(f64, i32)> = None;
                for (s, l) in &self.solids {
                    if let Some(t) = s.hit(o, d) {
                        if best.is_none_or(|(b, _)| t < b) {
                            best = Some((t, *l));
                        }
                    }
                }
                out[(j * cam.width + i) as usize] = best.map_or(0, |(_, l)| (l + 1) as u16);
            }
        }
        out
    }

    /// Label-map masks of every camera, in memory.
    pub fn masks(&self, cameras: &[Camera]) -> InMemoryMasks {
        InMemoryMasks {
            class_names: self.class_names.clone(),
            masks: cameras
                .iter()
                .enumerate()
                .map(|(v, c)| Mask {
                    origin: format!("synthetic view {v}"),
                    width: c.width,
                    height: c.height,
                    data: MaskData::Labels(self.label_mask(c)),
                })
                .collect(),
        }
    }
}

/// Corrupts a label map (`classes` labels `0 .. classes`) as a poor segmenter would: every
/// boundary moves by `radius` pixels, one way or the other at random (in a random order of
/// the classes, each class's original region is dilated by a disc of that radius, painting
/// over the classes before it: of two neighbouring classes the later grows into the earlier),
/// then a `flip` fraction of the pixels gets a random other label.
pub fn corrupt(
    labels: &mut [u16],
    width: u32,
    height: u32,
    classes: u16,
    radius: i32,
    flip: f64,
    seed: u64,
) {
    let (w, h) = (width as i32, height as i32);
    let mut r = Rng(seed);
    let mut order: Vec<u16> = (0..classes).collect();
    for i in (1..order.len()).rev() {
        order.swap(i, r.below(i + 1));
    }
    let disc: Vec<(i32, i32)> = (-radius..=radius)
        .flat_map(|dy| (-radius..=radius).map(move |dx| (dx, dy)))
        .filter(|(dx, dy)| dx * dx + dy * dy <= radius * radius)
        .collect();
    let cur = labels.to_vec();
    let at = |x: i32, y: i32| cur[(y * w + x) as usize];
    for c in order {
        for y in 0..h {
            for x in 0..w {
                if at(x, y) != c {
                    continue;
                }
                let interior = [(1, 0), (-1, 0), (0, 1), (0, -1)].iter().all(|(dx, dy)| {
                    let (xx, yy) = (x + dx, y + dy);
                    xx < 0 || yy < 0 || xx >= w || yy >= h || at(xx, yy) == c
                });
                if interior {
                    continue;
                }
                for (dx, dy) in &disc {
                    let (xx, yy) = (x + dx, y + dy);
                    if xx >= 0 && yy >= 0 && xx < w && yy < h {
                        labels[(yy * w + xx) as usize] = c;
                    }
                }
            }
        }
    }
    if classes > 1 {
        for l in labels.iter_mut() {
            if r.next_f64() < flip {
                let other = r.below(classes as usize - 1) as u16;
                *l = if other >= *l { other + 1 } else { other };
            }
        }
    }
}

/// Fraction of equal labels.
pub fn accuracy(pred: &[i32], truth: &[i32]) -> f64 {
    assert_eq!(pred.len(), truth.len(), "one prediction per truth");
    let ok = pred.iter().zip(truth).filter(|(a, b)| a == b).count();
    ok as f64 / truth.len().max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corrupt_moves_boundaries_by_the_radius() {
        let (w, h) = (40u32, 30u32);
        let square = |l: &[u16]| {
            let xs: Vec<u32> = (0..w * h)
                .filter(|&p| l[p as usize] == 1)
                .map(|p| p % w)
                .collect();
            (xs.len(), xs.iter().min().copied(), xs.iter().max().copied())
        };
        let mut base = vec![0u16; (w * h) as usize];
        for y in 10..20 {
            for x in 10..30 {
                base[(y * w + x) as usize] = 1;
            }
        }
        let (mut grew, mut shrank) = (false, false);
        for seed in 0..8 {
            let mut l = base.clone();
            corrupt(&mut l, w, h, 2, 3, 0.0, seed);
            match square(&l) {
                (_, Some(7), Some(32)) => grew = true,
                (n, Some(13), Some(26)) => {
                    assert_eq!(n, 14 * 4);
                    shrank = true
                }
                other => panic!("seed {seed}: {other:?}"),
            }
        }
        assert!(grew && shrank);
        let mut l = base.clone();
        corrupt(&mut l, w, h, 2, 0, 0.25, 3);
        let flipped = l.iter().zip(&base).filter(|(a, b)| a != b).count();
        assert!((200..400).contains(&flipped), "{flipped}");
    }

    #[test]
    fn samples_lie_on_free_surfaces() {
        let s = three_parts(5000, 2);
        let n = s.truth.len();
        let per: Vec<usize> = (-1..3)
            .map(|l| s.truth.iter().filter(|&&t| t == l).count())
            .collect();
        assert!(
            n > 4000 && n < 5000 && per.iter().all(|&c| c > 300),
            "{n} {per:?}"
        );
        for (i, m) in s.gaussians.means.iter().enumerate() {
            let p = m.map(|v| v as f64);
            let other = |(so, l): &(Solid, i32)| *l != s.truth[i] && so.contains(p);
            assert!(
                !s.solids.iter().any(other),
                "Gaussian {i} inside another solid"
            );
        }
    }
}
