//! The host backends pass the exported conformance suite: the parallel CPU backend (against
//! itself in f64: bit for bit) and the single-threaded reference kernels (against the parallel
//! CPU backend). The GPU engines run it in the root package's `backends` tests.

use resonance4d::compute;
use resonance4d::conformance::{run, Tolerances};

#[test]
fn the_cpu_backend_passes_the_conformance_suite() {
    let report = run(&*compute::cpu(), &Tolerances::default()).unwrap();
    print!("{report}");
    assert_eq!(report.precision, "f64");
    assert!(report.checks.iter().all(|c| c.error == 0.0), "{report}");
}

#[test]
fn the_reference_kernels_pass_the_conformance_suite() {
    let report = run(&*compute::reference(), &Tolerances::default()).unwrap();
    print!("{report}");
    assert!(report.checks.len() >= 20, "{report}");
}

#[test]
fn a_tolerance_of_zero_fails_with_the_check_named() {
    let tight = Tolerances {
        gradient: 0.0,
        ..Default::default()
    };
    let e = run(&*compute::reference(), &tight).unwrap_err().to_string();
    assert!(e.contains("adjoint.E[0]") && e.contains("reference"), "{e}");
}
