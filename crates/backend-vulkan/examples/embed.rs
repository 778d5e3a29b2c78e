//! Embedding the simulator in an application that already has a Vulkan device (a renderer,
//! an engine): the application creates the instance, the device and a compute-capable queue;
//! the engine shares them (`VulkanEngine::from_host`), simulates, and hands the particle
//! positions over as a `vk::Buffer` the application can bind in its own pipelines
//! (`VkBuffer::handle`); an application buffer goes the other way with
//! `VulkanEngine::import_buffer`.
//!
//! Run: `cargo run -p r4d-backend-vulkan --example embed` (any Vulkan device; Mesa's lavapipe
//! will do: `VK_ICD_FILENAMES=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json`).

use r4d_backend_vulkan::ash::{self, vk};
use r4d_backend_vulkan::{HostDevice, VulkanBackend, VulkanEngine};
use r4d_gpu::GpuEngine;
use r4d_mpm::{ParticleSet, SimConfig, Simulation, Simulator};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // --- The application's side: its own instance, device and queue. ---
    // SAFETY: loading the system's Vulkan loader.
    let entry = unsafe { ash::Entry::load()? };
    let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_1);
    // SAFETY: valid create infos; destroyed at the end of main.
    let instance = unsafe {
        entry.create_instance(
            &vk::InstanceCreateInfo::default().application_info(&app),
            None,
        )?
    };
    // SAFETY: the instance is valid.
    let physical = unsafe { instance.enumerate_physical_devices()? }
        .into_iter()
        .next()
        .ok_or("no Vulkan device")?;
    // SAFETY: `physical` belongs to the instance.
    let family = unsafe { instance.get_physical_device_queue_family_properties(physical) }
        .iter()
        .position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE))
        .ok_or("no compute queue")? as u32;
    let prio = [1.0f32];
    let queues = [vk::DeviceQueueCreateInfo::default()
        .queue_family_index(family)
        .queue_priorities(&prio)];
    // SAFETY: valid create info.
    let device = unsafe {
        instance.create_device(
            physical,
            &vk::DeviceCreateInfo::default().queue_create_infos(&queues),
            None,
        )?
    };

    // --- The engine on the application's device. ---
    let host = HostDevice {
        entry: entry.clone(),
        instance: instance.clone(),
        physical_device: physical,
        device: device.clone(),
        queue_family: family,
        queue_index: 0,
        float_atomics: false,
    };
    {
        // SAFETY: the handles belong together, outlive the engine (dropped at the end of this
        // block) and nothing else uses the queue meanwhile.
        let engine = unsafe { VulkanEngine::from_host(host)? };
        println!(
            "simulating on the application's device: {}",
            engine.device_name()
        );
        let cfg: SimConfig = toml::from_str(
            r#"
domain = { grid_lim = 1.0, n_grid = 16 }
time = { substep_dt = 2e-4, substeps_per_frame = 20, frames = 3 }
[[parts]]
material = "jelly"
youngs_modulus_pa = 2e4
density_kg_m3 = 1000.0
[[shapes]]
kind = "box"
min = [0.4, 0.4, 0.4]
max = [0.6, 0.6, 0.6]
[[boundary]]
type = "bounding_box"
"#,
        )?;
        let scene = ParticleSet::from_shapes(&cfg.shapes, cfg.domain.dx());
        let mut sim = Simulation::new(VulkanBackend::new(engine.clone()), &cfg, scene, "embed")?;
        let mut state = sim.init_state(&cfg.parts)?;
        for _ in 0..cfg.time.frames {
            sim.step_frame(&mut state, &cfg.parts)?;
        }
        let x = sim.positions(&state)?;
        println!("{} particles; the first is at {:?}", x.len(), x[0]);

        // Export: an engine buffer as the application's vk::Buffer.
        let staged = r4d_gpu::GpuBuf::<VulkanEngine, [f32; 3]>::upload(&engine, "export", &x)?;
        println!(
            "positions as vk::Buffer {:?} ({} bytes) for the application's own pipelines",
            staged.raw.handle(),
            staged.raw.size()
        );
        // Import: an application buffer (here: made with the same device) for the engine to
        // read back (or bind in its recordings).
        let info = vk::BufferCreateInfo::default()
            .size(staged.raw.size())
            .usage(
                vk::BufferUsageFlags::STORAGE_BUFFER
                    | vk::BufferUsageFlags::TRANSFER_SRC
                    | vk::BufferUsageFlags::TRANSFER_DST,
            );
        // SAFETY: valid create info; destroyed below after the engine is done with it.
        let app_buffer = unsafe { device.create_buffer(&info, None)? };
        // SAFETY: the buffer belongs to this device.
        let req = unsafe { device.get_buffer_memory_requirements(app_buffer) };
        // SAFETY: plain query.
        let mem_props = unsafe { instance.get_physical_device_memory_properties(physical) };
        let type_index = (0..mem_props.memory_type_count)
            .find(|&i| req.memory_type_bits & (1 << i) != 0)
            .ok_or("no memory type")?;
        // SAFETY: valid allocation info; freed below.
        let memory = unsafe {
            device.allocate_memory(
                &vk::MemoryAllocateInfo::default()
                    .allocation_size(req.size)
                    .memory_type_index(type_index),
                None,
            )?
        };
        // SAFETY: unbound buffer, fresh memory of the right size.
        unsafe { device.bind_buffer_memory(app_buffer, memory, 0)? };
        // SAFETY: the buffer belongs to the engine's device, has storage and transfer usage,
        // and is destroyed only after `engine.finish()`.
        let imported = unsafe { engine.import_buffer(app_buffer, staged.raw.size()) };
        engine.write(&imported, bytemuck::cast_slice(&x))?;
        let back = engine.read(&imported, 12)?;
        println!(
            "the engine wrote and read the application's buffer: {:?}",
            &back[..4]
        );
        engine.finish()?;
        drop(imported);
        // SAFETY: the engine is done with the buffer (finish above).
        unsafe {
            device.destroy_buffer(app_buffer, None);
            device.free_memory(memory, None);
        }
    }
    // The engine is gone; the application still owns (and now destroys) its device.
    // SAFETY: nothing made from them is alive.
    unsafe {
        device.destroy_device(None);
        instance.destroy_instance(None);
    }
    Ok(())
}

/// The example runs as a test too (`test = true` in Cargo.toml): skipped without a Vulkan
/// device unless `R4D_REQUIRE_GPU=1`, as the other Vulkan tests.
#[test]
fn the_embedding_example_runs() {
    if r4d_backend_vulkan::testing::vulkan_or_skip("embed example").is_none() {
        return;
    }
    main().unwrap();
}
