//! `R4D_VULKAN_DEVICE` picks a device by index or by a part of its name; an index or name
//! that matches nothing is a typed error listing the devices (never a panic, never another
//! device; it used to crash: the loader was unloaded before the instance was destroyed). One
//! test in this binary: it sets the environment.

use r4d_backend_vulkan::testing::vulkan_or_skip;
use r4d_backend_vulkan::{VulkanEngine, VulkanError};

#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn the_device_is_chosen_by_index_or_name() {
    let Some(default) = vulkan_or_skip("device choice") else {
        return;
    };
    let name = default.device_name().to_string();
    drop(default);
    let open = |v: &str| {
        // SAFETY: the only test of this binary; no other thread reads the environment.
        unsafe { std::env::set_var("R4D_VULKAN_DEVICE", v) };
        VulkanEngine::new()
    };
    // A part of the name.
    let part = &name[..name.len().min(4)];
    assert_eq!(open(part).unwrap().device_name(), name);
    // An index: one of them is the default device.
    let by_index: Vec<String> = (0..8)
        .filter_map(|i| open(&i.to_string()).ok())
        .map(|e| e.device_name().to_string())
        .collect();
    assert!(by_index.contains(&name), "{by_index:?} lacks {name}");
    // Nothing matches: a typed error naming the variable and the devices.
    for v in ["999", "no such device"] {
        match open(v) {
            Err(e @ VulkanError::NoDevice(_)) => {
                let m = e.to_string();
                assert!(m.contains("R4D_VULKAN_DEVICE") && m.contains(&name), "{m}");
            }
            other => panic!("R4D_VULKAN_DEVICE={v}: {other:?}"),
        }
    }
    // SAFETY: as above.
    unsafe { std::env::remove_var("R4D_VULKAN_DEVICE") };
}
