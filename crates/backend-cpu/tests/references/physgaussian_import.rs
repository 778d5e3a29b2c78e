//! The PhysGaussian import reproduces the trajectories of PhysGaussian's own Warp solver
//! (`tests/fixtures/physgaussian/`, copied from the project's reference data).
//!
//! Jelly: every particle within 0.05 dx at every frame. Metal, sand, plasticine (path
//! dependent): centroid within 0.25 dx and bounding box within 0.5 dx at every frame.

use r4d_backend_cpu::CpuBackend;
use r4d_mpm::{physgaussian, MpmKernels, ParticleSet, Simulation, Simulator};
use r4d_testkit::{fixture, read_npz, Array};

struct Run {
    dx: f64,
    reference: Array,
    ours: Vec<Vec<[f32; 3]>>,
}

fn run<B: MpmKernels>(backend: B, scenario: &str) -> Run {
    let dir = fixture(&format!("physgaussian/{scenario}"));
    let imp = physgaussian::import_file(&dir.join("physgaussian_config.json")).unwrap();
    let init = read_npz(&dir.join("initial_state.npz"));
    let traj = read_npz(&dir.join("trajectory.npz"));
    let x0 = &init["x0"];
    let n = x0.shape[0];
    let mut scene = ParticleSet {
        x: (0..n)
            .map(|i| std::array::from_fn(|a| x0.at(&[i, a]) as f32))
            .collect(),
        volume: init["volume"].data.iter().map(|&v| v as f32).collect(),
        part: vec![0; n],
    };
    imp.apply_to_scene(&mut scene, true);
    let cfg = imp.config;
    let mut sim = Simulation::new(backend, &cfg, scene, scenario).unwrap();
    let mut state = sim.init_state(&cfg.parts).unwrap();
    let mut ours = vec![sim.positions(&state).unwrap()];
    for _ in 0..cfg.time.frames {
        sim.step_frame(&mut state, &cfg.parts).unwrap();
        ours.push(sim.positions(&state).unwrap());
    }
    Run {
        dx: cfg.domain.dx(),
        reference: traj["positions"].clone(),
        ours,
    }
}

fn summary(pts: impl Iterator<Item = [f64; 3]>) -> ([f64; 3], [f64; 3], [f64; 3]) {
    let mut c = [0.0; 3];
    let mut lo = [f64::MAX; 3];
    let mut hi = [f64::MIN; 3];
    let mut n = 0.0;
    for p in pts {
        for a in 0..3 {
            c[a] += p[a];
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
        n += 1.0;
    }
    (c.map(|x| x / n), lo, hi)
}

fn check_per_particle(r: &Run, tol_dx: f64) {
    let n = r.reference.shape[1];
    assert_eq!(r.ours.len(), r.reference.shape[0]);
    let mut worst = (0.0, 0);
    for (k, frame) in r.ours.iter().enumerate() {
        for (i, p) in frame.iter().enumerate().take(n) {
            for a in 0..3 {
                let d = (p[a] as f64 - r.reference.at(&[k, i, a])).abs();
                if d > worst.0 {
                    worst = (d, k);
                }
            }
        }
    }
    eprintln!(
        "max particle deviation {:.3e} m = {:.4} dx (frame {})",
        worst.0,
        worst.0 / r.dx,
        worst.1
    );
    assert!(
        worst.0 <= tol_dx * r.dx,
        "max deviation {:.4} dx at frame {}",
        worst.0 / r.dx,
        worst.1
    );
}

fn check_aggregate(r: &Run) {
    let n = r.reference.shape[1];
    assert_eq!(r.ours.len(), r.reference.shape[0]);
    let (mut wc, mut wb) = (0.0f64, 0.0f64);
    for (k, frame) in r.ours.iter().enumerate() {
        let (c1, lo1, hi1) = summary(frame.iter().map(|p| p.map(|x| x as f64)));
        let (c2, lo2, hi2) =
            summary((0..n).map(|i| std::array::from_fn(|a| r.reference.at(&[k, i, a]))));
        for a in 0..3 {
            wc = wc.max((c1[a] - c2[a]).abs());
            wb = wb.max((lo1[a] - lo2[a]).abs()).max((hi1[a] - hi2[a]).abs());
        }
    }
    eprintln!(
        "max centroid deviation {:.4} dx, max bbox deviation {:.4} dx",
        wc / r.dx,
        wb / r.dx
    );
    assert!(wc <= 0.25 * r.dx, "centroid off by {:.4} dx", wc / r.dx);
    assert!(wb <= 0.5 * r.dx, "bounding box off by {:.4} dx", wb / r.dx);
}

#[test]
fn jelly_drop_matches_physgaussian_per_particle() {
    check_per_particle(&run(CpuBackend::default(), "jelly_drop"), 0.05);
}

#[test]
fn metal_bar_press_matches_physgaussian() {
    check_aggregate(&run(CpuBackend::default(), "metal_bar_press"));
}

#[test]
fn sand_pile_matches_physgaussian() {
    check_aggregate(&run(CpuBackend::default(), "sand_pile"));
}

#[test]
fn plasticine_slab_matches_physgaussian() {
    check_aggregate(&run(CpuBackend::default(), "plasticine_slab"));
}
