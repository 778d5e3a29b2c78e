//! A mutation fuzzer for every file parser, on the stable toolchain and the standard library
//! only: seeds from the repository's fixtures plus small synthetic files, mutated by
//! bit flips, interesting bytes, inserted huge/negative/non-finite numbers, deletions,
//! duplications and truncation; every parser must answer each input with `Ok` or a typed
//! error — never a panic, never a single allocation above 256 MiB, never a hang.
//!
//! `R4D_FUZZ_EXECS` sets the executions per parser (default 20 000: seconds in CI);
//! `R4D_FUZZ_SEED` the seed; `R4D_FUZZ_ONLY=ply,colmap` runs only the named parsers. A failing input is written to `target/fuzz-failures/` and the
//! test fails naming it; keep it under `tests/fixtures/fuzz/<parser>/` and it is replayed by
//! every run as a regression case.

use std::alloc::{GlobalAlloc, Layout, System};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// Tracks the largest single allocation since the last reset.
struct Track;

static LARGEST: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Track {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        LARGEST.fetch_max(l.size(), Ordering::Relaxed);
        // Refuse outright what no parser may ask for (the test then reports it).
        if l.size() > 1 << 32 {
            return std::ptr::null_mut();
        }
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, new: usize) -> *mut u8 {
        LARGEST.fetch_max(new, Ordering::Relaxed);
        if new > 1 << 32 {
            return std::ptr::null_mut();
        }
        unsafe { System.realloc(p, l, new) }
    }
}

#[global_allocator]
static ALLOC: Track = Track;

/// The most one allocation may take while parsing a hostile input.
const MAX_ALLOCATION: usize = 256 << 20;
/// Slower than this is a hang (a generous bound: parsing these inputs takes microseconds).
const HANG: Duration = Duration::from_secs(10);

/// xorshift64*.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next() % n as u64) as usize
        }
    }
}

const TOKENS: &[&[u8]] = &[
    b"0",
    b"-1",
    b"4294967296",
    b"18446744073709551615",
    b"9223372036854775807",
    b"1e308",
    b"-1e308",
    b"nan",
    b"NaN",
    b"inf",
    b"65536",
    b"32768",
    b"1e-300",
    b"\xff\xfe",
    b"\"",
    b"]",
    b"}",
    b"[",
    b"{",
    b",",
    b"\n",
    b"element vertex 4611686018427387904\n",
    b"property list uchar int vertex_indices\n",
];

fn mutate(rng: &mut Rng, seed: &[u8]) -> Vec<u8> {
    let mut v = seed.to_vec();
    for _ in 0..1 + rng.below(4) {
        let n = v.len();
        match rng.below(7) {
            0 if n > 0 => {
                let i = rng.below(n);
                v[i] ^= 1 << rng.below(8);
            }
            1 if n > 0 => {
                let i = rng.below(n);
                v[i] = [0u8, 0xff, b'9', b'-', b'.', b' ', 0x7f][rng.below(7)];
            }
            2 => {
                let t = TOKENS[rng.below(TOKENS.len())];
                let i = rng.below(n + 1);
                v.splice(i..i, t.iter().copied());
            }
            3 if n > 0 => {
                // Replace a run of digits with a token.
                let i = rng.below(n);
                if let Some(s) = (i..n).find(|&k| v[k].is_ascii_digit()) {
                    let e = (s..n).find(|&k| !v[k].is_ascii_digit()).unwrap_or(n);
                    let t = TOKENS[rng.below(12)];
                    v.splice(s..e, t.iter().copied());
                }
            }
            4 if n > 1 => {
                let a = rng.below(n);
                let b = (a + 1 + rng.below(64)).min(n);
                v.drain(a..b);
            }
            5 if n > 1 && n < 1 << 20 => {
                let a = rng.below(n);
                let b = (a + 1 + rng.below(256)).min(n);
                let chunk = v[a..b].to_vec();
                let i = rng.below(n + 1);
                v.splice(i..i, chunk);
            }
            _ if n > 0 => v.truncate(rng.below(n)),
            _ => v.push(b'0'),
        }
    }
    v
}

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

fn read(rel: &str) -> Vec<u8> {
    std::fs::read(repo(rel)).unwrap_or_else(|e| panic!("seed {rel}: {e}"))
}

/// One call of a parser on an input (`Err` and `Ok` both pass).
type Run = Box<dyn Fn(&[u8])>;

/// A parser under test: its name, seeds, and the call.
struct Target {
    name: &'static str,
    seeds: Vec<Vec<u8>>,
    run: Run,
}

fn tmp_dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("r4d_fuzz_{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Writes `bytes` to a file named `name` (for the parsers that read a path) and runs `f`.
fn via_file(name: &'static str, f: impl Fn(&Path) + 'static) -> Run {
    let path = tmp_dir().join(name);
    Box::new(move |b: &[u8]| {
        std::fs::write(&path, b).unwrap();
        f(&path);
    })
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn npy(header: &str, body: &[u8]) -> Vec<u8> {
    let mut h = header.to_string();
    let total = 10 + h.len() + 1;
    h.push_str(&" ".repeat((64 - total % 64) % 64));
    h.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(h.len() as u16).to_le_bytes());
    out.extend_from_slice(h.as_bytes());
    out.extend_from_slice(body);
    out
}

fn targets() -> Vec<Target> {
    let small_ply: Vec<Vec<u8>> = [
        "tests/fixtures/datasets/physdreamer/toyplant/moving_part_points.ply",
        "tests/fixtures/datasets/physdreamer/toyplant/clean_object_points.ply",
        "tests/fixtures/datasets/physdreamer/toyplant/point_cloud.ply",
    ]
    .iter()
    .map(|p| read(p))
    .chain([
        b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n4 5 6\n".to_vec(),
        b"ply\nformat binary_little_endian 1.0\nelement junk 1\nproperty uchar a\nelement vertex 1\nproperty float x\nend_header\n\x01\x00\x00\xc0\x3f".to_vec(),
    ])
    .collect();
    let cameras: Vec<Vec<u8>> = [
        "tests/fixtures/physgaussian/fit_jelly_arch/cameras.json",
        "tests/fixtures/datasets/physflow/model/phys_dreamer/toyphone/cameras.json",
        "tests/fixtures/datasets/physdreamer/toyplant/transforms_train.json",
    ]
    .iter()
    .map(|p| read(p))
    .chain([br#"{"cameras": [{"name": "c", "width": 64, "height": 48, "fx": 50, "fy": 50, "cx": 32, "cy": 24, "world_to_camera": [[1,0,0,0],[0,1,0,0],[0,0,1,3],[0,0,0,1]]}], "background": [1, 1, 1]}"#.to_vec()])
    .collect();
    let sim_configs: Vec<Vec<u8>> = [
        "tests/fixtures/fit/beam.toml",
        "tests/fixtures/fit/two_part_beam.toml",
        "configs/jelly_drop.toml",
        "configs/sand_column.toml",
        "configs/metal_bar.toml",
    ]
    .iter()
    .map(|p| read(p))
    .collect();
    let physgaussian: Vec<Vec<u8>> = [
        "tests/fixtures/physgaussian/fit_jelly_arch/physgaussian_config.json",
        "tests/fixtures/physgaussian/sand_pile/physgaussian_config.json",
        "tests/fixtures/physgaussian/metal_bar_press/physgaussian_config.json",
    ]
    .iter()
    .map(|p| read(p))
    .collect();
    let fit_toml = b"iters = 3\nlr = 0.05\nfree = [\"E\", \"density\"]\nframes = 5\ncheckpointing = \"nested:7\"\n[init]\ncandidates = 3\nframes = 3\n[[parts]]\nid = 0\nfree = [\"E\"]\nbounds = { E = [1e3, 1e7] }\n[loss.weights]\nl1 = 0.0\nspatial = 1.0\nmag = 1.0\nphase = 0.1\n".to_vec();
    let colmap_images =
        b"# header\n1 1 0 0 0 0 0 3 1 a.png\n1.0 2.0 -1\n2 0.7 0.7 0 0 0.1 0 3 1 b.png\n\n"
            .to_vec();
    let colmap_cameras = "1 PINHOLE 64 48 50 50 32 24\n2 SIMPLE_RADIAL 64 48 50 32 24 0\n";
    let videos = vec![
        npy(
            "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 2, 2, 3), }",
            &[0u8; 96],
        ),
        npy(
            "{'descr': '<f8', 'fortran_order': False, 'shape': (2, 1, 3), }",
            &[0u8; 48],
        ),
    ];
    let masks = vec![
        npy(
            "{'descr': '|b1', 'fortran_order': False, 'shape': (4, 4), }",
            &[1u8; 16],
        ),
        npy(
            "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 4, 4), }",
            &[0u8; 128],
        ),
    ];
    let parts = vec![
        br#"{"num_parts": 2, "class_names": ["a", "b"], "labels": [0, 1, -1, 1]}"#.to_vec(),
        br#"{"num_parts": 1, "labels": [0, 0]}"#.to_vec(),
    ];
    let optimiser = serde_json::to_vec(
        &r4d_optim::LogDomainOptimizer::new(
            vec![1.0, 2.0],
            vec![(0.1, 10.0), (0.5, 5.0)],
            Default::default(),
            Some(1.0),
        )
        .unwrap(),
    )
    .unwrap();
    // A fit checkpoint with every section filled (initialisation, optimiser, best point,
    // multi-start), as both fits write it.
    let checkpoint = {
        let names = vec!["E[0]".to_string(), "density[0]".to_string()];
        let mut s = r4d_optim::record::FitState::new(names, "0".repeat(32));
        s.iters_done = 2;
        s.optimizer = r4d_optim::LogDomainOptimizer::new(
            vec![1e5, 1e3],
            vec![(1e3, 1e8), (10.0, 1e4)],
            Default::default(),
            Some(1.0),
        )
        .ok();
        s.best = Some((0.5, vec![1e5, 1e3]));
        s.init = r4d_optim::InitOutcome::from_candidates(
            vec![r4d_optim::Candidate {
                index: 0,
                theta: vec![1e5, 1e3],
                score: Some(0.9),
                error: None,
            }],
            1,
        )
        .ok();
        s.starts = vec![r4d_optim::record::StartResult {
            failed: None,
            candidate: 0,
            score: Some(0.9),
            loss: 0.5,
            theta: vec![1e5, 1e3],
        }];
        let unchecked = serde_json::to_vec(&s).unwrap();
        vec![s.to_json().into_bytes(), unchecked]
    };
    let snapshot = {
        let p = tmp_dir().join("seed-state.r4d");
        r4d_mpm::Snapshot {
            frame: 1,
            substep: 10,
            time_s: 0.01,
            x: vec![[0.5; 3]; 4],
            v: vec![[0.0; 3]; 4],
            c: vec![[0.0; 9]; 4],
            f: vec![[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]; 4],
            plastic: vec![[0.0, 1.0]; 4],
            fingerprint: "f".repeat(32),
        }
        .write(&p)
        .unwrap();
        vec![std::fs::read(&p).unwrap()]
    };
    let png = |img: image::DynamicImage| {
        let mut b = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut b), image::ImageFormat::Png)
            .unwrap();
        b
    };
    let frames = vec![
        std::fs::read(repo(
            "tests/fixtures/physgaussian/fit_jelly_arch/cam0/frame_0000.png",
        ))
        .unwrap(),
        png(image::DynamicImage::ImageRgb8(image::RgbImage::from_fn(
            6,
            4,
            |x, y| image::Rgb([x as u8 * 40, y as u8 * 60, 7]),
        ))),
        png(image::DynamicImage::ImageRgba16(
            image::ImageBuffer::from_fn(3, 3, |x, _| image::Rgba([x as u16 * 9000, 1, 2, 65535])),
        )),
    ];
    let label_pngs = vec![
        png(image::DynamicImage::ImageLuma8(image::GrayImage::from_fn(
            5,
            4,
            |x, y| image::Luma([((x + y) % 3) as u8]),
        ))),
        png(image::DynamicImage::ImageLuma16(
            image::ImageBuffer::from_fn(4, 4, |x, _| image::Luma([x as u16 * 300])),
        )),
    ];
    let classes = vec![
        br#"{"class_names": ["stem", "head"], "ignore": 255}"#.to_vec(),
        br#"{"class_names": ["a"]}"#.to_vec(),
    ];
    let physflow = vec![std::fs::read(repo(
        "tests/fixtures/datasets/physflow/config/phys_dreamer/toyphone_config.json",
    ))
    .unwrap()];
    let all_data = vec![std::fs::read(repo(
        "tests/fixtures/datasets/pacnerf/toyball/all_data.json",
    ))
    .unwrap()];
    let transforms = vec![std::fs::read(repo(
        "tests/fixtures/datasets/physdreamer/toyplant/transforms_train.json",
    ))
    .unwrap()];
    let mp4 = {
        let p = tmp_dir().join("seed.mp4");
        let mut v = r4d_loss::Video::<f32>::zeros(2, 16, 16);
        for (i, x) in v.data_mut().iter_mut().enumerate() {
            *x = (i % 7) as f32 / 7.0;
        }
        r4d_video::write_mp4(&p, &v, 30.0).unwrap();
        vec![std::fs::read(&p).unwrap()]
    };
    let colmap_dir = repo("tests/fixtures/datasets/physdreamer/toyplant_colmap/sparse/0");
    let cameras_bin = std::fs::read(colmap_dir.join("cameras.bin")).unwrap();
    let images_bin = std::fs::read(colmap_dir.join("images.bin")).unwrap();
    let colmap_bins = vec![cameras_bin.clone(), images_bin.clone()];
    vec![
        Target {
            name: "colmap_bin",
            seeds: colmap_bins,
            // Each input as cameras.bin (with the fixture's images.bin) and as images.bin.
            run: Box::new(move |b| {
                let (c, i) = (Path::new("cameras.bin"), Path::new("images.bin"));
                let _ = r4d_datasets::cameras::colmap_bin_bytes_to_text(b, c, &images_bin, i);
                let _ = r4d_datasets::cameras::colmap_bin_bytes_to_text(&cameras_bin, c, b, i);
            }),
        },
        Target {
            name: "fit_checkpoint",
            seeds: checkpoint,
            run: Box::new(|b| {
                let free = vec![
                    vec![
                        r4d_optim::ParamKind::YoungsModulus,
                        r4d_optim::ParamKind::Density
                    ];
                    1
                ];
                let space = r4d_optim::space::ParamSpace::new(
                    r4d_optim::space::Granularity::Part,
                    &free,
                    &[0],
                    |_, k| k.default_bounds(),
                );
                if let Ok(s) = r4d_optim::record::FitState::from_json(&text(b)) {
                    let _ = s.check(&space, &"0".repeat(32));
                }
                // The checks behind the checksum, on any state that parses.
                if let Ok(s) = serde_json::from_slice::<r4d_optim::record::FitState>(b) {
                    let _ = s.check(&space, &s.fingerprint.clone());
                }
            }),
        },
        Target {
            name: "state_snapshot",
            seeds: snapshot,
            run: Box::new(|b| {
                let _ = r4d_mpm::Snapshot::decode(b, Path::new("state.r4d"), 4, &"f".repeat(32));
            }),
        },
        Target {
            name: "png_frame",
            seeds: frames,
            run: Box::new(|b| {
                let _ = r4d_loss::io::decode_frame::<f32>(b, Path::new("frame_0000.png"));
            }),
        },
        Target {
            name: "mask_png",
            seeds: label_pngs,
            run: Box::new(|b| {
                let p = Path::new("mask.png");
                let _ = r4d_segment::mask::decode_label_png(b, p);
                let _ = r4d_segment::mask::decode_probability_map(b, p, false);
            }),
        },
        Target {
            name: "classes_json",
            seeds: classes,
            run: Box::new(|b| {
                let _ = r4d_segment::mask::parse_classes(&text(b), Path::new("classes.json"));
            }),
        },
        Target {
            name: "physflow_config",
            seeds: physflow,
            run: Box::new(|b| {
                let _ = r4d_datasets::physflow_config::decode(&text(b), Path::new("c.json"));
            }),
        },
        Target {
            name: "pacnerf_all_data",
            seeds: all_data,
            run: {
                let d = tmp_dir().join("pacnerf");
                std::fs::create_dir_all(&d).unwrap();
                Box::new(move |b| {
                    let _ = r4d_datasets::pacnerf::parse_all_data(&text(b), &d);
                })
            },
        },
        Target {
            name: "physdreamer_transforms",
            seeds: transforms,
            run: {
                let d = tmp_dir().join("physdreamer");
                std::fs::create_dir_all(&d).unwrap();
                Box::new(move |b| {
                    let _ = r4d_datasets::physdreamer::parse_transforms(&text(b), &d);
                })
            },
        },
        Target {
            name: "mp4",
            seeds: mp4,
            run: via_file("v.mp4", |p| {
                let _ = r4d_video::read_mp4::<f32>(p, None);
            }),
        },
        Target {
            name: "ply",
            seeds: small_ply.clone(),
            run: Box::new(|b| {
                let _ = r4d_mpm::ply::parse_ply(b, "f.ply");
            }),
        },
        Target {
            name: "gaussians_ply",
            seeds: small_ply,
            run: Box::new(|b| {
                let _ = r4d_splat::ply::parse_gaussians(b, "f.ply");
            }),
        },
        Target {
            name: "cameras_json",
            seeds: cameras,
            run: Box::new(|b| {
                let _ = r4d_splat::camera_io::parse_camera_json(&text(b), "c.json");
            }),
        },
        Target {
            name: "colmap",
            seeds: vec![colmap_images],
            run: Box::new(move |b| {
                let _ = r4d_splat::camera_io::parse_colmap(colmap_cameras, &text(b), "colmap");
                let _ = r4d_splat::camera_io::parse_colmap(
                    &text(b),
                    "1 1 0 0 0 0 0 3 1 a.png\n",
                    "colmap",
                );
            }),
        },
        Target {
            name: "sim_config",
            seeds: sim_configs,
            run: Box::new(|b| {
                let _ = r4d_mpm::SimConfig::parse(&text(b), Path::new("sim.toml"));
            }),
        },
        Target {
            name: "physgaussian_json",
            seeds: physgaussian,
            run: Box::new(|b| {
                let _ = r4d_mpm::physgaussian::import_str(&text(b), "pg.json");
            }),
        },
        Target {
            name: "fit_toml",
            seeds: vec![fit_toml],
            run: Box::new(|b| {
                if let Ok(c) = toml::from_str::<r4d_optim::video::FitConfig>(&text(b)) {
                    let _ = c.validate();
                    let _ = c.free_kinds(&[Default::default(), Default::default()]);
                }
            }),
        },
        Target {
            name: "npy_video",
            seeds: videos,
            run: Box::new(|b| {
                let _ = r4d_loss::io::decode_npy_video::<f32>(b, Path::new("v.npy"));
            }),
        },
        Target {
            name: "npy_mask",
            seeds: masks,
            run: Box::new(|b| {
                let _ = r4d_segment::mask::parse_npy(b);
                let _ = r4d_segment::mask::decode_probability_map(b, Path::new("m.npy"), true);
            }),
        },
        Target {
            name: "parts_json",
            seeds: parts,
            run: Box::new(|b| {
                let _ = r4d_segment::PartLabels::parse(&text(b), Path::new("parts.json"));
            }),
        },
        Target {
            name: "optimiser_state",
            seeds: vec![optimiser],
            run: Box::new(|b| {
                if let Ok(o) = serde_json::from_slice::<r4d_optim::LogDomainOptimizer>(b) {
                    if o.validate(2).is_ok() {
                        let mut o = o;
                        o.step(&[0.1, -0.2]);
                    }
                }
            }),
        },
    ]
}

/// Runs `t` on `input`: an error message for a panic, an oversized allocation or a hang.
fn check(t: &Target, input: &[u8]) -> Result<Duration, String> {
    LARGEST.store(0, Ordering::Relaxed);
    let start = Instant::now();
    let r = catch_unwind(AssertUnwindSafe(|| (t.run)(input)));
    let took = start.elapsed();
    let largest = LARGEST.load(Ordering::Relaxed);
    if r.is_err() {
        return Err("panicked".into());
    }
    if largest > MAX_ALLOCATION {
        return Err(format!("allocated {largest} bytes at once"));
    }
    if took > HANG {
        return Err(format!("took {took:?}"));
    }
    Ok(took)
}

#[test]
fn every_parser_survives_mutated_inputs() {
    let execs: usize = std::env::var("R4D_FUZZ_EXECS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(20_000);
    let seed: u64 = std::env::var("R4D_FUZZ_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0x5eed);
    // R4D_FUZZ_ONLY=ply,colmap runs only those parsers (long runs, one parser at a time).
    let only: Option<Vec<String>> = std::env::var("R4D_FUZZ_ONLY")
        .ok()
        .map(|s| s.split(',').map(|t| t.trim().to_string()).collect());
    let all: Vec<Target> = targets()
        .into_iter()
        .filter(|t| only.as_ref().is_none_or(|o| o.iter().any(|n| n == t.name)))
        .collect();
    // The parsers' own panics are what is looked for; keep their messages out of the log.
    std::panic::set_hook(Box::new(|_| {}));
    let failures_dir = repo("target/fuzz-failures");
    let mut failures = Vec::new();
    for t in all {
        let mut rng = Rng((seed ^ (t.name.len() as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)) | 1);
        let t0 = Instant::now();
        let mut slowest = Duration::ZERO;
        // Regression inputs first, then the seeds as they are, then mutations.
        let regressions: Vec<Vec<u8>> = std::fs::read_dir(repo("tests/fixtures/fuzz").join(t.name))
            .map(|d| {
                d.filter_map(|e| std::fs::read(e.ok()?.path()).ok())
                    .collect()
            })
            .unwrap_or_default();
        let fixed: Vec<&Vec<u8>> = regressions.iter().chain(&t.seeds).collect();
        let mut count = 0usize;
        for i in 0..fixed.len() + execs {
            let input = if i < fixed.len() {
                fixed[i].clone()
            } else {
                let s = &t.seeds[rng.below(t.seeds.len())];
                mutate(&mut rng, s)
            };
            count += 1;
            match check(&t, &input) {
                Ok(d) => slowest = slowest.max(d),
                Err(why) => {
                    std::fs::create_dir_all(&failures_dir).ok();
                    let path = failures_dir.join(format!("{}-{i}.bin", t.name));
                    std::fs::write(&path, &input).ok();
                    failures.push(format!("{}: {why}: input {}", t.name, path.display()));
                    if failures.len() > 20 {
                        break;
                    }
                }
            }
        }
        eprintln!(
            "fuzz {:<18} {count:>9} executions in {:>7.2} s, slowest {:?}",
            t.name,
            t0.elapsed().as_secs_f64(),
            slowest
        );
    }
    let _ = std::panic::take_hook();
    assert!(
        failures.is_empty(),
        "{} failure(s):\n{}",
        failures.len(),
        failures.join("\n")
    );
}
