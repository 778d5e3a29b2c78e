//! The GPU engines pass the exported conformance suite (`r4d-conformance`): simulation,
//! adjoint, renderer and render VJP, and the frames kept on the device (the link kernels), through
//! their `Compute`, against the CPU in f32, on the binary's shared engines.

#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn wgpu_passes_the_conformance_suite() {
    let Some(ctx) = crate::common::gpu::wgpu("wgpu conformance") else {
        return;
    };
    let compute = resonance4d::compute::WgpuCompute::new((*ctx).clone());
    let report = r4d_conformance::run(&compute, &Default::default()).unwrap();
    print!("{report}");
    assert_eq!(report.precision, "f32");
    assert!(
        report.checks.iter().any(|c| c.name == "linked.vjp.F"),
        "frames stay on the device: the link checks ran"
    );
}

#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn vulkan_passes_the_conformance_suite() {
    let Some(engine) = crate::common::gpu::vulkan("vulkan conformance") else {
        return;
    };
    let compute = resonance4d::compute::VulkanCompute::new(engine.clone());
    let report = r4d_conformance::run(&compute, &Default::default()).unwrap();
    print!("{report}");
    assert_eq!(report.precision, "f32");
    r4d_backend_vulkan::testing::assert_validation_clean(&engine, "vulkan conformance");
}
