//! Per-Gaussian projection (EWA splatting with gsplat's conventions) and its VJP, written once
//! for every backend: 3D covariance (optionally deformed), camera transform, Jacobian with the
//! frustum clamp, 2D covariance + 0.3 px low-pass, conic, radii, culling, opacity (with the
//! antialiased compensation) and view-dependent colour.

use crate::camera::{consts, Camera, RasterizeMode};
use crate::covariance::*;
use crate::real::*;
use crate::sh;

/// A camera in the scalar type of the computation.
#[derive(Clone, Copy, Debug)]
pub struct CamParams<T> {
    /// World-to-camera rotation.
    pub rot: M3<T>,
    /// World-to-camera translation.
    pub trans: V3<T>,
    /// Camera centre in world coordinates.
    pub campos: V3<T>,
    /// Focal length x (px).
    pub fx: T,
    /// Focal length y (px).
    pub fy: T,
    /// Principal point x (px).
    pub cx: T,
    /// Principal point y (px), of the full image for a cropped camera.
    pub cy: T,
    /// Image width.
    pub width: u32,
    /// Image height (the full image's for a cropped camera).
    pub height: u32,
    /// The rows composited, `rows[0] .. rows[1]` of the `height` rows: all of them, or the
    /// band of a cropped camera ([`Camera::crop_rows`]). Projection and binning are those of
    /// the full image either way, so a band's pixels are the full image's.
    pub rows: [u32; 2],
    /// Near plane.
    pub near: T,
    /// Far plane.
    pub far: T,
    /// Antialiased mode (opacity compensation).
    pub antialiased: bool,
    /// Frustum clamp of the projection's Jacobian, `[x+, x-, y+, y-]` (limits of `x / z`
    /// and `y / z`, gsplat's `(W - cx) / fx + 0.3 tan_x` ...), from the full image when the
    /// camera is a crop.
    pub lims: [T; 4],
}

impl<T: Real> CamParams<T> {
    /// Converts a [`Camera`] (f64) and the rasterize mode. A cropped camera gives the full
    /// image's projection with [`CamParams::rows`] its band.
    pub fn new(cam: &Camera, mode: RasterizeMode) -> Self {
        let c = T::c;
        let (w, fx, fy, cx) = (c(cam.width as f64), c(cam.fx), c(cam.fy), c(cam.cx));
        let (full_h, full_cy) = cam.full_frame_y();
        let row0 = cam.crop.map_or(0, |r| r.row0);
        let (h, cy) = (c(full_h as f64), c(full_cy));
        let tan_x = c(0.5) * w / fx;
        let tan_y = c(0.5) * h / fy;
        let lims = [
            (w - cx) / fx + c(0.3) * tan_x,
            cx / fx + c(0.3) * tan_x,
            (h - cy) / fy + c(0.3) * tan_y,
            cy / fy + c(0.3) * tan_y,
        ];
        CamParams {
            lims,
            rot: cast3(&cam.rotation()),
            trans: castv(cam.translation()),
            campos: castv(cam.position()),
            fx: T::c(cam.fx),
            fy: T::c(cam.fy),
            cx: T::c(cam.cx),
            cy: T::c(full_cy),
            width: cam.width,
            height: full_h,
            rows: [row0, row0 + cam.height],
            near: T::c(cam.near),
            far: T::c(cam.far),
            antialiased: mode == RasterizeMode::Antialiased,
        }
    }
}

/// The raw parameters of one Gaussian (SH coefficients are passed beside it).
#[derive(Clone, Copy, Debug)]
pub struct GaussianIn<T> {
    /// Centre (deformed centre when `f` is given).
    pub mean: V3<T>,
    /// Log-scales.
    pub log_scale: V3<T>,
    /// Unnormalised quaternion (w, x, y, z).
    pub quat: [T; 4],
    /// Opacity logit.
    pub opacity_logit: T,
    /// Deformation gradient, if deformed.
    pub f: Option<M3<T>>,
}

/// A projected Gaussian: what the rasterizer needs.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct Projected<T> {
    /// Centre in pixels (u, v).
    pub mean2d: [T; 2],
    /// Inverse 2D covariance (a, b, c): `[[a, b], [b, c]]`.
    pub conic: [T; 3],
    /// Camera-space depth z.
    pub depth: T,
    /// Opacity used (after compensation).
    pub opacity: T,
    /// Colour.
    pub color: [T; 3],
    /// Pixel radii (x, y); (0, 0) = culled.
    pub radii: [u32; 2],
}

/// Upstream gradient of a [`Projected`] (depth gets none: it only enters the depth output).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct ProjectedGrad<T> {
    /// dL/d(u, v).
    pub mean2d: [T; 2],
    /// dL/d(a, b, c).
    pub conic: [T; 3],
    /// dL/dopacity.
    pub opacity: T,
    /// dL/dcolour.
    pub color: [T; 3],
}

impl<T: Real> ProjectedGrad<T> {
    /// `self += o`.
    pub fn add(&mut self, o: &Self) {
        for i in 0..2 {
            self.mean2d[i] += o.mean2d[i];
        }
        for i in 0..3 {
            self.conic[i] += o.conic[i];
            self.color[i] += o.color[i];
        }
        self.opacity += o.opacity;
    }
}

/// Gradient of one Gaussian's raw parameters (SH gradients are added into a slice).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GaussianGrad<T> {
    /// dL/dmean.
    pub mean: V3<T>,
    /// dL/dlog_scale.
    pub log_scale: V3<T>,
    /// dL/dquat.
    pub quat: [T; 4],
    /// dL/dopacity_logit.
    pub opacity_logit: T,
    /// dL/dF (zero without deformation).
    pub f: M3<T>,
    /// dL/dSigma' (the covariance the camera sees, after the deformation).
    pub cov3d: M3<T>,
}

fn sigmoid<T: Real>(x: T) -> T {
    T::one() / (T::one() + (-x).exp())
}

/// Everything of the forward pass the VJP needs again.
struct Fwd<T> {
    sigma0: M3<T>,
    mc: V3<T>,
    sc: M3<T>,
    j: [[T; 3]; 2],
    xc: T,
    yc: T,
    clamp_x: Option<T>,
    clamp_y: Option<T>,
    cov0: [T; 3],
    cov: [T; 3],
    det: T,
    det_clamped: bool,
    polar: Option<M3<T>>,
    dir_w: V3<T>,
    dir: V3<T>,
}

fn forward<T: Real>(g: &GaussianIn<T>, cam: &CamParams<T>) -> Option<Fwd<T>> {
    let c = T::c;
    let mc = {
        let r = mat_vec(&cam.rot, &g.mean);
        [
            r[0] + cam.trans[0],
            r[1] + cam.trans[1],
            r[2] + cam.trans[2],
        ]
    };
    let (x, y, z) = (mc[0], mc[1], mc[2]);
    if !(z > cam.near && z < cam.far) {
        return None;
    }
    let sigma0 = covariance(&g.log_scale, &g.quat);
    let sigma = match &g.f {
        Some(f) => deform_covariance(f, &sigma0),
        None => sigma0,
    };
    let sc = mul_bt(&mul(&cam.rot, &sigma), &cam.rot);
    let [lim_xp, lim_xn, lim_yp, lim_yn] = cam.lims;
    let clamp = |v: T, lo: T, hi: T| -> (T, Option<T>) {
        let r = v / z;
        if r < lo {
            (z * lo, Some(lo))
        } else if r > hi {
            (z * hi, Some(hi))
        } else {
            (v, None)
        }
    };
    let (xc, clamp_x) = clamp(x, -lim_xn, lim_xp);
    let (yc, clamp_y) = clamp(y, -lim_yn, lim_yp);
    let zero = T::zero();
    let j = [
        [cam.fx / z, zero, -cam.fx * xc / (z * z)],
        [zero, cam.fy / z, -cam.fy * yc / (z * z)],
    ];
    // cov2d = J sc J^T
    let mut cov0 = [zero; 3];
    for a in 0..3 {
        for b in 0..3 {
            cov0[0] += j[0][a] * sc[a][b] * j[0][b];
            cov0[1] += j[0][a] * sc[a][b] * j[1][b];
            cov0[2] += j[1][a] * sc[a][b] * j[1][b];
        }
    }
    let eps = c(consts::EPS2D);
    let cov = [cov0[0] + eps, cov0[1], cov0[2] + eps];
    let det_raw = cov[0] * cov[2] - cov[1] * cov[1];
    let floor = c(1e-10);
    let (det, det_clamped) = if det_raw < floor {
        (floor, true)
    } else {
        (det_raw, false)
    };
    let polar = g.f.as_ref().map(polar_rotation);
    let dir_w = [0, 1, 2].map(|i| g.mean[i] - cam.campos[i]);
    let dir = match &polar {
        Some(r) => mat_t_vec(r, &dir_w),
        None => dir_w,
    };
    Some(Fwd {
        sigma0,
        mc,
        sc,
        j,
        xc,
        yc,
        clamp_x,
        clamp_y,
        cov0,
        cov,
        det,
        det_clamped,
        polar,
        dir_w,
        dir,
    })
}

/// Projects one Gaussian; `None` when it is culled (near/far planes or off screen).
pub fn project<T: Real>(
    g: &GaussianIn<T>,
    sh_coeffs: &[T],
    sh_degree: u32,
    cam: &CamParams<T>,
) -> Option<Projected<T>> {
    let c = T::c;
    let f = forward(g, cam)?;
    let (x, y, z) = (f.mc[0], f.mc[1], f.mc[2]);
    let u = cam.fx * x / z + cam.cx;
    let v = cam.fy * y / z + cam.cy;
    let rx = (c(consts::RADIUS_SIGMAS) * f.cov[0].sqrt()).ceil();
    let ry = (c(consts::RADIUS_SIGMAS) * f.cov[2].sqrt()).ceil();
    let (w, h) = (c(cam.width as f64), c(cam.height as f64));
    if !(rx.is_finite() && ry.is_finite())
        || u + rx <= T::zero()
        || u - rx >= w
        || v + ry <= T::zero()
        || v - ry >= h
    {
        return None;
    }
    let mut opacity = sigmoid(g.opacity_logit);
    if cam.antialiased {
        let det0 = f.cov0[0] * f.cov0[2] - f.cov0[1] * f.cov0[1];
        opacity *= (det0 / f.det).max(T::zero()).sqrt();
    }
    Some(Projected {
        mean2d: [u, v],
        conic: [f.cov[2] / f.det, -f.cov[1] / f.det, f.cov[0] / f.det],
        depth: z,
        opacity,
        color: sh::eval(sh_degree, sh_coeffs, &f.dir),
        radii: [rx.to_u32().unwrap_or(0), ry.to_u32().unwrap_or(0)],
    })
}

/// VJP of [`project`] for a Gaussian that was not culled: returns the raw-parameter gradient
/// and adds dL/dsh into `d_sh` (`[k][c]`).
pub fn project_vjp<T: Real>(
    g: &GaussianIn<T>,
    sh_coeffs: &[T],
    sh_degree: u32,
    cam: &CamParams<T>,
    d: &ProjectedGrad<T>,
    d_sh: &mut [T],
) -> GaussianGrad<T> {
    let c = T::c;
    let zero = T::zero();
    let mut out = GaussianGrad::default();
    let Some(f) = forward(g, cam) else {
        return out;
    };
    // Colour.
    let d_dir = sh::eval_vjp(sh_degree, sh_coeffs, &f.dir, &d.color, d_sh);
    let mut g_polar = zero3::<T>();
    let d_dir_w = match &f.polar {
        Some(r) => {
            for jj in 0..3 {
                for ii in 0..3 {
                    g_polar[jj][ii] = f.dir_w[jj] * d_dir[ii];
                }
            }
            mat_vec(r, &d_dir)
        }
        None => d_dir,
    };
    out.mean = d_dir_w;
    // Opacity.
    let sig = sigmoid(g.opacity_logit);
    let det0 = f.cov0[0] * f.cov0[2] - f.cov0[1] * f.cov0[1];
    let ratio = det0 / f.det;
    let comp = if cam.antialiased {
        ratio.max(zero).sqrt()
    } else {
        T::one()
    };
    out.opacity_logit = d.opacity * comp * sig * (T::one() - sig);
    // Conic and compensation -> 2D covariance.
    let (a2, b2, c2) = (f.cov[0], f.cov[1], f.cov[2]);
    let det = f.det;
    let [ga, gb, gc] = d.conic;
    let mut g_det = -(ga * c2 - gb * b2 + gc * a2) / (det * det);
    let mut g_det0 = zero;
    if cam.antialiased && ratio > zero {
        let g_ratio = d.opacity * sig * c(0.5) / comp;
        g_det0 = g_ratio / det;
        g_det -= g_ratio * det0 / (det * det);
    }
    if f.det_clamped {
        g_det = zero;
    }
    let mut g_a = gc / det + g_det * c2 + g_det0 * f.cov0[2];
    let mut g_c = ga / det + g_det * a2 + g_det0 * f.cov0[0];
    let mut g_b = -gb / det - c(2.0) * b2 * g_det - c(2.0) * f.cov0[1] * g_det0;
    if !(g_a.is_finite() && g_b.is_finite() && g_c.is_finite()) {
        (g_a, g_b, g_c) = (zero, zero, zero);
    }
    // Mean 2D.
    let (x, y, z) = (f.mc[0], f.mc[1], f.mc[2]);
    let mut g_mc = [
        d.mean2d[0] * cam.fx / z,
        d.mean2d[1] * cam.fy / z,
        -d.mean2d[0] * cam.fx * x / (z * z) - d.mean2d[1] * cam.fy * y / (z * z),
    ];
    // cov2d = J sc J^T with G2 = [[g_a, g_b/2], [g_b/2, g_c]].
    let g2 = [[g_a, g_b * c(0.5)], [g_b * c(0.5), g_c]];
    let j = &f.j;
    let mut g_sc = zero3::<T>();
    for a in 0..3 {
        for b in 0..3 {
            let mut s = zero;
            for p in 0..2 {
                for q in 0..2 {
                    s += j[p][a] * g2[p][q] * j[q][b];
                }
            }
            g_sc[a][b] = s;
        }
    }
    // g_J = 2 G2 J sc
    let mut g_j = [[zero; 3]; 2];
    for p in 0..2 {
        for a in 0..3 {
            let mut s = zero;
            for q in 0..2 {
                for b in 0..3 {
                    s += g2[p][q] * j[q][b] * f.sc[b][a];
                }
            }
            g_j[p][a] = c(2.0) * s;
        }
    }
    let z2 = z * z;
    let z3 = z2 * z;
    g_mc[2] += -cam.fx / z2 * g_j[0][0] - cam.fy / z2 * g_j[1][1]
        + c(2.0) * cam.fx * f.xc / z3 * g_j[0][2]
        + c(2.0) * cam.fy * f.yc / z3 * g_j[1][2];
    let g_xc = -cam.fx / z2 * g_j[0][2];
    let g_yc = -cam.fy / z2 * g_j[1][2];
    match f.clamp_x {
        Some(l) => g_mc[2] += g_xc * l,
        None => g_mc[0] += g_xc,
    }
    match f.clamp_y {
        Some(l) => g_mc[2] += g_yc * l,
        None => g_mc[1] += g_yc,
    }
    let g_mean = mat_t_vec(&cam.rot, &g_mc);
    for i in 0..3 {
        out.mean[i] += g_mean[i];
    }
    // sc = W Sigma' W^T.
    let g_sigma = mul(&mul_at(&cam.rot, &g_sc), &cam.rot);
    out.cov3d = g_sigma;
    let g_sigma0 = match &g.f {
        Some(fm) => {
            let (g_s0, g_f) = deform_covariance_vjp(fm, &f.sigma0, &g_sigma);
            let r = f.polar.as_ref().expect("polar with F");
            out.f = add(&g_f, &polar_rotation_vjp(fm, r, &g_polar));
            g_s0
        }
        None => g_sigma,
    };
    let (g_ls, g_q) = covariance_vjp(&g.log_scale, &g.quat, &g_sigma0);
    out.log_scale = g_ls;
    out.quat = g_q;
    out
}
