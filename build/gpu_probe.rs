// Included by the build scripts of the root package and the GPU backends (`include!`): decides
// whether this machine is expected to have a GPU adapter, so that without one the GPU tests
// are compiled as `#[ignore]`d (reported as ignored, with the reason) instead of returning
// early and being reported as passed. The tests then panic if the build expected an adapter
// and none opens (a driver found but broken), rather than pass.
//
// Expected: `R4D_REQUIRE_GPU=1`; macOS/iOS (Metal) and Windows (DX12); elsewhere a Vulkan
// loader (`libvulkan.so.1`) and at least one Vulkan driver manifest (`VK_ICD_FILENAMES`,
// `VK_DRIVER_FILES`, or `*.json` in the standard `vulkan/icd.d` folders). `R4D_NO_GPU=1`
// forces "not expected".

/// Prints the cargo directives and sets `cfg(r4d_gpu)` when an adapter is expected.
fn probe_gpu() {
    println!("cargo::rustc-check-cfg=cfg(r4d_gpu)");
    for v in [
        "R4D_REQUIRE_GPU",
        "R4D_NO_GPU",
        "VK_ICD_FILENAMES",
        "VK_DRIVER_FILES",
        "XDG_DATA_DIRS",
        "LD_LIBRARY_PATH",
    ] {
        println!("cargo:rerun-if-env-changed={v}");
    }
    let set = |v: &str| std::env::var(v).is_ok_and(|x| x == "1");
    let expected = if set("R4D_NO_GPU") {
        false
    } else if set("R4D_REQUIRE_GPU") {
        true
    } else {
        let os = std::env::var("CARGO_CFG_TARGET_OS").unwrap_or_default();
        matches!(os.as_str(), "macos" | "ios" | "windows") || vulkan_driver_present()
    };
    if expected {
        println!("cargo:rustc-cfg=r4d_gpu");
    }
}

fn vulkan_driver_present() -> bool {
    use std::path::{Path, PathBuf};
    let mut lib_dirs: Vec<PathBuf> = [
        "/usr/lib/x86_64-linux-gnu",
        "/usr/lib/aarch64-linux-gnu",
        "/usr/lib64",
        "/usr/lib",
        "/lib/x86_64-linux-gnu",
        "/lib64",
        "/usr/local/lib",
    ]
    .iter()
    .map(PathBuf::from)
    .collect();
    if let Some(p) = std::env::var_os("LD_LIBRARY_PATH") {
        lib_dirs.extend(std::env::split_paths(&p));
    }
    let loader = lib_dirs
        .iter()
        .any(|d| d.join("libvulkan.so.1").exists() || d.join("libvulkan.so").exists());
    let files = |v: &str| -> bool {
        std::env::var_os(v).is_some_and(|p| std::env::split_paths(&p).any(|f| f.is_file()))
    };
    let mut icd_dirs: Vec<PathBuf> = vec![
        PathBuf::from("/usr/share/vulkan/icd.d"),
        PathBuf::from("/usr/local/share/vulkan/icd.d"),
        PathBuf::from("/etc/vulkan/icd.d"),
    ];
    if let Some(p) = std::env::var_os("XDG_DATA_DIRS") {
        icd_dirs.extend(std::env::split_paths(&p).map(|d| d.join("vulkan/icd.d")));
    }
    let manifest_in = |d: &Path| -> bool {
        println!("cargo:rerun-if-changed={}", d.display());
        std::fs::read_dir(d).is_ok_and(|rd| {
            rd.flatten()
                .any(|e| e.path().extension().is_some_and(|x| x == "json"))
        })
    };
    let driver = files("VK_ICD_FILENAMES")
        || files("VK_DRIVER_FILES")
        || icd_dirs.iter().any(|d| manifest_in(d));
    loader && driver
}
