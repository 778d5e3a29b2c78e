//! The MP4 muxer: one H.264 video track, `moov` before `mdat` ("fast start", so a browser can
//! play the file while it downloads), all samples in one chunk, 32-bit chunk offsets unless the
//! file needs 64.

/// What the muxer needs of an encoded video.
pub(crate) struct Stream<'a> {
    /// Coded width and height (even).
    pub width: u16,
    pub height: u16,
    /// The sample entry's code (`avc1`).
    pub codec: [u8; 4],
    /// Ticks per second, and the duration of each frame in ticks.
    pub timescale: u32,
    pub frame_ticks: u32,
    /// `avcC` fields: profile, compatibility flags, level, parameter sets.
    pub profile: u8,
    pub compat: u8,
    pub level: u8,
    pub sps: &'a [u8],
    pub pps: &'a [u8],
    /// Length-prefixed (4-byte) samples, and which are sync (IDR) frames.
    pub samples: &'a [Vec<u8>],
    pub sync: &'a [bool],
}

struct W(Vec<u8>);

impl W {
    fn u8(&mut self, v: u8) -> &mut Self {
        self.0.push(v);
        self
    }
    fn u16(&mut self, v: u16) -> &mut Self {
        self.0.extend(v.to_be_bytes());
        self
    }
    fn u32(&mut self, v: u32) -> &mut Self {
        self.0.extend(v.to_be_bytes());
        self
    }
    fn u64(&mut self, v: u64) -> &mut Self {
        self.0.extend(v.to_be_bytes());
        self
    }
    fn bytes(&mut self, b: &[u8]) -> &mut Self {
        self.0.extend_from_slice(b);
        self
    }
    fn zeros(&mut self, n: usize) -> &mut Self {
        self.0.resize(self.0.len() + n, 0);
        self
    }
    /// A box: its payload written by `f`, the size patched in afterwards.
    fn boxed(&mut self, kind: &[u8; 4], f: impl FnOnce(&mut W)) -> &mut Self {
        let start = self.0.len();
        self.u32(0).bytes(kind);
        f(self);
        let size = (self.0.len() - start) as u32;
        self.0[start..start + 4].copy_from_slice(&size.to_be_bytes());
        self
    }
    /// A full box (version 0, `flags`).
    fn full(&mut self, kind: &[u8; 4], flags: u32, f: impl FnOnce(&mut W)) -> &mut Self {
        self.boxed(kind, |w| {
            w.u32(flags);
            f(w)
        })
    }
    fn matrix(&mut self) -> &mut Self {
        for v in [0x0001_0000u32, 0, 0, 0, 0x0001_0000, 0, 0, 0, 0x4000_0000] {
            self.u32(v);
        }
        self
    }
}

fn ftyp() -> Vec<u8> {
    let mut w = W(Vec::new());
    w.boxed(b"ftyp", |w| {
        w.bytes(b"isom").u32(0x200);
        for b in [b"isom", b"iso2", b"avc1", b"mp41"] {
            w.bytes(b);
        }
    });
    w.0
}

fn moov(s: &Stream, mdat_payload_at: u64, co64: bool) -> Vec<u8> {
    let n = s.samples.len() as u32;
    let duration = u64::from(n) * u64::from(s.frame_ticks);
    // Movie time in milliseconds.
    let movie_ms = (duration as f64 * 1000.0 / s.timescale as f64).round() as u32;
    let mut w = W(Vec::new());
    w.boxed(b"moov", |w| {
        w.full(b"mvhd", 0, |w| {
            w.u32(0).u32(0).u32(1000).u32(movie_ms);
            w.u32(0x0001_0000)
                .u16(0x0100)
                .zeros(10)
                .matrix()
                .zeros(24)
                .u32(2);
        });
        w.boxed(b"trak", |w| {
            w.full(b"tkhd", 3, |w| {
                w.u32(0).u32(0).u32(1).u32(0).u32(movie_ms);
                w.zeros(8).u16(0).u16(0).u16(0).u16(0).matrix();
                w.u32(u32::from(s.width) << 16)
                    .u32(u32::from(s.height) << 16);
            });
            w.boxed(b"mdia", |w| {
                w.full(b"mdhd", 0, |w| {
                    // Language 'und' packed as three 5-bit letters.
                    w.u32(0).u32(0).u32(s.timescale).u32(duration as u32);
                    w.u16(0x55c4).u16(0);
                });
                w.full(b"hdlr", 0, |w| {
                    w.u32(0).bytes(b"vide").zeros(12).bytes(b"VideoHandler\0");
                });
                w.boxed(b"minf", |w| {
                    w.full(b"vmhd", 1, |w| {
                        w.zeros(8);
                    });
                    w.boxed(b"dinf", |w| {
                        w.full(b"dref", 0, |w| {
                            w.u32(1).full(b"url ", 1, |_| {});
                        });
                    });
                    w.boxed(b"stbl", |w| stbl(w, s, mdat_payload_at, co64));
                });
            });
        });
    });
    w.0
}

fn stbl(w: &mut W, s: &Stream, first_sample_at: u64, co64: bool) {
    let n = s.samples.len() as u32;
    w.full(b"stsd", 0, |w| {
        w.u32(1).boxed(&s.codec, |w| {
            w.zeros(6).u16(1).zeros(16).u16(s.width).u16(s.height);
            w.u32(0x0048_0000).u32(0x0048_0000).u32(0).u16(1);
            let mut name = [0u8; 32];
            let label = b"resonance4d H.264";
            name[0] = label.len() as u8;
            name[1..=label.len()].copy_from_slice(label);
            w.bytes(&name).u16(0x0018).u16(0xffff);
            w.boxed(b"avcC", |w| {
                w.u8(1).u8(s.profile).u8(s.compat).u8(s.level);
                w.u8(0xfc | 3)
                    .u8(0xe0 | 1)
                    .u16(s.sps.len() as u16)
                    .bytes(s.sps);
                w.u8(1).u16(s.pps.len() as u16).bytes(s.pps);
            });
        });
    });
    w.full(b"stts", 0, |w| {
        w.u32(1).u32(n).u32(s.frame_ticks);
    });
    w.full(b"stss", 0, |w| {
        let sync: Vec<u32> = (0..n)
            .filter(|&i| s.sync[i as usize])
            .map(|i| i + 1)
            .collect();
        w.u32(sync.len() as u32);
        for i in sync {
            w.u32(i);
        }
    });
    w.full(b"stsc", 0, |w| {
        w.u32(1).u32(1).u32(n).u32(1);
    });
    w.full(b"stsz", 0, |w| {
        w.u32(0).u32(n);
        for smp in s.samples {
            w.u32(smp.len() as u32);
        }
    });
    if co64 {
        w.full(b"co64", 0, |w| {
            w.u32(1).u64(first_sample_at);
        });
    } else {
        w.full(b"stco", 0, |w| {
            w.u32(1).u32(first_sample_at as u32);
        });
    }
}

/// The whole file: `ftyp`, `moov`, `mdat`.
pub(crate) fn file(s: &Stream) -> Vec<u8> {
    let payload: u64 = s.samples.iter().map(|v| v.len() as u64).sum();
    let ftyp = ftyp();
    // The moov's size does not depend on the offset's value, only on its width.
    let large_mdat = payload + 8 > u64::from(u32::MAX);
    let probe = moov(s, 0, false);
    let mdat_header = if large_mdat { 16 } else { 8 };
    let at = (ftyp.len() + probe.len()) as u64 + mdat_header;
    let co64 = at + payload > u64::from(u32::MAX);
    let moov = moov(s, at + if co64 { 4 } else { 0 }, co64);
    let mut out = Vec::with_capacity((ftyp.len() + moov.len()) + payload as usize + 16);
    out.extend(ftyp);
    out.extend(moov);
    if large_mdat {
        out.extend(1u32.to_be_bytes());
        out.extend(b"mdat");
        out.extend((payload + 16).to_be_bytes());
    } else {
        out.extend(((payload + 8) as u32).to_be_bytes());
        out.extend(b"mdat");
    }
    for smp in s.samples {
        out.extend_from_slice(smp);
    }
    out
}
