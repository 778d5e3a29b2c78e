//! The spectral half of Dual-domain Motion Supervision: log-magnitude and phase agreement of
//! the per-patch 3-D DFT of the frame differences, and its exact gradient.
//!
//! Conventions (`tests/fixtures/loss/README.md`, "DMS loss"): BT.601 gray
//! `Y = 0.299 R + 0.587 G + 0.114 B` of the stored values; differences `D_t = Y_{t+1} - Y_t`;
//! non-overlapping `ph x pw` patches (16 x 16) of the frames cropped to whole patches at the
//! top-left; per patch the unnormalised forward DFT over `(t, h, w)` of its
//! `(T - 1) x ph x pw` differences;
//! `L_mag = mean |ln(1 + |F_r|) - ln(1 + |F_g|)|` and
//! `L_phase = 1 - mean Re(F_r / (|F_r| + eps) conj(F_g / (|F_g| + eps)))`, `eps = 1e-8`,
//! means over every entry of every patch.
//!
//! # Computation
//!
//! All spectral arithmetic is f64 (in f32 the round-off of spectral entries that are
//! mathematically zero, ~1e-7 max|F|, is far above `eps` and turns them into unit phasors
//! of random phase: the README measured L_phase moving by 4e-4). Both videos are real, so
//! their spectra are Hermitian (`F[-k] = conj F[k]`) and only the half with
//! `kw <= pw / 2` is computed: a real-input DFT along `w` (`pw / 2 + 1` frequencies, one
//! complex FFT of `pw / 2` per row), then complex DFTs along `h` and `t` of that half. Each
//! video is transformed on its own, so a patch whose differences are zero has an exactly
//! zero spectrum. The sums over the whole spectrum weigh each entry of the half by 2 (it
//! stands for itself and its conjugate), except in the self-conjugate planes `kw = 0` and
//! (even `pw`) `kw = pw / 2`, which hold both members of each pair: there each pair
//! `k, -k` is evaluated once with weight 2 (1 for a self-conjugate entry). The 3-D DFT is
//! three batches of 1-D rustfft transforms (plans built once in [`Spectral::new`]) along the
//! contiguous axis, with a transpose between batches.
//!
//! # Gradient
//!
//! With `G[k] = dL/dRe F[k] + i dL/dIm F[k]` for a spectrum `F = DFT(x)` of a real `x`,
//! `dL/dx = Re(DFT(conj G))`: the adjoint of a DFT is a DFT. `G` is Hermitian (the loss is
//! symmetric in `k, -k`), so `DFT(conj G)`, the unnormalised inverse DFT of `G`, is real: it
//! is computed from the half of `G` (inverse DFTs along `t` and `h`, then the inverse
//! real-output DFT along `w`, which supplies the conjugate half). Per entry, with `r = |F|`:
//! `d|F| = F / r` (0 at `F = 0`, PyTorch's subgradient), the magnitude term gives
//! `sign(ln(1+r) - ln(1+r_g)) / (1 + r) * F / r`, the phase term
//! `q G_P - q^2 Re(conj(G_P) F) F / r` with `q = 1 / (r + eps)` and `G_P = -P_g / N`.
//!
//! # Near-zero rendered spectra
//!
//! Where the rendered spectrum is (near) zero and the reference's is not — a static rendered
//! patch against a moving reference, the typical start of a fit — the phase term's gradient
//! is `-P_g / (N eps)`: about `1 / (N eps)` per entry, `1e8 / N`. It is exact (PyTorch
//! gives the same) but useless for gradient descent. Two options tame it:
//! [`SpectralConfig::eps`] (the gradient scales as `1 / eps`) and
//! [`SpectralConfig::phase_mask`] (entries where either spectrum's magnitude is below the
//! threshold contribute `S = 0` and no gradient).
//!
//! Memory: the videos are read band by band; the only temporaries are a band's gray frames
//! and a few `(T - 1) x ph x pw` buffers per worker.

use crate::entries::{entries, EntryOut, EntryParams};
use crate::error::{Input, LossError};
use crate::par;
use crate::real::Real;
use crate::real_fft::RealFft;
use crate::rows::Isa;
use crate::video::{check_grad_len, check_pair, Video};
use rustfft::num_complex::Complex;
use rustfft::{Fft, FftPlanner};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

type C64 = Complex<f64>;

/// Normalisation of the per-patch DFT.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FftNorm {
    /// Unnormalised forward DFT (`torch.fft.fftn(norm="backward")`, the default).
    #[default]
    Backward,
    /// Scaled by `1 / sqrt((T - 1) ph pw)` (`norm="ortho"`).
    Ortho,
}

/// Reduction of the magnitude term over spectral entries.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Reduction {
    /// Mean over every entry of every patch.
    #[default]
    Mean,
    /// Sum over every entry of every patch.
    Sum,
}

/// Settings of the spectral terms (each of the README's choices).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SpectralConfig {
    /// Patch size `[rows, columns]` (16 x 16).
    pub patch: [usize; 2],
    /// DFT normalisation.
    pub norm: FftNorm,
    /// Reduction of `L_mag`.
    pub mag_reduction: Reduction,
    /// `eps` of the phase normalisation `F / (|F| + eps)` (1e-8).
    pub eps: f64,
    /// Phase mask: entries where `|F_r|` or `|F_g|` (after normalisation) is below this
    /// contribute nothing to the phase sum (and no gradient); the mean still divides by
    /// every entry. `None` (the paper): no mask.
    pub phase_mask: Option<f64>,
}

impl Default for SpectralConfig {
    fn default() -> Self {
        SpectralConfig {
            patch: [16, 16],
            norm: FftNorm::Backward,
            mag_reduction: Reduction::Mean,
            eps: 1e-8,
            phase_mask: None,
        }
    }
}

impl SpectralConfig {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), LossError> {
        if self.patch[0] == 0 || self.patch[1] == 0 {
            return Err(LossError::Config(format!(
                "patch size must be positive, got {}x{}",
                self.patch[0], self.patch[1]
            )));
        }
        if !(self.eps > 0.0 && self.eps <= 1.0) {
            return Err(LossError::Config(format!(
                "phase eps must lie in (0, 1] (F / (|F| + eps) is 0/0 where a spectrum entry is 0), got {}",
                self.eps
            )));
        }
        if let Some(m) = self.phase_mask {
            if !(m >= 0.0 && m.is_finite()) {
                return Err(LossError::Config(format!(
                    "phase mask threshold must be finite and >= 0, got {m}"
                )));
            }
        }
        Ok(())
    }
}

/// The spectral terms of one evaluation (unweighted).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SpectralTerms {
    /// `L_mag`.
    pub mag: f64,
    /// `L_phase`.
    pub phase: f64,
    /// Spectral entries, `N (T - 1) ph pw`.
    pub entries: usize,
    /// Entries the phase mask removed.
    pub masked: usize,
}

/// The spectral terms for videos of one shape, with FFT plans built once.
#[derive(Clone)]
pub struct Spectral {
    cfg: SpectralConfig,
    frames: usize,
    height: usize,
    width: usize,
    fft_t: Arc<dyn Fft<f64>>,
    fft_h: Arc<dyn Fft<f64>>,
    ifft_t: Arc<dyn Fft<f64>>,
    ifft_h: Arc<dyn Fft<f64>>,
    /// Real-input DFTs along `w`.
    rfft_w: RealFft,
    scratch: usize,
    /// The instruction set of the per-entry pass.
    isa: Isa,
}

impl std::fmt::Debug for Spectral {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Spectral")
            .field("cfg", &self.cfg)
            .field("frames", &self.frames)
            .field("height", &self.height)
            .field("width", &self.width)
            .finish_non_exhaustive()
    }
}

/// Sums of one band of patches.
#[derive(Clone, Copy, Default)]
struct BandSums {
    mag: f64,
    phase: f64,
    masked: usize,
}

/// Weights of the gradient: `d L / d |.|` of the magnitude term per entry and
/// `d L / d S` of the phase term per entry.
#[derive(Clone, Copy)]
struct GradWeights {
    mag: f64,
    phase: f64,
}

impl Spectral {
    /// Plans for videos of `frames x height x width`.
    pub fn new(
        cfg: SpectralConfig,
        frames: usize,
        height: usize,
        width: usize,
    ) -> Result<Self, LossError> {
        cfg.validate()?;
        if frames < 2 {
            return Err(LossError::TooFewFrames {
                input: Input::Reference,
                frames,
                needed: 2,
                what: "the spectral loss (frame differences)",
            });
        }
        let [ph, pw] = cfg.patch;
        if height < ph || width < pw {
            return Err(LossError::SmallerThanPatch {
                input: Input::Reference,
                height,
                width,
                patch_h: ph,
                patch_w: pw,
            });
        }
        let mut planner = FftPlanner::<f64>::new();
        let fft_t = planner.plan_fft_forward(frames - 1);
        let fft_h = planner.plan_fft_forward(ph);
        let ifft_t = planner.plan_fft_inverse(frames - 1);
        let ifft_h = planner.plan_fft_inverse(ph);
        let rfft_w = RealFft::new(pw, &mut planner);
        let scratch = [&fft_t, &fft_h, &ifft_t, &ifft_h]
            .iter()
            .map(|f| f.get_inplace_scratch_len())
            .max()
            .unwrap_or(0)
            .max(rfft_w.scratch_len());
        Ok(Spectral {
            cfg,
            frames,
            height,
            width,
            fft_t,
            fft_h,
            ifft_t,
            ifft_h,
            rfft_w,
            scratch,
            isa: Isa::detect(),
        })
    }

    /// The configuration.
    pub fn config(&self) -> &SpectralConfig {
        &self.cfg
    }

    /// Number of spectral entries `N (T - 1) ph pw`.
    pub fn entries(&self) -> usize {
        let [ph, pw] = self.cfg.patch;
        (self.height / ph) * (self.width / pw) * (self.frames - 1) * ph * pw
    }

    fn check<T: Real>(&self, rendered: &Video<T>, reference: &Video<T>) -> Result<(), LossError> {
        if (reference.frames(), reference.height(), reference.width())
            != (self.frames, self.height, self.width)
        {
            return Err(LossError::Config(format!(
                "spectral plans are for {} frames of {}x{}, the reference has {} of {}x{}",
                self.frames,
                self.height,
                self.width,
                reference.frames(),
                reference.height(),
                reference.width()
            )));
        }
        check_pair(rendered, reference)
    }

    /// `L_mag` and `L_phase` of `rendered` against `reference`.
    pub fn evaluate<T: Real>(
        &self,
        rendered: &Video<T>,
        reference: &Video<T>,
    ) -> Result<SpectralTerms, LossError> {
        self.check(rendered, reference)?;
        Ok(self.run(rendered, reference, None))
    }

    /// `L_mag` and `L_phase`, adding `w_mag * dL_mag/d rendered + w_phase * dL_phase/d
    /// rendered` to `grad` (`(T, H, W, 3)`).
    pub fn evaluate_grad_into<T: Real>(
        &self,
        rendered: &Video<T>,
        reference: &Video<T>,
        w_mag: f64,
        w_phase: f64,
        grad: &mut [T],
    ) -> Result<SpectralTerms, LossError> {
        self.check(rendered, reference)?;
        check_grad_len(rendered, grad)?;
        Ok(self.run(rendered, reference, Some((w_mag, w_phase, grad))))
    }

    /// Runs only the FFTs and transposes of one evaluation (forward transforms of both
    /// videos, and with `grad` the backward transforms), on zeros, scheduled as
    /// [`Spectral::evaluate`] schedules them. For profiling the share of time in FFTs.
    pub fn transforms_only(&self, grad: bool) {
        let [ph, pw] = self.cfg.patch;
        let (nb, npw) = (self.height / ph, self.width / pw);
        par::map((0..nb).collect(), |_| {
            let mut ws = Workspace::new(self, false);
            let mut d = vec![0.0; (self.frames - 1) * ph * pw];
            for _ in 0..npw {
                self.forward(&ws.dr, &mut ws.z, &mut ws.tmp, &mut ws.scratch);
                self.forward(&ws.dg, &mut ws.zg, &mut ws.tmp, &mut ws.scratch);
                if grad {
                    self.backward_transform(&mut ws.g, &mut d, &mut ws.tmp, &mut ws.scratch);
                }
            }
        });
    }

    /// Unchecked evaluation, in parallel over bands of patch rows.
    pub(crate) fn run<T: Real>(
        &self,
        x: &Video<T>,
        y: &Video<T>,
        grad: Option<(f64, f64, &mut [T])>,
    ) -> SpectralTerms {
        let ph = self.cfg.patch[0];
        let (nb, w) = (self.height / ph, self.width);
        let entries = self.entries();
        let n = entries as f64;
        let band_len = ph * w * 3;
        let flen = x.frame_len();
        let (weights, grad) = match grad {
            Some((wm, wp, g)) => {
                let mag = match self.cfg.mag_reduction {
                    Reduction::Mean => wm / n,
                    Reduction::Sum => wm,
                };
                (
                    Some(GradWeights {
                        mag,
                        phase: -wp / n,
                    }),
                    Some(g),
                )
            }
            None => (None, None),
        };
        // Band b of the gradient: rows b*ph .. (b+1)*ph of every frame.
        let mut bands: Vec<(usize, Vec<&mut [T]>)> = (0..nb).map(|b| (b, Vec::new())).collect();
        if let Some(g) = grad {
            for frame in g.chunks_mut(flen) {
                for (b, band) in frame.chunks_mut(band_len).take(nb).enumerate() {
                    bands[b].1.push(band);
                }
            }
        }
        let with_grad = weights.is_some();
        let sums = par::map_pooled(
            bands,
            || Workspace::new(self, with_grad),
            |ws, (b, mut g)| {
                let gb = if g.is_empty() {
                    None
                } else {
                    Some((weights.expect("weights with a gradient"), &mut g[..]))
                };
                self.band(x, y, b, gb, ws)
            },
        );
        let (mut mag, mut phase, mut masked) = (0.0, 0.0, 0);
        for s in &sums {
            mag += s.mag;
            phase += s.phase;
            masked += s.masked;
        }
        SpectralTerms {
            mag: match self.cfg.mag_reduction {
                Reduction::Mean => mag / n,
                Reduction::Sum => mag,
            },
            phase: 1.0 - phase / n,
            entries,
            masked,
        }
    }

    /// One band of patches (patch row `b`), one patch at a time. The band's gray frames of
    /// both videos are read once, sequentially, into `(T, ph, W)` f64 buffers; with a
    /// gradient, the band's gray-frame gradient is accumulated likewise and added to the
    /// frames at the end (sequential access instead of one strided read per patch row).
    fn band<T: Real>(
        &self,
        x: &Video<T>,
        y: &Video<T>,
        b: usize,
        grad: Option<(GradWeights, &mut [&mut [T]])>,
        ws: &mut Workspace,
    ) -> BandSums {
        let [ph, pw] = self.cfg.patch;
        let (nt, w) = (self.frames, self.width);
        let npw = w / pw;
        if grad.is_some() {
            ws.gy.fill(0.0);
        }
        let pl = ph * pw;
        for t in 0..nt {
            let (fx, fy) = (x.frame(t), y.frame(t));
            for h in 0..ph {
                let row = (b * ph + h) * w * 3;
                for jj in 0..npw {
                    let src = row + jj * pw * 3..row + (jj + 1) * pw * 3;
                    let dst = (jj * nt + t) * pl + h * pw..(jj * nt + t) * pl + (h + 1) * pw;
                    gray_rows(&fx[src.clone()], &mut ws.yr[dst.clone()]);
                    gray_rows(&fy[src], &mut ws.yg[dst]);
                }
            }
        }
        let mut sums = BandSums::default();
        for j in 0..npw {
            self.gather(j, ws);
            self.forward(&ws.dr, &mut ws.z, &mut ws.tmp, &mut ws.scratch);
            self.forward(&ws.dg, &mut ws.zg, &mut ws.tmp, &mut ws.scratch);
            let gw = grad.as_ref().map(|(w, _)| *w);
            let s = self.entries_pass(&ws.z, &ws.zg, gw.map(|w| (w, &mut ws.g[..])), &mut ws.ev);
            sums.mag += s.mag;
            sums.phase += s.phase;
            sums.masked += s.masked;
            if grad.is_some() {
                // The gradient with respect to the patch's differences, into `dr` (read).
                self.backward_transform(&mut ws.g, &mut ws.dr, &mut ws.tmp, &mut ws.scratch);
                self.scatter(j, ws);
            }
        }
        if let Some((_, g)) = grad {
            for (t, frame) in g.iter_mut().enumerate() {
                for h in 0..ph {
                    let row = h * w * 3;
                    for jj in 0..npw {
                        let o = (jj * nt + t) * pl + h * pw;
                        let px = &mut frame[row + jj * pw * 3..row + (jj + 1) * pw * 3];
                        for (p, &v) in px.chunks_exact_mut(3).zip(&ws.gy[o..o + pw]) {
                            p[0] += T::c(0.299 * v);
                            p[1] += T::c(0.587 * v);
                            p[2] += T::c(0.114 * v);
                        }
                    }
                }
            }
        }
        sums
    }

    /// Gray frame differences of patch `j` of the band: `dr = D_rendered`,
    /// `dg = D_reference`, layout `(t, h, w)`.
    fn gather(&self, j: usize, ws: &mut Workspace) {
        let [ph, pw] = self.cfg.patch;
        let pl = ph * pw;
        let base = j * self.frames * pl;
        for t in 0..self.frames - 1 {
            let (a, c) = (base + t * pl, base + (t + 1) * pl);
            let out = t * pl..(t + 1) * pl;
            let (dr, dg) = (&mut ws.dr[out.clone()], &mut ws.dg[out]);
            let (r0, r1) = (&ws.yr[a..a + pl], &ws.yr[c..c + pl]);
            let (g0, g1) = (&ws.yg[a..a + pl], &ws.yg[c..c + pl]);
            for q in 0..pl {
                dr[q] = r1[q] - r0[q];
                dg[q] = g1[q] - g0[q];
            }
        }
    }

    /// The half spectrum of the real `(t, h, w)` differences `d` into `z`, layout
    /// `(kh, kw, kt)` with `kw <= pw / 2`.
    fn forward(&self, d: &[f64], z: &mut [C64], tmp: &mut [C64], scratch: &mut [C64]) {
        let ph = self.cfg.patch[0];
        let (td, nw) = (self.frames - 1, self.rfft_w.bins());
        let len = td * ph * nw;
        let z = &mut z[..len];
        self.rfft_w.forward(d, z, tmp, scratch); // (td, ph, nw)
        transpose(z, &mut tmp[..len], td * ph, nw); // (nw, td, ph)
        self.fft_h.process_with_scratch(&mut tmp[..len], scratch);
        transpose(&tmp[..len], z, nw * td, ph); // (ph, nw, td)
        self.fft_t.process_with_scratch(z, scratch);
    }

    /// The real `(t, h, w)` inverse DFT of the Hermitian spectrum whose half is `g` (layout
    /// `(kh, kw, kt)`, overwritten) into `d`: `Re(DFT(conj G))`, the gradient with respect
    /// to the differences.
    fn backward_transform(
        &self,
        g: &mut [C64],
        d: &mut [f64],
        tmp: &mut [C64],
        scratch: &mut [C64],
    ) {
        let ph = self.cfg.patch[0];
        let (td, nw) = (self.frames - 1, self.rfft_w.bins());
        let len = td * ph * nw;
        let g = &mut g[..len];
        self.ifft_t.process_with_scratch(g, scratch);
        transpose(g, &mut tmp[..len], ph, nw * td); // (nw, td, ph)
        self.ifft_h.process_with_scratch(&mut tmp[..len], scratch);
        transpose(&tmp[..len], g, nw, td * ph); // (td, ph, nw)
        self.rfft_w.inverse(g, d, tmp, scratch);
    }

    /// Values of every entry of the spectrum whose half is `zr` (layout `(kh, kw, kt)`,
    /// `kw <= pw / 2`); with `grad`, also the half of `G` of the rendered spectrum into `g`
    /// (same layout). The per-entry arithmetic runs lane-wise over the whole half
    /// ([`entries`]); this pass weighs the Hermitian pairs and sums in entry order.
    fn entries_pass(
        &self,
        zr: &[C64],
        zg: &[C64],
        grad: Option<(GradWeights, &mut [C64])>,
        ev: &mut EntryBufs,
    ) -> BandSums {
        let [ph, pw] = self.cfg.patch;
        let (td, nw) = (self.frames - 1, self.rfft_w.bins());
        let len = td * ph * nw;
        let scale = match self.cfg.norm {
            FftNorm::Backward => 1.0,
            FftNorm::Ortho => 1.0 / ((td * ph * pw) as f64).sqrt(),
        };
        let params = EntryParams {
            scale,
            eps: self.cfg.eps,
            mask: self.cfg.phase_mask,
        };
        let mut g = grad.map(|(w, g)| ((w.mag, w.phase), &mut g[..len]));
        entries(
            self.isa,
            &zr[..len],
            &zg[..len],
            params,
            EntryOut {
                abs_dm: &mut ev.abs_dm[..len],
                cos: &mut ev.cos[..len],
                keep: &mut ev.keep[..len],
                grad: g.as_mut().map(|(w, g)| (*w, &mut **g)),
            },
        );
        let (abs_dm, cos, keep) = (&ev.abs_dm[..len], &ev.cos[..len], &ev.keep[..len]);
        let mut sums = BandSums::default();
        let mut kept = 0.0;
        for kh in 0..ph {
            let mh = (ph - kh) % ph;
            for kw in 0..nw {
                let row = (kh * nw + kw) * td;
                // The planes kw = 0 and kw = pw / 2 hold their own conjugates (kw = -kw mod
                // pw); every other entry stands for itself and its conjugate in the half
                // that is not stored.
                if kw != 0 && 2 * kw != pw {
                    for e in row..row + td {
                        sums.mag += 2.0 * abs_dm[e];
                        sums.phase += 2.0 * cos[e];
                        kept += 2.0 * keep[e];
                    }
                    continue;
                }
                let mrow = (mh * nw + kw) * td;
                for kt in 0..td {
                    let e = row + kt;
                    let m = mrow + if kt == 0 { 0 } else { td - kt };
                    if m < e {
                        continue;
                    }
                    let weight = if m == e { 1.0 } else { 2.0 };
                    sums.mag += weight * abs_dm[e];
                    sums.phase += weight * cos[e];
                    kept += weight * keep[e];
                    if let Some((_, g)) = g.as_mut() {
                        g[m] = g[e].conj();
                    }
                }
            }
        }
        // Every entry of the full spectrum counted once: `kept` of them kept.
        sums.masked = td * ph * pw - kept as usize;
        sums
    }

    /// Adds the gradient of patch `j` with respect to its differences (in `dr`, layout
    /// `(t, h, w)`) to the band's gray-frame gradient (`dL/dY_t = g_{t-1} - g_t`).
    fn scatter(&self, j: usize, ws: &mut Workspace) {
        let [ph, pw] = self.cfg.patch;
        let (nt, td) = (self.frames, self.frames - 1);
        let pl = ph * pw;
        for t in 0..nt {
            let o = (j * nt + t) * pl;
            let gy = &mut ws.gy[o..o + pl];
            if t > 0 {
                for (y, &d) in gy.iter_mut().zip(&ws.dr[(t - 1) * pl..t * pl]) {
                    *y += d;
                }
            }
            if t < td {
                for (y, &d) in gy.iter_mut().zip(&ws.dr[t * pl..(t + 1) * pl]) {
                    *y -= d;
                }
            }
        }
    }
}

impl Workspace {
    /// Buffers for one worker.
    fn new(sp: &Spectral, with_grad: bool) -> Self {
        let [ph, pw] = sp.cfg.patch;
        let td = sp.frames - 1;
        let half = td * ph * sp.rfft_w.bins();
        let n = sp.frames * ph * (sp.width / pw) * pw;
        Workspace {
            yr: vec![0.0; n],
            yg: vec![0.0; n],
            gy: vec![0.0; if with_grad { n } else { 0 }],
            dr: vec![0.0; td * ph * pw],
            dg: vec![0.0; td * ph * pw],
            z: vec![C64::default(); half],
            zg: vec![C64::default(); half],
            tmp: vec![C64::default(); half.max(td * ph * sp.rfft_w.buffer_len())],
            g: vec![C64::default(); half],
            scratch: vec![C64::default(); sp.scratch],
            ev: EntryBufs {
                abs_dm: vec![0.0; half],
                cos: vec![0.0; half],
                keep: vec![0.0; half],
            },
        }
    }
}

/// BT.601 gray of interleaved RGB rows, in f64.
fn gray_rows<T: Real>(rgb: &[T], out: &mut [f64]) {
    for (o, p) in out.iter_mut().zip(rgb.chunks_exact(3)) {
        *o = 0.299 * p[0].f64() + 0.587 * p[1].f64() + 0.114 * p[2].f64();
    }
}

/// Per-worker buffers.
struct Workspace {
    /// The band's gray frames, patch-major `(W / pw, T, ph, pw)`: rendered, reference.
    yr: Vec<f64>,
    yg: Vec<f64>,
    /// The band's gray-frame gradient, same layout.
    gy: Vec<f64>,
    /// One patch's differences `(T - 1, ph, pw)`: rendered (then the gradient with respect
    /// to them), reference.
    dr: Vec<f64>,
    dg: Vec<f64>,
    /// Half spectra `(ph, pw / 2 + 1, T - 1)`: rendered, reference, `G`.
    z: Vec<C64>,
    zg: Vec<C64>,
    g: Vec<C64>,
    /// Transposes and the real-input DFTs' work buffer.
    tmp: Vec<C64>,
    scratch: Vec<C64>,
    /// The per-entry values of one patch's half spectrum.
    ev: EntryBufs,
}

/// Per-entry values of one half spectrum (see [`entries`]).
struct EntryBufs {
    abs_dm: Vec<f64>,
    cos: Vec<f64>,
    keep: Vec<f64>,
}

/// Transposes the `rows x cols` matrix `src` into `dst` (`cols x rows`).
fn transpose(src: &[C64], dst: &mut [C64], rows: usize, cols: usize) {
    for r in 0..rows {
        let s = &src[r * cols..(r + 1) * cols];
        for (c, &v) in s.iter().enumerate() {
            dst[c * rows + r] = v;
        }
    }
}
