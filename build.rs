//! Build script of the root package: tells the LPIPS golden tests whether pretrained weights
//! are present, so that without them they are reported as *ignored* (with the reason), never
//! as passed. The weights are looked for in `$R4D_LPIPS_DIR`, else `target/lpips/` (where
//! `scripts/lpips_weights.sh` puts them); `R4D_REQUIRE_LPIPS=1` (CI) makes their absence a
//! build error. It also decides whether the GPU tests can run here (`cfg(r4d_gpu)`,
//! `build/gpu_probe.rs`): without an expected adapter they are reported as ignored.

use std::path::PathBuf;

include!("build/gpu_probe.rs");

fn main() {
    println!("cargo:rerun-if-changed=build/gpu_probe.rs");
    probe_gpu();
    println!("cargo::rustc-check-cfg=cfg(r4d_lpips_weights)");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=R4D_LPIPS_DIR");
    println!("cargo:rerun-if-env-changed=R4D_REQUIRE_LPIPS");
    let dir = match std::env::var_os("R4D_LPIPS_DIR") {
        Some(d) => PathBuf::from(d),
        None => PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("set by cargo"))
            .join("target/lpips"),
    };
    // Watch the folder (made if missing, so that cargo does not rerun this every build).
    let _ = std::fs::create_dir_all(&dir);
    println!("cargo:rerun-if-changed={}", dir.display());
    let found = ["alex", "vgg"]
        .iter()
        .all(|n| dir.join(format!("{n}.safetensors")).is_file());
    if found {
        println!("cargo:rustc-cfg=r4d_lpips_weights");
        println!("cargo:rustc-env=R4D_LPIPS_TEST_DIR={}", dir.display());
    } else if std::env::var("R4D_REQUIRE_LPIPS").is_ok_and(|v| v == "1") {
        panic!(
            "R4D_REQUIRE_LPIPS=1 but {} lacks alex.safetensors / vgg.safetensors: run scripts/lpips_weights.sh",
            dir.display()
        );
    }
}
