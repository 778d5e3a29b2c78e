//! RGB <-> YUV 4:2:0 (I420), the conversion every MP4 read and write goes through.
//!
//! Matrix: ITU-R BT.601, limited ("TV") range: `Y = 16 + 219 Y'`, `Cb = 128 + 224 (B - Y') /
//! 1.772`, `Cr = 128 + 224 (R - Y') / 1.402` with `Y' = 0.299 R + 0.587 G + 0.114 B`, and its
//! exact inverse. This is what a browser and ffmpeg assume for an H.264 stream that does not say
//! otherwise (the writer's streams do not); a file recorded as BT.709 (most HD cameras) is read
//! with the BT.601 matrix too, which shifts saturated colours by a few percent.
//!
//! Chroma: writing averages each 2 x 2 block; reading gives each pixel the chroma sample of its
//! block (no interpolation), as ffmpeg's `yuv420p -> rgb24` conversion does (and so decord,
//! through which PhysDreamer and PhysFlow read their videos): a decoded frame matches ffmpeg's
//! decode to within a level or two (48.5 dB PSNR on tests/video/ffmpeg_fixtures.rs' High-profile clip). Decoded values are
//! rounded to 8 bits (`k / 255`).

use rayon::prelude::*;

const KR: f32 = 0.299;
const KB: f32 = 0.114;
const KG: f32 = 1.0 - KR - KB;

/// One I420 frame: a full-size luma plane and half-size chroma planes (sides rounded up).
#[derive(Clone, Debug, PartialEq)]
pub struct I420 {
    /// Width in pixels (even).
    pub width: usize,
    /// Height in pixels (even).
    pub height: usize,
    /// `Y`, `U`, `V` planes, contiguous: `width * height + 2 * (width / 2) * (height / 2)` bytes.
    pub data: Vec<u8>,
}

fn q(x: f32) -> u8 {
    (x + 0.5).clamp(0.0, 255.0) as u8
}

/// Converts an `h x w` RGB frame (`[0, 1]`, row-major, 3 values per pixel) to I420. An odd side
/// is padded to even by repeating the last column or row.
pub fn rgb_to_i420(rgb: &[f32], w: usize, h: usize) -> I420 {
    rgb_to_i420_padded(rgb, w, h, w + (w & 1), h + (h & 1))
}

/// As [`rgb_to_i420`], padded (last column and row repeated) to `we x he` (even, at least
/// `w x h`).
pub fn rgb_to_i420_padded(rgb: &[f32], w: usize, h: usize, we: usize, he: usize) -> I420 {
    assert_eq!(rgb.len(), w * h * 3, "frame size");
    assert!(
        we >= w && he >= h && we % 2 == 0 && he % 2 == 0,
        "padded size"
    );
    let (cw, ch) = (we / 2, he / 2);
    let mut data = vec![0u8; we * he + 2 * cw * ch];
    let (yp, uv) = data.split_at_mut(we * he);
    let (up, vp) = uv.split_at_mut(cw * ch);
    let px = |x: usize, y: usize| {
        let i = (y.min(h - 1) * w + x.min(w - 1)) * 3;
        let c = |k: usize| rgb[i + k].clamp(0.0, 1.0);
        (c(0), c(1), c(2))
    };
    yp.par_chunks_mut(we).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            let (r, g, b) = px(x, y);
            *o = q(16.0 + 219.0 * (KR * r + KG * g + KB * b));
        }
    });
    up.par_chunks_mut(cw)
        .zip(vp.par_chunks_mut(cw))
        .enumerate()
        .for_each(|(j, (ur, vr))| {
            for i in 0..cw {
                let (mut r, mut g, mut b) = (0.0, 0.0, 0.0);
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let p = px(2 * i + dx, 2 * j + dy);
                    r += p.0;
                    g += p.1;
                    b += p.2;
                }
                let (r, g, b) = (r / 4.0, g / 4.0, b / 4.0);
                let yl = KR * r + KG * g + KB * b;
                ur[i] = q(128.0 + 224.0 * (b - yl) / (2.0 * (1.0 - KB)));
                vr[i] = q(128.0 + 224.0 * (r - yl) / (2.0 * (1.0 - KR)));
            }
        });
    I420 {
        width: we,
        height: he,
        data,
    }
}

/// Planes of a decoded frame, as the decoder lays them out (rows may be padded).
pub struct Planes<'a> {
    /// Luma.
    pub y: &'a [u8],
    /// Cb.
    pub u: &'a [u8],
    /// Cr.
    pub v: &'a [u8],
    /// Row strides of `y`, `u`, `v` in bytes.
    pub strides: (usize, usize, usize),
    /// Width and height in pixels.
    pub size: (usize, usize),
}

/// BT.601 limited-range YUV -> 8-bit RGB in 16.16 fixed point (the float formulas of the
/// module docs times 255, rounded to 1/65536): `C = Y - 16`, `D = U - 128`, `E = V - 128`,
/// `R = 1.164383 C + 1.596027 E`, `G = 1.164383 C - 0.391762 D - 0.812968 E`,
/// `B = 1.164383 C + 2.017232 D`.
const FY: i32 = 76_309;
const FRV: i32 = 104_597;
const FGU: i32 = 25_675;
const FGV: i32 = 53_279;
const FBU: i32 = 132_201;

#[inline(always)]
fn clip8(x: i32) -> u8 {
    ((x + 32_768) >> 16).clamp(0, 255) as u8
}

/// Converts decoded planes to 8-bit RGB into `out` (row-major, 3 bytes per pixel; length
/// `width * height * 3`), rows in parallel.
pub fn i420_to_rgb8(p: &Planes, out: &mut [u8]) {
    let (w, h) = p.size;
    assert_eq!(out.len(), w * h * 3, "output size");
    out.par_chunks_mut(w * 3)
        .enumerate()
        .for_each(|(y, row)| i420_row(&row_planes(p, y), row));
}

/// The planes of row `y` alone.
fn row_planes<'a>(p: &Planes<'a>, y: usize) -> Planes<'a> {
    Planes {
        y: &p.y[y * p.strides.0..],
        u: &p.u[(y / 2) * p.strides.1..],
        v: &p.v[(y / 2) * p.strides.2..],
        strides: (0, 0, 0),
        size: (p.size.0, 1),
    }
}

/// `k / 255` for every byte `k`.
pub fn byte_to_unit() -> &'static [f32; 256] {
    static LUT: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    LUT.get_or_init(|| std::array::from_fn(|k| k as f32 / 255.0))
}

/// Converts decoded planes to RGB in `[0, 1]` (row-major, 3 values per pixel; length
/// `width * height * 3`): [`i420_to_rgb8`]'s bytes `k` as `k / 255`, so a decoded video is
/// stored as compactly as PNG frames.
pub fn i420_to_rgb(p: &Planes, out: &mut [f32]) {
    let (w, h) = p.size;
    assert_eq!(out.len(), w * h * 3, "output size");
    let lut = byte_to_unit();
    out.par_chunks_mut(w * 3).enumerate().for_each(|(y, row)| {
        let mut bytes = vec![0u8; w * 3];
        i420_row(&row_planes(p, y), &mut bytes);
        for (o, &b) in row.iter_mut().zip(&bytes) {
            *o = lut[b as usize];
        }
    });
}

/// 16 pixels (8 chroma samples): planar arithmetic the compiler vectorises, then interleaved.
#[inline(always)]
fn block16(y: &[u8], u: &[u8], v: &[u8], o: &mut [u8]) {
    let (y, u, v) = (&y[..16], &u[..8], &v[..8]);
    let o = &mut o[..48];
    let mut rgb = [[0u8; 16]; 3];
    for k in 0..16 {
        let c = FY * (i32::from(y[k]) - 16);
        let d = i32::from(u[k / 2]) - 128;
        let e = i32::from(v[k / 2]) - 128;
        rgb[0][k] = clip8(c + FRV * e);
        rgb[1][k] = clip8(c - FGU * d - FGV * e);
        rgb[2][k] = clip8(c + FBU * d);
    }
    for k in 0..16 {
        o[3 * k] = rgb[0][k];
        o[3 * k + 1] = rgb[1][k];
        o[3 * k + 2] = rgb[2][k];
    }
}

/// One pixel.
#[inline(always)]
fn pixel(y: u8, u: u8, v: u8, o: &mut [u8]) {
    let c = FY * (i32::from(y) - 16);
    let (d, e) = (i32::from(u) - 128, i32::from(v) - 128);
    o[0] = clip8(c + FRV * e);
    o[1] = clip8(c - FGU * d - FGV * e);
    o[2] = clip8(c + FBU * d);
}

#[inline(always)]
fn row_body(p: &Planes, o: &mut [u8]) {
    let w = p.size.0;
    let blocks = w / 16;
    for i in 0..blocks {
        block16(
            &p.y[16 * i..],
            &p.u[8 * i..],
            &p.v[8 * i..],
            &mut o[48 * i..],
        );
    }
    for x in 16 * blocks..w {
        pixel(p.y[x], p.u[x / 2], p.v[x / 2], &mut o[3 * x..]);
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn row_avx2(p: &Planes, o: &mut [u8]) {
    row_body(p, o)
}

/// One row (`p.size.1 == 1`, planes starting at the row) without the parallel split: blocks of
/// 16 pixels in vector registers (AVX2 where the CPU has it, checked at run time).
fn i420_row(p: &Planes, o: &mut [u8]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        return unsafe { row_avx2(p, o) };
    }
    row_body(p, o)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn planes(f: &I420) -> Planes<'_> {
        let (w, h) = (f.width, f.height);
        let (y, uv) = f.data.split_at(w * h);
        let (u, v) = uv.split_at(w / 2 * (h / 2));
        Planes {
            y,
            u,
            v,
            strides: (w, w / 2, w / 2),
            size: (w, h),
        }
    }

    #[test]
    fn flat_colours_round_trip_to_a_quantisation_step() {
        for c in [
            [0.0, 0.0, 0.0],
            [1.0, 1.0, 1.0],
            [0.8, 0.2, 0.4],
            [0.1, 0.9, 0.3],
        ] {
            let rgb: Vec<f32> = (0..16).flat_map(|_| c).collect();
            let f = rgb_to_i420(&rgb, 4, 4);
            let mut back = vec![0f32; 48];
            i420_to_rgb(&planes(&f), &mut back);
            for (a, b) in rgb.iter().zip(&back) {
                assert!(
                    (a - b).abs() < 1.5 / 219.0 + 1.5 / 224.0 * 1.8,
                    "{a} vs {b}"
                );
            }
        }
        // Black and white are exactly the range's ends.
        let f = rgb_to_i420(&[1.0; 12], 2, 2);
        assert_eq!(&f.data[..4], &[235; 4]);
        assert_eq!(&f.data[4..], &[128, 128]);
    }

    #[test]
    fn odd_sides_are_padded_by_repetition() {
        let rgb: Vec<f32> = (0..3 * 3 * 3).map(|i| (i % 7) as f32 / 7.0).collect();
        let f = rgb_to_i420(&rgb, 3, 3);
        assert_eq!((f.width, f.height), (4, 4));
        assert_eq!(f.data[3], f.data[2]); // last column repeated
        assert_eq!(&f.data[12..16], &f.data[8..12]); // last row repeated
    }
}
