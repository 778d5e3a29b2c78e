//! Dataset load: a PhysFlow-release scene of 1M SH-degree-3 Gaussians (the fixture `toyphone`
//! with its Gaussians replicated and jittered; its config, cameras, moving part and frames as
//! they are) parsed, opacity-filtered, moving-part-selected, normalised and filled, the way
//! `r4d fit --dataset` and `r4d dataset inspect` load it. Reports the time per load and, from
//! the counting allocator, the peak heap of one load.
//!
//! Target: <= 10 s and <= 1 GB for 1M Gaussians on 2 cores.

#![expect(
    missing_docs,
    reason = "criterion's macros generate undocumented public items"
)]

use criterion::{criterion_group, criterion_main, Criterion};
use r4d_datasets::{load, LoadOptions};
use resonance4d::alloc::{peak_since, reset_peak, Counting};
use std::path::{Path, PathBuf};

#[global_allocator]
static GLOBAL: Counting = Counting;

const N: usize = 1_000_000;

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("mkdir");
    for e in std::fs::read_dir(from).expect("read_dir") {
        let e = e.expect("entry");
        let t = to.join(e.file_name());
        if e.path().is_dir() {
            copy_dir(&e.path(), &t);
        } else {
            std::fs::copy(e.path(), &t).expect("copy");
        }
    }
}

/// A copy of the toyphone fixture whose latest point cloud holds `N` SH-3 Gaussians.
fn scene(root: &Path) -> (PathBuf, PathBuf) {
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/datasets/physflow");
    let dir = root.join("model/phys_dreamer/toyphone");
    copy_dir(&fixtures.join("model/phys_dreamer/toyphone"), &dir);
    let cfg = fixtures.join("config/phys_dreamer/toyphone_config.json");
    // The fixture's inpainted background is SH degree 1; the scene here is degree 3 (as
    // PhysFlow's scenes are), so leave the background out.
    std::fs::remove_file(dir.join("inpaint_points.ply")).expect("inpaint_points.ply");
    // The loader reads the largest iteration; the fixture's is 7000.
    let pc = dir.join("point_cloud/iteration_7000/point_cloud.ply");
    let src = r4d_splat::ply::read_gaussians(&pc).expect("fixture");
    let k = r4d_splat::gaussians::sh_coeffs(3);
    let mut g = r4d_splat::Gaussians {
        sh_degree: 3,
        means: Vec::with_capacity(N),
        log_scales: Vec::with_capacity(N),
        quats: Vec::with_capacity(N),
        opacity_logits: Vec::with_capacity(N),
        sh: Vec::with_capacity(N * k * 3),
    };
    let mut s = 0x9e37_79b9_7f4a_7c15u64;
    let mut r = || {
        s = s
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        ((s >> 40) as f32 / (1u64 << 24) as f32) - 0.5
    };
    for i in 0..N {
        let j = i % src.len();
        let m = src.means[j];
        g.means
            .push([m[0] + 0.01 * r(), m[1] + 0.01 * r(), m[2] + 0.01 * r()]);
        g.log_scales.push(src.log_scales[j]);
        g.quats.push(src.quats[j]);
        g.opacity_logits.push(src.opacity_logits[j] + r());
        let sh = src.sh_of(j);
        for c in 0..k * 3 {
            g.sh.push(sh.get(c).copied().unwrap_or(0.01 * r()));
        }
    }
    // The loader takes the largest iteration_N.
    let big = dir.join("point_cloud/iteration_99999/point_cloud.ply");
    std::fs::create_dir_all(big.parent().expect("parent")).expect("mkdir");
    r4d_splat::ply::write_gaussians(&big, &g).expect("write");
    (dir, cfg)
}

fn bench_dataset(c: &mut Criterion) {
    let root = std::env::temp_dir().join(format!("r4d-bench-dataset-{}", std::process::id()));
    let (dir, cfg) = scene(&root);
    let opts = LoadOptions {
        sim: Some(cfg),
        ..Default::default()
    };
    let mark = reset_peak();
    let ds = load(&dir, &opts).expect("load");
    let peak = peak_since(mark);
    eprintln!(
        "dataset load: {N} Gaussians in the file, {} rendered after the opacity filter, {} simulated particles; peak heap {:.0} MB",
        ds.scene.len(),
        ds.particles.len(),
        peak as f64 / 1e6
    );
    drop(ds);
    let mut g = c.benchmark_group("dataset_load");
    g.sample_size(10);
    g.bench_function("physflow_1M_sh3", |b| {
        b.iter(|| load(&dir, &opts).expect("load"))
    });
    g.finish();
    let _ = std::fs::remove_dir_all(&root);
}

criterion_group!(benches, bench_dataset);
criterion_main!(benches);
