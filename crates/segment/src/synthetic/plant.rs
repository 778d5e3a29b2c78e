//! A harder synthetic scene for part lifting: a potted plant, with the structures real
//! segmenters get wrong and ground truth from geometry.
//!
//! * Floor (static, -1): the square `[-0.6, 0.6]^2` at `z = 0`.
//! * Part 0, `pot`: a thick-walled open cylinder (outer radius 0.22, inner 0.19, height 0.25,
//!   bottom 0.03 thick) with its rim.
//! * Part 1, `soil`: fills the pot up to `z = 0.19`, 6 cm below the rim: seen only through the
//!   opening, at a grazing angle from the low views.
//! * Part 2, `stem`: a curved tube of radius 0.011 (a chain of capsules) from the soil to the
//!   flower, 3-4 pixels wide in the 256x256 views.
//! * Part 3, `leaves`: five thin drooping leaves (flat ellipsoids 0.13 x 0.045 x 0.004) on
//!   the stem.
//! * Part 4, `petals`: seven petals (flat ellipsoids) around the top of the stem.
//!
//! The Gaussians are surfels on the free surface of the union (as in
//! [`three_parts`](super::three_parts)), anisotropic up to 15:1 in the surface plane (along
//! the stem and the leaves), in natural colours (the stem and the leaves share a green, pot and
//! soil are two browns), with **non-unit quaternions** (random norm in [0.3, 3]) and in a
//! **shuffled order**. Masks are ray-cast from the same primitives
//! ([`PlantScene::label_mask`]); [`corrupt_parts`] and [`mislabel_part`] degrade them like a
//! real segmenter.

use super::{cross, dot, normalize, quat_from_axes, sub, Rng};
use crate::mask::{InMemoryMasks, Mask, MaskData};
use r4d_splat::{Camera, Gaussians};

/// A primitive of the plant scene: a convex solid, or a difference of two.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Prim {
    /// The floor square `[-half, half]^2` at `z = 0` (a surface).
    Floor {
        /// Half the side.
        half: f64,
    },
    /// A vertical cylinder.
    Cylinder {
        /// Axis `(x, y)`.
        axis: [f64; 2],
        /// Radius.
        radius: f64,
        /// Bottom and top.
        z: [f64; 2],
    },
    /// An open vessel: the outer cylinder minus the inner one (from `inner_z0` up, open top).
    Vessel {
        /// Axis `(x, y)`.
        axis: [f64; 2],
        /// Outer radius.
        outer: f64,
        /// Inner radius.
        inner: f64,
        /// Height of the rim.
        height: f64,
        /// Height of the inner floor (bottom thickness).
        inner_z0: f64,
    },
    /// A capsule (a segment swept by a sphere).
    Capsule {
        /// One end.
        a: [f64; 3],
        /// The other end.
        b: [f64; 3],
        /// Radius.
        r: f64,
    },
    /// An ellipsoid `c + R diag(r) u`, `|u| = 1` (columns of `axes`: unit axes).
    Ellipsoid {
        /// Centre.
        c: [f64; 3],
        /// Unit axes.
        axes: [[f64; 3]; 3],
        /// Semi-axes.
        r: [f64; 3],
    },
}

const EPS: f64 = 1e-9;

fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    a.map(|v| v * s)
}

/// `[t0, t1]` where the ray is inside a convex solid (possibly `t0 < 0`).
type Span = Option<(f64, f64)>;

fn cyl_span(axis: [f64; 2], radius: f64, z: [f64; 2], o: [f64; 3], d: [f64; 3]) -> Span {
    let (ox, oy) = (o[0] - axis[0], o[1] - axis[1]);
    let a = d[0] * d[0] + d[1] * d[1];
    let (mut t0, mut t1) = if a > EPS {
        let b = ox * d[0] + oy * d[1];
        let c = ox * ox + oy * oy - radius * radius;
        let disc = b * b - a * c;
        if disc < 0.0 {
            return None;
        }
        let s = disc.sqrt();
        ((-b - s) / a, (-b + s) / a)
    } else if ox * ox + oy * oy < radius * radius {
        (f64::NEG_INFINITY, f64::INFINITY)
    } else {
        return None;
    };
    if d[2].abs() > EPS {
        let (za, zb) = ((z[0] - o[2]) / d[2], (z[1] - o[2]) / d[2]);
        t0 = t0.max(za.min(zb));
        t1 = t1.min(za.max(zb));
    } else if o[2] < z[0] || o[2] > z[1] {
        return None;
    }
    (t0 <= t1).then_some((t0, t1))
}

fn sphere_span(c: [f64; 3], r: f64, o: [f64; 3], d: [f64; 3]) -> Span {
    let oc = sub(o, c);
    let (a, b, cc) = (dot(d, d), dot(oc, d), dot(oc, oc) - r * r);
    let disc = b * b - a * cc;
    if disc < 0.0 {
        return None;
    }
    let s = disc.sqrt();
    Some(((-b - s) / a, (-b + s) / a))
}

fn capsule_span(a: [f64; 3], b: [f64; 3], r: f64, o: [f64; 3], d: [f64; 3]) -> Span {
    let ab = sub(b, a);
    let len = dot(ab, ab).sqrt();
    let u = scale(ab, 1.0 / len);
    let oc = sub(o, a);
    let (du, ou) = (dot(d, u), dot(oc, u));
    let dp = sub(d, scale(u, du));
    let op = sub(oc, scale(u, ou));
    let mut body: Span = None;
    let qa = dot(dp, dp);
    if qa > EPS {
        let qb = dot(op, dp);
        let qc = dot(op, op) - r * r;
        let disc = qb * qb - qa * qc;
        if disc >= 0.0 {
            let s = disc.sqrt();
            let (mut t0, mut t1) = ((-qb - s) / qa, (-qb + s) / qa);
            if du.abs() > EPS {
                let (sa, sb) = (-ou / du, (len - ou) / du);
                t0 = t0.max(sa.min(sb));
                t1 = t1.min(sa.max(sb));
            } else if !(0.0..=len).contains(&ou) {
                t1 = t0 - 1.0;
            }
            if t0 <= t1 {
                body = Some((t0, t1));
            }
        }
    }
    // The union of three convex pieces is convex: one interval.
    [body, sphere_span(a, r, o, d), sphere_span(b, r, o, d)]
        .into_iter()
        .flatten()
        .reduce(|x, y| (x.0.min(y.0), x.1.max(y.1)))
}

fn ellipsoid_span(c: [f64; 3], axes: [[f64; 3]; 3], r: [f64; 3], o: [f64; 3], d: [f64; 3]) -> Span {
    // In the frame where the ellipsoid is the unit sphere.
    let oc = sub(o, c);
    let lo = [0, 1, 2].map(|k| dot(oc, axes[k]) / r[k]);
    let ld = [0, 1, 2].map(|k| dot(d, axes[k]) / r[k]);
    sphere_span([0.0; 3], 1.0, lo, ld)
}

impl Prim {
    /// Strictly inside (the floor has no inside).
    pub fn contains(&self, p: [f64; 3]) -> bool {
        match *self {
            Prim::Floor { .. } => false,
            Prim::Cylinder { axis, radius, z } => {
                let (dx, dy) = (p[0] - axis[0], p[1] - axis[1]);
                dx * dx + dy * dy < radius * radius && p[2] > z[0] && p[2] < z[1]
            }
            Prim::Vessel {
                axis,
                outer,
                inner,
                height,
                inner_z0,
            } => {
                let (dx, dy) = (p[0] - axis[0], p[1] - axis[1]);
                let rr = dx * dx + dy * dy;
                let in_outer = rr < outer * outer && p[2] > 0.0 && p[2] < height;
                let in_inner = rr <= inner * inner && p[2] >= inner_z0;
                in_outer && !in_inner
            }
            Prim::Capsule { a, b, r } => {
                let ab = sub(b, a);
                let t = (dot(sub(p, a), ab) / dot(ab, ab)).clamp(0.0, 1.0);
                let q = sub(p, add(a, scale(ab, t)));
                dot(q, q) < r * r
            }
            Prim::Ellipsoid { c, axes, r } => {
                let q = sub(p, c);
                (0..3)
                    .map(|k| (dot(q, axes[k]) / r[k]).powi(2))
                    .sum::<f64>()
                    < 1.0
            }
        }
    }

    /// The smallest `t > 0` where the ray `o + t d` enters the primitive (rays start
    /// outside every solid).
    pub fn hit(&self, o: [f64; 3], d: [f64; 3]) -> Option<f64> {
        let first = |s: Span| s.and_then(|(t0, _)| (t0 > EPS).then_some(t0));
        match *self {
            Prim::Floor { half } => {
                if d[2].abs() < EPS {
                    return None;
                }
                let t = -o[2] / d[2];
                let p = [o[0] + t * d[0], o[1] + t * d[1]];
                (t > EPS && p[0].abs() <= half && p[1].abs() <= half).then_some(t)
            }
            Prim::Cylinder { axis, radius, z } => first(cyl_span(axis, radius, z, o, d)),
            Prim::Vessel {
                axis,
                outer,
                inner,
                height,
                inner_z0,
            } => {
                let (a0, a1) = cyl_span(axis, outer, [0.0, height], o, d)?;
                // The cavity reaches above the rim (open top).
                match cyl_span(axis, inner, [inner_z0, height + 10.0], o, d) {
                    Some((b0, b1)) if a0 >= b0 && a0 <= b1 => (b1 < a1 && b1 > EPS).then_some(b1),
                    _ => (a0 > EPS).then_some(a0),
                }
            }
            Prim::Capsule { a, b, r } => first(capsule_span(a, b, r, o, d)),
            Prim::Ellipsoid { c, axes, r } => first(ellipsoid_span(c, axes, r, o, d)),
        }
    }
}

/// The potted-plant scene (see the module docs).
#[derive(Clone, Debug)]
pub struct PlantScene {
    /// The Gaussians (shuffled, non-unit quaternions).
    pub gaussians: Gaussians,
    /// The true label of every Gaussian (-1: floor).
    pub truth: Vec<i32>,
    /// The primitives with their labels.
    pub prims: Vec<(Prim, i32)>,
    /// The part names: `pot, soil, stem, leaves, petals`.
    pub class_names: Vec<String>,
}

/// How far an in-plane offset may go: the face it must stay on.
#[derive(Clone, Copy, Debug)]
enum Keep {
    /// Within the square `|x|, |y| <= half`.
    Square(f64),
    /// Within radii `[r0, r1]` of the axis (horizontal faces) or heights (vertical faces).
    Annulus([f64; 2], f64, f64),
    /// Height range of a vertical cylinder side.
    Heights(f64, f64),
    /// Within the outline of the primitive with this index (capsule: within 1.3 radii of
    /// its axis segment; flat ellipsoid: inside its outline).
    Near(usize),
}

/// A surface sample: position, outward normal, in-plane axes, their largest scales, label,
/// face.
struct Sample {
    p: [f64; 3],
    n: [f64; 3],
    axes: [[f64; 3]; 2],
    max_scale: [f64; 2],
    label: i32,
    keep: Keep,
}

/// Parameters of the plant's layout.
const POT_AXIS: [f64; 2] = [0.0, 0.0];
const POT_OUTER: f64 = 0.22;
const POT_INNER: f64 = 0.19;
const POT_H: f64 = 0.25;
const POT_BOTTOM: f64 = 0.03;
const SOIL_Z: f64 = 0.19;
const STEM_R: f64 = 0.011;

/// The stem's centre line: a bent curve from inside the soil to the flower.
fn stem_point(t: f64) -> [f64; 3] {
    let z = SOIL_Z - 0.02 + t * 0.5;
    let bend = 0.09 * t * t;
    [bend, 0.03 * (3.0 * t).sin(), z]
}

fn leaf(at: f64, azimuth_deg: f64, droop: f64) -> Prim {
    let base = stem_point(at);
    let az = azimuth_deg.to_radians();
    let long = normalize([az.cos(), az.sin(), -droop]);
    let side = normalize(cross([0.0, 0.0, 1.0], long));
    let n = cross(long, side);
    let r = [0.13, 0.045, 0.004];
    Prim::Ellipsoid {
        c: add(base, scale(long, r[0] * 0.92)),
        axes: [long, side, n],
        r,
    }
}

fn petal(k: usize, count: usize) -> Prim {
    let top = stem_point(1.0);
    let az = (k as f64 / count as f64 * 360.0 + 10.0).to_radians();
    let long = normalize([az.cos(), az.sin(), 0.45]);
    let side = normalize(cross([0.0, 0.0, 1.0], long));
    let n = cross(long, side);
    let r = [0.06, 0.026, 0.005];
    Prim::Ellipsoid {
        c: add(top, scale(long, r[0] * 0.85)),
        axes: [long, side, n],
        r,
    }
}

/// The scene's primitives with labels (floor -1, then the parts in order).
fn primitives() -> Vec<(Prim, i32)> {
    let mut prims = vec![
        (Prim::Floor { half: 0.6 }, -1),
        (
            Prim::Vessel {
                axis: POT_AXIS,
                outer: POT_OUTER,
                inner: POT_INNER,
                height: POT_H,
                inner_z0: POT_BOTTOM,
            },
            0,
        ),
        (
            Prim::Cylinder {
                axis: POT_AXIS,
                radius: POT_INNER,
                z: [POT_BOTTOM, SOIL_Z],
            },
            1,
        ),
    ];
    let segs = 8;
    for s in 0..segs {
        let (t0, t1) = (s as f64 / segs as f64, (s + 1) as f64 / segs as f64);
        prims.push((
            Prim::Capsule {
                a: stem_point(t0),
                b: stem_point(t1),
                r: STEM_R,
            },
            2,
        ));
    }
    for (at, az, droop) in [
        (0.40, 20.0, 0.3),
        (0.50, 150.0, 0.45),
        (0.58, 265.0, 0.3),
        (0.67, 75.0, 0.5),
        (0.76, 205.0, 0.4),
    ] {
        prims.push((leaf(at, az, droop), 3));
    }
    for k in 0..7 {
        prims.push((petal(k, 7), 4));
    }
    prims
}

fn push_grid(
    out: &mut Vec<Sample>,
    r: &mut Rng,
    (nu, nv): (usize, usize),
    mut at: impl FnMut(f64, f64) -> Option<Sample>,
) {
    for a in 0..nu {
        for b in 0..nv {
            let u = (a as f64 + r.range(0.15, 0.85)) / nu as f64;
            let v = (b as f64 + r.range(0.15, 0.85)) / nv as f64;
            if let Some(s) = at(u, v) {
                out.push(s);
            }
        }
    }
}

fn frame(n: [f64; 3]) -> [[f64; 3]; 2] {
    let helper = if n[2].abs() < 0.9 {
        [0.0, 0.0, 1.0]
    } else {
        [1.0, 0.0, 0.0]
    };
    let t1 = normalize(cross(helper, n));
    [t1, cross(n, t1)]
}

/// The potted plant with about `n` Gaussians (before dropping hidden samples), `seed` for
/// the jitter, the anisotropy, the quaternion norms and the order.
pub fn potted_plant(n: usize, seed: u64) -> PlantScene {
    use std::f64::consts::PI;
    let prims = primitives();
    let mut r = Rng(seed);
    // Thin parts are sampled 2x finer than the pot, the floor 2x coarser.
    let weighted_area = 1.44 / 4.0
        + 2.0 * PI * POT_OUTER * POT_H
        + 2.0 * PI * POT_INNER * (POT_H - SOIL_Z)
        + PI * (POT_OUTER * POT_OUTER - POT_INNER * POT_INNER)
        + PI * POT_INNER * POT_INNER
        + 4.0
            * (2.0 * PI * STEM_R * 0.5
                + 5.0 * 2.0 * PI * 0.13 * 0.045
                + 7.0 * 2.0 * PI * 0.06 * 0.026);
    let s = (weighted_area / n.max(1) as f64).sqrt();
    let mut out: Vec<Sample> = Vec::new();
    let ez = [0.0, 0.0, 1.0];
    // Floor, spacing 2s.
    let nf = (1.2 / (2.0 * s)).round().max(1.0) as usize;
    push_grid(&mut out, &mut r, (nf, nf), |u, v| {
        Some(Sample {
            p: [-0.6 + 1.2 * u, -0.6 + 1.2 * v, 0.0],
            n: ez,
            axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            max_scale: [1.4 * s; 2],
            label: -1,
            keep: Keep::Square(0.6),
        })
    });
    // Pot: outer side, inner side above the soil (normal towards the axis), rim.
    let side = |out: &mut Vec<Sample>, r: &mut Rng, rad: f64, z: [f64; 2], sign: f64| {
        let nphi = ((2.0 * PI * rad / s).round() as usize).max(3);
        let nz = ((z[1] - z[0]) / s).round().max(1.0) as usize;
        push_grid(out, r, (nphi, nz), |u, v| {
            let phi = 2.0 * PI * u;
            let nrm = [sign * phi.cos(), sign * phi.sin(), 0.0];
            Some(Sample {
                p: [rad * phi.cos(), rad * phi.sin(), z[0] + v * (z[1] - z[0])],
                n: nrm,
                // Right-handed (axes[0] x axes[1] = normal) on both sides.
                axes: if sign > 0.0 {
                    [[-phi.sin(), phi.cos(), 0.0], ez]
                } else {
                    [ez, [-phi.sin(), phi.cos(), 0.0]]
                },
                max_scale: [0.7 * s, 0.7 * s],
                label: 0,
                keep: Keep::Heights(z[0], z[1]),
            })
        });
    };
    side(&mut out, &mut r, POT_OUTER, [0.0, POT_H], 1.0);
    side(&mut out, &mut r, POT_INNER, [SOIL_Z, POT_H], -1.0);
    let disc =
        |out: &mut Vec<Sample>, r: &mut Rng, r0: f64, r1: f64, z: f64, label: i32, sp: f64| {
            let nd = (2.0 * r1 / sp).round().max(1.0) as usize;
            push_grid(out, r, (nd, nd), |u, v| {
                let (x, y) = (-r1 + 2.0 * r1 * u, -r1 + 2.0 * r1 * v);
                let rr = (x * x + y * y).sqrt();
                (rr >= r0 && rr <= r1).then_some(Sample {
                    p: [x, y, z],
                    n: ez,
                    axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                    max_scale: [0.7 * sp; 2],
                    label,
                    keep: Keep::Annulus([0.0, 0.0], r0, r1),
                })
            });
        };
    disc(&mut out, &mut r, POT_INNER, POT_OUTER, POT_H, 0, s);
    disc(&mut out, &mut r, 0.0, POT_INNER, SOIL_Z, 1, s);
    // Thin parts at spacing s / 2.
    let st = s / 2.0;
    for (pi, (prim, label)) in prims.iter().enumerate() {
        match *prim {
            Prim::Capsule { a, b, r: cr } => {
                let ab = sub(b, a);
                let len = dot(ab, ab).sqrt();
                let u = scale(ab, 1.0 / len);
                let [t1, t2] = frame(u);
                let nphi = ((2.0 * PI * cr / st).round() as usize).max(6);
                // Along the stem: elongated surfels, up to 15:1.
                let nl = ((len / (3.0 * st)).round() as usize).max(1);
                push_grid(&mut out, &mut r, (nphi, nl), |x, y| {
                    let phi = 2.0 * PI * x;
                    let nrm = add(scale(t1, phi.cos()), scale(t2, phi.sin()));
                    let tang = add(scale(t1, -phi.sin()), scale(t2, phi.cos()));
                    Some(Sample {
                        p: add(add(a, scale(u, y * len)), scale(nrm, cr)),
                        n: nrm,
                        axes: [tang, u],
                        max_scale: [0.2 * cr, 3.0 * cr],
                        label: *label,
                        keep: Keep::Near(pi),
                    })
                });
            }
            Prim::Ellipsoid { c, axes, r: er } => {
                // Both faces of a flat ellipsoid, sampled over its outline.
                let (na, nb) = (
                    ((2.0 * er[0] / st).round() as usize).max(2),
                    ((2.0 * er[1] / st).round() as usize).max(2),
                );
                for face in [1.0, -1.0] {
                    push_grid(&mut out, &mut r, (na, nb), |x, y| {
                        let (pu, pv) = (2.0 * x - 1.0, 2.0 * y - 1.0);
                        let q = pu * pu + pv * pv;
                        if q >= 0.97 {
                            return None;
                        }
                        let h = face * (1.0 - q).sqrt();
                        let p = add(
                            c,
                            add(
                                add(scale(axes[0], pu * er[0]), scale(axes[1], pv * er[1])),
                                scale(axes[2], h * er[2]),
                            ),
                        );
                        let g = [pu / er[0], pv / er[1], h / er[2]];
                        let nrm = normalize(add(
                            add(scale(axes[0], g[0]), scale(axes[1], g[1])),
                            scale(axes[2], g[2]),
                        ));
                        // In-plane: along the length and across, elongated towards the tip.
                        let edge = (1.0 - q).sqrt();
                        let ratio = 1.0 + 3.0 * r_aniso(x, y);
                        Some(Sample {
                            p,
                            n: nrm,
                            axes: frame_in(nrm, axes[0]),
                            max_scale: [
                                (0.7 * st * ratio).min(0.45 * er[0] * edge.max(0.2)),
                                0.7 * st * edge.max(0.3),
                            ],
                            label: *label,
                            keep: Keep::Near(pi),
                        })
                    });
                }
            }
            _ => {}
        }
    }
    // Free: the point just outside lies in no solid, and the point is in no other part.
    let free = |q: [f64; 3], nrm: [f64; 3], label: i32| {
        let o = add(q, scale(nrm, 1e-4));
        !prims
            .iter()
            .any(|(pr, l)| pr.contains(o) || (*l != label && pr.contains(q)))
    };
    out.retain(|s| free(s.p, s.n, s.label));
    let mut order: Vec<usize> = (0..out.len()).collect();
    for i in (1..order.len()).rev() {
        order.swap(i, r.below(i + 1));
    }
    let mut g = Gaussians {
        sh_degree: 0,
        ..Default::default()
    };
    let mut truth = Vec::with_capacity(out.len());
    const Y0: f32 = 0.282_094_8;
    for &i in &order {
        let smp = &out[i];
        let on_face = |q: [f64; 3]| match smp.keep {
            Keep::Square(h) => q[0].abs() <= h && q[1].abs() <= h,
            Keep::Annulus(c, r0, r1) => {
                let rr = ((q[0] - c[0]).powi(2) + (q[1] - c[1]).powi(2)).sqrt();
                rr >= r0 && rr <= r1
            }
            Keep::Heights(z0, z1) => (z0..=z1).contains(&q[2]),
            Keep::Near(k) => near(&prims[k].0, q),
        };
        let sc = [0, 1].map(|k| {
            let a = smp.axes[k];
            let mut sa = smp.max_scale[k];
            let ok = |sa: f64| {
                [-1.5, 1.5].iter().all(|&t| {
                    let q = add(smp.p, scale(a, t * sa));
                    on_face(q) && free(q, smp.n, smp.label)
                })
            };
            let floor = smp.max_scale[k] / 5.0;
            while sa > floor && !ok(sa) {
                sa *= 0.8;
            }
            sa
        });
        let thin = sc[0].min(sc[1]) / 20.0;
        g.means.push(smp.p.map(|x| x as f32));
        g.log_scales
            .push([sc[0].ln() as f32, sc[1].ln() as f32, thin.ln() as f32]);
        let q = quat_from_axes(smp.axes[0], smp.axes[1], smp.n);
        let norm = r.range(0.3, 3.0) as f32;
        g.quats.push(q.map(|v| v * norm));
        g.opacity_logits.push(r.range(2.5, 5.0) as f32);
        // Natural colours, not part colours: the stem and the leaves share a green, the pot
        // and the soil are two browns, so colour alone does not give the parts away.
        let c = match smp.label {
            0 => [0.72, 0.40, 0.24],
            1 => [0.32, 0.22, 0.14],
            2 => [0.26, 0.52, 0.20],
            3 => [0.24, 0.50, 0.19],
            4 => [0.88, 0.52, 0.70],
            _ => [0.5, 0.5, 0.5],
        };
        let shade = 0.8 + 0.3 * r.next_f64() as f32;
        g.sh.extend(c.map(|x| (x * shade - 0.5) / Y0));
        truth.push(smp.label);
    }
    PlantScene {
        gaussians: g,
        truth,
        prims,
        class_names: ["pot", "soil", "stem", "leaves", "petals"]
            .map(String::from)
            .to_vec(),
    }
}

/// Whether `q` lies within the outline of a capsule (1.3 radii of its segment) or a flat
/// ellipsoid (inside its outline, within 1.5 thicknesses of its middle plane).
fn near(p: &Prim, q: [f64; 3]) -> bool {
    match *p {
        Prim::Capsule { a, b, r } => {
            let ab = sub(b, a);
            let t = (dot(sub(q, a), ab) / dot(ab, ab)).clamp(0.0, 1.0);
            let d = sub(q, add(a, scale(ab, t)));
            dot(d, d) <= (1.3 * r) * (1.3 * r)
        }
        Prim::Ellipsoid { c, axes, r } => {
            let d = sub(q, c);
            let l = [0, 1, 2].map(|k| dot(d, axes[k]) / r[k]);
            l[0] * l[0] + l[1] * l[1] <= 1.0 && l[2].abs() <= 1.5
        }
        _ => true,
    }
}

/// A deterministic anisotropy in [0, 1] over a leaf (more towards the tip).
fn r_aniso(x: f64, y: f64) -> f64 {
    (x * (0.5 + 0.5 * (7.0 * y).sin().abs())).clamp(0.0, 1.0)
}

/// In-plane axes at a point with normal `n`, the first along `along` projected into the plane.
fn frame_in(n: [f64; 3], along: [f64; 3]) -> [[f64; 3]; 2] {
    let a = sub(along, scale(n, dot(along, n)));
    if dot(a, a) < 1e-12 {
        return frame(n);
    }
    let t1 = normalize(a);
    [t1, cross(n, t1)]
}

/// `n` cameras around the plant at distance 1.5 from `(0, 0, 0.32)`, elevations alternating
/// 20 and 50 degrees, horizontal field of view 50 degrees.
pub fn plant_cameras(n: usize, width: u32, height: u32) -> Vec<Camera> {
    let target = [0.0, 0.0, 0.32];
    (0..n)
        .map(|k| {
            let az = (10.0 + 360.0 * k as f64 / n as f64).to_radians();
            let el = if k % 2 == 0 { 20f64 } else { 50.0 }.to_radians();
            let eye = [
                target[0] + 1.5 * el.cos() * az.cos(),
                target[1] + 1.5 * el.cos() * az.sin(),
                target[2] + 1.5 * el.sin(),
            ];
            let mut c = Camera::look_at(width, height, 50.0, eye, target, [0.0, 0.0, 1.0]);
            c.name = format!("plant_{k:02}.png");
            c
        })
        .collect()
}

impl PlantScene {
    /// The label map the camera sees, ray-cast through every pixel centre: 0 where the
    /// nearest hit is the floor or nothing, `k + 1` where it is part `k`.
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
                let d =
                    [0, 1, 2].map(|k| rot[0][k] * dc[0] + rot[1][k] * dc[1] + rot[2][k] * dc[2]);
                let mut best: Option<(f64, i32)> = None;
                for (p, l) in &self.prims {
                    if let Some(t) = p.hit(o, d) {
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
                    origin: format!("plant view {v}"),
                    width: c.width,
                    height: c.height,
                    data: MaskData::Labels(self.label_mask(c)),
                })
                .collect(),
        }
    }
}

/// Degrades a label map (labels `0 ..= parts`) as a real segmenter does, per part: each part
/// (label >= 1), in a random order, is dilated or eroded (at random) by a random radius in
/// `radii` pixels: dilation paints the part over every pixel within the radius of it, erosion
/// gives each part pixel within the radius of another label that label. Then a `flip`
/// fraction of the pixels gets a random other label.
pub fn corrupt_parts(
    labels: &mut [u16],
    width: u32,
    height: u32,
    parts: u16,
    radii: [i32; 2],
    flip: f64,
    seed: u64,
) {
    let (w, h) = (width as i32, height as i32);
    let mut r = Rng(seed ^ 0x005e_ed0f_c044_u64);
    let mut order: Vec<u16> = (1..=parts).collect();
    for i in (1..order.len()).rev() {
        order.swap(i, r.below(i + 1));
    }
    for c in order {
        let rad = radii[0] + r.below((radii[1] - radii[0] + 1).max(1) as usize) as i32;
        let dilate = r.next_f64() < 0.5;
        let cur = labels.to_vec();
        let at = |x: i32, y: i32| cur[(y * w + x) as usize];
        let disc: Vec<(i32, i32)> = (-rad..=rad)
            .flat_map(|dy| (-rad..=rad).map(move |dx| (dx, dy)))
            .filter(|(dx, dy)| dx * dx + dy * dy <= rad * rad)
            .collect();
        for y in 0..h {
            for x in 0..w {
                let inside = at(x, y) == c;
                if inside == dilate {
                    continue;
                }
                // Dilation: a non-part pixel within `rad` of the part becomes the part.
                // Erosion: a part pixel within `rad` of another label takes that label.
                let mut found = None;
                for (dx, dy) in &disc {
                    let (xx, yy) = (x + dx, y + dy);
                    if xx < 0 || yy < 0 || xx >= w || yy >= h {
                        continue;
                    }
                    let l = at(xx, yy);
                    if (l == c) == dilate {
                        found = Some(l);
                        break;
                    }
                }
                if let Some(l) = found {
                    labels[(y * w + x) as usize] = if dilate { c } else { l };
                }
            }
        }
    }
    if parts >= 1 {
        for l in labels.iter_mut() {
            if r.next_f64() < flip {
                let other = r.below(parts as usize) as u16;
                *l = if other >= *l { other + 1 } else { other };
            }
        }
    }
}

/// Relabels every pixel of label `from` as `to` (a segmenter that confuses two parts in one
/// view).
pub fn mislabel_part(labels: &mut [u16], from: u16, to: u16) {
    for l in labels.iter_mut().filter(|l| **l == from) {
        *l = to;
    }
}

/// Per-class accuracy over the Gaussians selected by `keep`: for each true label `-1 ..
/// num_parts`, `(right, total)`.
pub fn per_part(
    pred: &[i32],
    truth: &[i32],
    num_parts: usize,
    keep: impl Fn(usize) -> bool,
) -> Vec<(usize, usize)> {
    let mut out = vec![(0usize, 0usize); num_parts + 1];
    for (i, (&p, &t)) in pred.iter().zip(truth).enumerate() {
        if !keep(i) || t < -1 || t >= num_parts as i32 {
            continue;
        }
        let e = &mut out[(t + 1) as usize];
        e.1 += 1;
        if p == t {
            e.0 += 1;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn primitives_hit_where_they_contain() {
        // Along random rays the first hit point lies on the surface: just behind it inside,
        // just before it outside.
        let mut r = Rng(5);
        let mut hits = 0;
        for (p, _) in primitives().iter().skip(1) {
            for _ in 0..400 {
                let o = [r.range(-1.0, 1.0), r.range(-1.0, 1.0), r.range(0.8, 1.5)];
                let target = [
                    r.range(-0.25, 0.25),
                    r.range(-0.25, 0.25),
                    r.range(0.0, 0.7),
                ];
                let d = normalize(sub(target, o));
                if let Some(t) = p.hit(o, d) {
                    hits += 1;
                    assert!(p.contains(add(o, scale(d, t + 1e-6))), "{p:?} at {t}");
                    assert!(!p.contains(add(o, scale(d, t - 1e-6))), "{p:?} at {t}");
                }
            }
        }
        assert!(hits > 300, "{hits}");
        // Into the pot's opening, straight down: the soil, not the pot.
        let soil_hit = primitives()[2].0.hit([0.05, 0.0, 1.0], [0.0, 0.0, -1.0]);
        let pot_hit = primitives()[1].0.hit([0.05, 0.0, 1.0], [0.0, 0.0, -1.0]);
        assert!((soil_hit.unwrap() - (1.0 - SOIL_Z)).abs() < 1e-9);
        assert!((pot_hit.unwrap() - (1.0 - POT_BOTTOM)).abs() < 1e-9);
        // Onto the rim.
        let rim = primitives()[1].0.hit([0.2, 0.0, 1.0], [0.0, 0.0, -1.0]);
        assert!((rim.unwrap() - (1.0 - POT_H)).abs() < 1e-9);
    }

    #[test]
    fn plant_has_every_part_with_hard_gaussians() {
        let s = potted_plant(20_000, 3);
        let per: Vec<usize> = (-1..5)
            .map(|l| s.truth.iter().filter(|&&t| t == l).count())
            .collect();
        assert!(per.iter().all(|&c| c > 200), "{per:?}");
        let norms: Vec<f32> = s
            .gaussians
            .quats
            .iter()
            .map(|q| q.iter().map(|v| v * v).sum::<f32>().sqrt())
            .collect();
        assert!(norms.iter().any(|&n| n < 0.5) && norms.iter().any(|&n| n > 2.0));
        let aniso = s
            .gaussians
            .log_scales
            .iter()
            .map(|l| (l[0] - l[1]).abs().exp())
            .fold(0f32, f32::max);
        assert!(aniso > 10.0, "{aniso}");
        // Shuffled: labels are not sorted.
        assert!(s.truth.windows(2).filter(|w| w[0] != w[1]).count() > 1000);
    }

    #[test]
    fn corrupt_parts_erodes_or_dilates_each_part() {
        let (w, h) = (60u32, 40u32);
        let mut base = vec![0u16; (w * h) as usize];
        for y in 10..30 {
            for x in 10..30 {
                base[(y * w + x) as usize] = 1;
            }
        }
        let count = |l: &[u16]| l.iter().filter(|&&v| v == 1).count();
        let (mut grew, mut shrank) = (false, false);
        for seed in 0..10 {
            let mut l = base.clone();
            corrupt_parts(&mut l, w, h, 1, [2, 4], 0.0, seed);
            let c = count(&l);
            if c > 400 {
                assert!((540..=800).contains(&c), "{c}");
                grew = true;
            } else {
                assert!((144..=256).contains(&c), "{c}");
                shrank = true;
            }
        }
        assert!(grew && shrank);
        let mut l = base.clone();
        mislabel_part(&mut l, 1, 2);
        assert_eq!(count(&l), 0);
    }
}
