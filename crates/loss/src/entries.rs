//! The spectral terms' per-entry arithmetic over a patch's half spectrum, lane-wise.
//!
//! For every entry `e` of the rendered and reference half spectra (`zr`, `zg`, already in
//! the caller's layout) this computes, with `F = z s` (`s` the DFT normalisation) and
//! `r = |F|`:
//!
//! * `|dm|`, `dm = ln(1 + r_r) - ln(1 + r_g)`, evaluated as `ln_1p((r_r - r_g) / (1 + r_g))`
//!   (exactly 0 when `r_r = r_g`);
//! * the phase agreement `Re(F_r conj F_g) / ((r_r + eps) (r_g + eps))`, 0 where the phase
//!   mask drops the entry, and the mask itself (1 kept, 0 dropped);
//! * with gradient weights, `G[e]` of the rendered spectrum: the magnitude term's
//!   `w_mag sign(dm) / (1 + r_r) F_r / r_r` plus the phase term's
//!   `q G_P - q^2 Re(conj(G_P) F_r) F_r / r_r` (`q = 1 / (r_r + eps)`,
//!   `G_P = w_phase F_g / (r_g + eps)`), times `s`; `F_r / r_r` is 0 where `r_r = 0`.
//!
//! The loop body has no branch (selects only, and a polynomial `ln_1p`), so LLVM vectorises
//! it over entries; it is instantiated for the target's baseline and, chosen at runtime,
//! for AVX2 (four f64 lanes). Rust never contracts `a * b + c` into a fused multiply-add,
//! so both instantiations give the same bits. The weighting of the Hermitian pairs and the
//! sums stay with the caller, in entry order.

use crate::rows::Isa;
use rustfft::num_complex::Complex;

type C64 = Complex<f64>;

/// What the per-entry pass needs besides the spectra.
#[derive(Clone, Copy, Debug)]
pub(crate) struct EntryParams {
    /// DFT normalisation factor `s`.
    pub scale: f64,
    /// `eps` of the phase normalisation.
    pub eps: f64,
    /// Phase mask threshold (`None`: keep every entry).
    pub mask: Option<f64>,
}

/// Per-entry outputs; each slice is at least as long as the spectra.
pub(crate) struct EntryOut<'a> {
    /// `|dm|`.
    pub abs_dm: &'a mut [f64],
    /// The phase agreement, 0 where masked.
    pub cos: &'a mut [f64],
    /// 1 where the phase term keeps the entry, 0 where the mask drops it.
    pub keep: &'a mut [f64],
    /// With `(w_mag, w_phase)`: `G` of the rendered spectrum per entry.
    pub grad: Option<((f64, f64), &'a mut [C64])>,
}

/// Fills `out` for every entry of `zr` and `zg` (same length).
pub(crate) fn entries(isa: Isa, zr: &[C64], zg: &[C64], p: EntryParams, out: EntryOut<'_>) {
    debug_assert_eq!(zr.len(), zg.len());
    match isa {
        Isa::Generic => entries_impl(zr, zg, p, out),
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Isa::Avx2Fma` is only produced by `Isa::detect` after checking that the
        // CPU supports AVX2 and FMA.
        Isa::Avx2Fma => unsafe { entries_avx2(zr, zg, p, out) },
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn entries_avx2(zr: &[C64], zg: &[C64], p: EntryParams, out: EntryOut<'_>) {
    entries_impl(zr, zg, p, out)
}

#[inline(always)]
fn entries_impl(zr: &[C64], zg: &[C64], p: EntryParams, out: EntryOut<'_>) {
    let n = zr.len();
    let (zg, abs_dm, cos, keep) = (
        &zg[..n],
        &mut out.abs_dm[..n],
        &mut out.cos[..n],
        &mut out.keep[..n],
    );
    // Without a mask every entry is kept: a threshold of -1 keeps all (magnitudes are >= 0).
    let t = p.mask.unwrap_or(-1.0);
    let (s, eps) = (p.scale, p.eps);
    match out.grad {
        None => {
            for e in 0..n {
                let v = values(zr[e], zg[e], s, eps, t);
                abs_dm[e] = v.dm.abs();
                cos[e] = v.cos;
                keep[e] = v.keep;
            }
        }
        Some(((wm, wp), g)) => {
            let g = &mut g[..n];
            for e in 0..n {
                let v = values(zr[e], zg[e], s, eps, t);
                abs_dm[e] = v.dm.abs();
                cos[e] = v.cos;
                keep[e] = v.keep;
                let sign = f64::from(u8::from(v.dm > 0.0)) - f64::from(u8::from(v.dm < 0.0));
                let r_inv = if v.rr > 0.0 { 1.0 / v.rr } else { 0.0 };
                // G_P = w_phase P_g; its projection on F_r.
                let gp = (v.fg * v.qg) * wp;
                let proj = gp.re * v.fr.re + gp.im * v.fr.im;
                let kq = v.keep * v.qr;
                let a = wm * sign * r_inv / (1.0 + v.rr) - kq * v.qr * proj * r_inv;
                g[e] = (v.fr * a + gp * kq) * s;
            }
        }
    }
}

/// One entry's intermediate values.
struct Values {
    fr: C64,
    fg: C64,
    rr: f64,
    qr: f64,
    qg: f64,
    dm: f64,
    cos: f64,
    keep: f64,
}

#[inline(always)]
fn values(zr: C64, zg: C64, s: f64, eps: f64, t: f64) -> Values {
    let (fr, fg) = (zr * s, zg * s);
    let rr = (fr.re * fr.re + fr.im * fr.im).sqrt();
    let rg = (fg.re * fg.re + fg.im * fg.im).sqrt();
    let dm = ln_1p((rr - rg) / (1.0 + rg));
    let (qr, qg) = (1.0 / (rr + eps), 1.0 / (rg + eps));
    let keep = if rr >= t && rg >= t { 1.0 } else { 0.0 };
    let cos = keep * ((fr.re * qr) * (fg.re * qg) + (fr.im * qr) * (fg.im * qg));
    Values {
        fr,
        fg,
        rr,
        qr,
        qg,
        dm,
        cos,
        keep,
    }
}

/// `ln(1 + x)` for `x > -1` with `1 + x` a normal number, without branches: `ln(u) x / (u -
/// 1)` with `u = 1 + x` (which cancels the rounding of `u`), and `x` itself where `u`
/// rounds to 1. Accurate to a few ulp.
#[inline(always)]
pub(crate) fn ln_1p(x: f64) -> f64 {
    let u = 1.0 + x;
    let d = u - 1.0;
    if d == 0.0 {
        x
    } else {
        ln_normal(u) * (x / d)
    }
}

/// The natural logarithm of a positive normal `u`, branch-free: `u = 2^k m` with `m` in
/// `[sqrt(1/2), sqrt(2))`, `ln m = f - f^2 / 2 + s (f^2 / 2 + R(s^2))`, `f = m - 1`,
/// `s = f / (2 + f)`, `R` the minimax polynomial of the classic freely distributable
/// implementation (error below 1 ulp before the final rounding).
#[inline(always)]
fn ln_normal(u: f64) -> f64 {
    const LN2_HI: f64 = 0.693_147_180_369_123_8;
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    const LG1: f64 = 0.666_666_666_666_673_5;
    const LG2: f64 = 0.399_999_999_994_094_2;
    const LG3: f64 = 0.285_714_287_436_623_9;
    const LG4: f64 = 0.222_221_984_321_497_84;
    const LG5: f64 = 0.181_835_721_616_180_5;
    const LG6: f64 = 0.153_138_376_992_093_73;
    const LG7: f64 = 0.147_981_986_051_165_86;
    let bits = u.to_bits();
    // The mantissa with the exponent of 1 or of 1/2, whichever puts it in
    // [sqrt(1/2), sqrt(2)): mantissas above sqrt(2) (0x6a09e... of the fraction) take 1/2.
    let frac = bits & 0x000f_ffff_ffff_ffff;
    let high = frac > 0x0006_a09e_667f_3bcc;
    let m = f64::from_bits(frac | ((0x3ff - u64::from(high)) << 52));
    // The biased exponent as a double, exactly (2^52 + e read as a double, less 2^52).
    let biased = f64::from_bits((bits >> 52) | 0x4330_0000_0000_0000) - 4_503_599_627_370_496.0;
    let k = biased - 1023.0 + if high { 1.0 } else { 0.0 };
    let f = m - 1.0;
    let s = f / (2.0 + f);
    let z = s * s;
    let w = z * z;
    let t1 = w * (LG2 + w * (LG4 + w * LG6));
    let t2 = z * (LG1 + w * (LG3 + w * (LG5 + w * LG7)));
    let r = t2 + t1;
    let hfsq = 0.5 * f * f;
    k * LN2_HI - ((hfsq - (s * (hfsq + r) + k * LN2_LO)) - f)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ln_1p_matches_the_standard_library() {
        let mut worst = 0.0f64;
        let mut x = -0.999_999;
        // Values from just above -1 to 1e12, dense near 0 (both signs) where cancellation bites.
        let mut xs: Vec<f64> = Vec::new();
        while x < 1e12 {
            xs.push(x);
            x = if x < 0.0 { x * 0.93 } else { x * 1.07 + 1e-300 };
            if x > -1e-300 && x < 0.0 {
                x = 1e-300;
            }
        }
        xs.extend([0.0, 1e-17, -1e-17, 2.2e-16, -1.1e-16, 0.5, -0.5, 1.0, 3.0]);
        for &x in &xs {
            let (a, b) = (ln_1p(x), x.ln_1p());
            if b == 0.0 {
                assert_eq!(a, 0.0, "x = {x}");
                continue;
            }
            assert_eq!(a.signum(), b.signum(), "x = {x}");
            worst = worst.max(((a - b) / b).abs());
        }
        assert!(worst < 4.0 * f64::EPSILON, "worst relative error {worst:e}");
    }

    #[test]
    fn both_builds_give_the_same_bits() {
        let zr: Vec<C64> = (0..37)
            .map(|i| C64::new((i as f64 * 0.7).sin() * 3.0, (i as f64 * 1.3).cos()))
            .collect();
        let mut zg: Vec<C64> = (0..37)
            .map(|i| C64::new((i as f64 * 0.4).cos(), (i as f64 * 0.9).sin() * 2.0))
            .collect();
        zg[3] = zr[3];
        zg[5] = C64::default();
        let run = |isa| {
            let n = zr.len();
            let (mut a, mut c, mut k) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
            let mut g = vec![C64::default(); n];
            let p = EntryParams {
                scale: 0.5,
                eps: 1e-8,
                mask: Some(0.1),
            };
            entries(
                isa,
                &zr,
                &zg,
                p,
                EntryOut {
                    abs_dm: &mut a,
                    cos: &mut c,
                    keep: &mut k,
                    grad: Some(((0.3, -0.2), &mut g)),
                },
            );
            (a, c, k, g)
        };
        let generic = run(Isa::Generic);
        assert_eq!(generic.0[3], 0.0, "equal magnitudes give exactly 0");
        assert_eq!(generic.2[5], 0.0, "a zero reference entry is masked");
        assert_eq!(generic, run(Isa::detect()));
    }
}
