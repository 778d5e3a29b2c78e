//! The Vulkan device: instance, physical device choice, one compute queue, the memory
//! allocator, buffers and the pipeline cache. Everything is destroyed in order when the last
//! [`Device`] handle (engine or buffer) goes away.

use crate::VulkanError;
use ash::vk;
use gpu_allocator::vulkan::{
    Allocation, AllocationCreateDesc, AllocationScheme, Allocator, AllocatorCreateDesc,
};
use gpu_allocator::MemoryLocation;
use r4d_shaders::{BindingKind, Kernel};
use std::collections::HashMap;
use std::ffi::CStr;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

/// A compute pipeline of one kernel.
pub(crate) struct Pipeline {
    pub layout: vk::PipelineLayout,
    pub set_layout: vk::DescriptorSetLayout,
    pub pipeline: vk::Pipeline,
    module: vk::ShaderModule,
}

/// The Khronos validation layer's name.
const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// Counts (and prints) the validation layer's warnings and errors.
unsafe extern "system" fn on_message(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut std::ffi::c_void,
) -> vk::Bool32 {
    if severity.intersects(
        vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
            | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
    ) {
        // SAFETY: `user` is the device's counter, alive as long as the messenger; `data` is
        // valid for the call.
        unsafe {
            (*(user as *const AtomicUsize)).fetch_add(1, Ordering::Relaxed);
            let msg = data
                .as_ref()
                .and_then(|d| d.message_as_c_str())
                .map(|m| m.to_string_lossy().into_owned())
                .unwrap_or_default();
            eprintln!("vulkan validation ({severity:?}): {msg}");
        }
    }
    vk::FALSE
}

/// The validation messenger and its counter.
struct Validation {
    utils: ash::ext::debug_utils::Instance,
    messenger: vk::DebugUtilsMessengerEXT,
    count: Box<AtomicUsize>,
}

/// The device and what lives as long as it.
pub(crate) struct Device {
    // Kept loaded for the instance's lifetime.
    _entry: ash::Entry,
    validation: Option<Validation>,
    pub instance: ash::Instance,
    pub device: ash::Device,
    pub queue: Mutex<vk::Queue>,
    pub queue_family: u32,
    pub allocator: Mutex<Option<Allocator>>,
    pub pipelines: Mutex<HashMap<&'static str, Arc<Pipeline>>>,
    /// The adapter's name (`VkPhysicalDeviceProperties::deviceName`).
    pub name: String,
    /// The device type (discrete, integrated, virtual, CPU).
    pub kind: vk::PhysicalDeviceType,
    /// `VK_EXT_shader_atomic_float`'s buffer float32 add is enabled: scatter kernels run
    /// their native variant (else their compare-exchange one).
    pub float_atomics: bool,
    /// Nanoseconds per timestamp tick (`VkPhysicalDeviceLimits::timestampPeriod`).
    pub timestamp_period_ns: f32,
    /// Valid bits of the queue family's timestamps (0: none).
    pub timestamp_bits: u32,
    pub in_use: AtomicU64,
    pub peak: AtomicU64,
    /// Bytes copied from the host to device buffers (writes, recordings' uniforms and data).
    pub uploaded: AtomicU64,
    /// Bytes read back from device buffers.
    pub downloaded: AtomicU64,
    /// Buffers dropped while a pending command buffer may still use them: freed by
    /// [`Device::collect`] once the engine has waited for its submissions.
    graveyard: Mutex<Vec<(vk::Buffer, Option<Allocation>)>>,
    /// Bytes in the graveyard.
    pub graveyard_bytes: AtomicU64,
    /// The instance and device were created here (destroyed with it); `false`: the host
    /// application's ([`crate::HostDevice`]), left alive.
    owned: bool,
    /// The pipeline cache, loaded from and saved to `cache_path`.
    pipeline_cache: vk::PipelineCache,
    cache_path: Option<std::path::PathBuf>,
}

/// The valid timestamp bits of queue family `family` of `pd` (0 when out of range).
fn timestamp_bits(instance: &ash::Instance, pd: vk::PhysicalDevice, family: u32) -> u32 {
    // SAFETY: pd belongs to the instance.
    let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
    families
        .get(family as usize)
        .map_or(0, |f| f.timestamp_valid_bits)
}

/// The largest pipeline cache file read (bytes).
const MAX_CACHE_BYTES: u64 = 256 << 20;

/// Where the pipeline cache of a device lives: `R4D_VULKAN_PIPELINE_CACHE` (a file; `off`
/// disables it), else `$XDG_CACHE_HOME/r4d/` or `~/.cache/r4d/`, one file per vendor and
/// device id.
fn cache_path(props: &vk::PhysicalDeviceProperties) -> Option<std::path::PathBuf> {
    match std::env::var_os("R4D_VULKAN_PIPELINE_CACHE") {
        Some(p) if p == "off" => None,
        Some(p) => Some(p.into()),
        None => {
            let base = std::env::var_os("XDG_CACHE_HOME")
                .map(std::path::PathBuf::from)
                .or_else(|| {
                    std::env::var_os("HOME").map(|h| std::path::Path::new(&h).join(".cache"))
                })?;
            Some(base.join("r4d").join(format!(
                "vulkan-pipelines-{:04x}-{:04x}.bin",
                props.vendor_id, props.device_id
            )))
        }
    }
}

/// The cache file: this magic, the checksum of the data ([`r4d_fsio::Fingerprint`], 32 hex
/// digits), then the driver's pipeline cache data.
const CACHE_MAGIC: &[u8; 8] = b"R4DVKPC1";

fn cache_checksum(data: &[u8]) -> String {
    let mut f = r4d_fsio::Fingerprint::new();
    f.bytes(data);
    f.finish()
}

/// A pipeline cache seeded with `path`'s data when it is whole (magic and checksum) and its
/// header is this device's (Vulkan's header: length, version 1, vendor id, device id,
/// pipeline cache UUID); anything else (missing, damaged, another device's or driver's, too
/// large) starts empty: a driver never sees bytes it did not write.
fn load_cache(
    device: &ash::Device,
    props: &vk::PhysicalDeviceProperties,
    path: Option<&std::path::Path>,
) -> vk::PipelineCache {
    let data = path
        .filter(|p| std::fs::metadata(p).is_ok_and(|m| m.len() <= MAX_CACHE_BYTES))
        .and_then(|p| std::fs::read(p).ok())
        .filter(|f| {
            f.len() >= 40
                && &f[..8] == CACHE_MAGIC
                && f[8..40] == *cache_checksum(&f[40..]).as_bytes()
        })
        .map(|f| f[40..].to_vec())
        .filter(|d| {
            let u = |o: usize| u32::from_le_bytes([d[o], d[o + 1], d[o + 2], d[o + 3]]);
            d.len() >= 32
                && u(0) >= 32
                && u(4) == 1
                && u(8) == props.vendor_id
                && u(12) == props.device_id
                && d[16..32] == props.pipeline_cache_uuid
        })
        .unwrap_or_default();
    let info = vk::PipelineCacheCreateInfo::default().initial_data(&data);
    // SAFETY: valid create info (the data was checked against this device's header); an
    // error falls back to no cache.
    unsafe { device.create_pipeline_cache(&info, None) }
        .unwrap_or_else(|_| vk::PipelineCache::null())
}

/// A device buffer (storage, uniform, copy source and destination).
pub struct VkBuffer {
    pub(crate) buffer: vk::Buffer,
    pub(crate) size: u64,
    allocation: Mutex<Option<Allocation>>,
    counted: bool,
    /// Created (and destroyed) by the engine; `false`: imported, the host's to destroy.
    owned: bool,
    pub(crate) dev: Arc<Device>,
}

impl std::fmt::Debug for VkBuffer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VkBuffer")
            .field("size", &self.size)
            .finish_non_exhaustive()
    }
}

fn vk_err(what: &'static str) -> impl Fn(vk::Result) -> VulkanError {
    move |result| VulkanError::Vk { what, result }
}

impl Device {
    /// Opens the Vulkan loader and a device with a compute queue. `wanted`
    /// (`R4D_VULKAN_DEVICE`): the device's index in the loader's enumeration (a number), or
    /// a substring of its name; otherwise discrete > integrated > virtual > CPU.
    pub fn new(
        wanted: Option<&str>,
        allow_float_atomics: bool,
    ) -> Result<Arc<Device>, VulkanError> {
        // SAFETY: loading the system's Vulkan loader; its symbols are used only through ash.
        let entry =
            unsafe { ash::Entry::load() }.map_err(|e| VulkanError::NoLoader(e.to_string()))?;
        let app = vk::ApplicationInfo::default()
            .application_name(c"resonance4d")
            .api_version(vk::API_VERSION_1_1);
        let validate = std::env::var("R4D_VULKAN_VALIDATION").is_ok_and(|v| v == "1");
        let (layers, extensions) = if validate {
            // SAFETY: plain queries of the loader.
            let available = unsafe { entry.enumerate_instance_layer_properties() }
                .map_err(vk_err("vkEnumerateInstanceLayerProperties"))?;
            if !available
                .iter()
                .any(|l| l.layer_name_as_c_str().is_ok_and(|n| n == VALIDATION_LAYER))
            {
                return Err(VulkanError::NoDevice(
                    ": R4D_VULKAN_VALIDATION=1 but the Khronos validation layer is not installed (vulkan-validationlayers)".into(),
                ));
            }
            (
                vec![VALIDATION_LAYER.as_ptr()],
                vec![ash::ext::debug_utils::NAME.as_ptr()],
            )
        } else {
            (Vec::new(), Vec::new())
        };
        let ici = vk::InstanceCreateInfo::default()
            .application_info(&app)
            .enabled_layer_names(&layers)
            .enabled_extension_names(&extensions);
        // SAFETY: valid create info; the instance is destroyed in Drop.
        let instance =
            unsafe { entry.create_instance(&ici, None) }.map_err(vk_err("vkCreateInstance"))?;
        let validation = if validate {
            let utils = ash::ext::debug_utils::Instance::new(&entry, &instance);
            let count = Box::new(AtomicUsize::new(0));
            let info = vk::DebugUtilsMessengerCreateInfoEXT::default()
                .message_severity(
                    vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                        | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
                )
                .message_type(
                    vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                        | vk::DebugUtilsMessageTypeFlagsEXT::GENERAL,
                )
                .pfn_user_callback(Some(on_message))
                .user_data(&*count as *const AtomicUsize as *mut std::ffi::c_void);
            // SAFETY: the counter is boxed and outlives the messenger (destroyed in Drop).
            match unsafe { utils.create_debug_utils_messenger(&info, None) } {
                Ok(messenger) => Some(Validation {
                    utils,
                    messenger,
                    count,
                }),
                Err(result) => {
                    // SAFETY: nothing else was created from the instance.
                    unsafe { instance.destroy_instance(None) };
                    return Err(VulkanError::Vk {
                        what: "vkCreateDebugUtilsMessengerEXT",
                        result,
                    });
                }
            }
        } else {
            None
        };
        let mut validation = validation;
        // `open` keeps a clone of the loader on success; this one stays loaded until the
        // instance is destroyed on failure (dropping the last clone unloads libvulkan, and
        // destroying the instance after that crashed: found by `tests/device_choice.rs`).
        match Self::open(
            entry.clone(),
            instance.clone(),
            wanted,
            allow_float_atomics,
            &mut validation,
        ) {
            Ok(d) => Ok(d),
            Err(e) => {
                // SAFETY: nothing else was created from the instance.
                unsafe {
                    if let Some(v) = validation {
                        v.utils.destroy_debug_utils_messenger(v.messenger, None);
                    }
                    instance.destroy_instance(None)
                };
                drop(entry);
                Err(e)
            }
        }
    }

    /// Warnings and errors the validation layer reported (0 without `R4D_VULKAN_VALIDATION=1`).
    pub fn validation_messages(&self) -> usize {
        self.validation
            .as_ref()
            .map_or(0, |v| v.count.load(Ordering::Relaxed))
    }

    /// Opens the device; `validation` moves into it on success and stays with the caller on
    /// failure (to be destroyed with the instance).
    fn open(
        entry: ash::Entry,
        instance: ash::Instance,
        wanted: Option<&str>,
        allow_float_atomics: bool,
        validation: &mut Option<Validation>,
    ) -> Result<Arc<Device>, VulkanError> {
        // SAFETY: the instance is valid.
        let pds = unsafe { instance.enumerate_physical_devices() }
            .map_err(vk_err("vkEnumeratePhysicalDevices"))?;
        let rank = |t: vk::PhysicalDeviceType| match t {
            vk::PhysicalDeviceType::DISCRETE_GPU => 0,
            vk::PhysicalDeviceType::INTEGRATED_GPU => 1,
            vk::PhysicalDeviceType::VIRTUAL_GPU => 2,
            vk::PhysicalDeviceType::CPU => 3,
            _ => 4,
        };
        let mut found: Vec<(
            usize,
            vk::PhysicalDevice,
            u32,
            String,
            vk::PhysicalDeviceType,
        )> = Vec::new();
        let mut names = Vec::new();
        let wanted_index = wanted.and_then(|w| w.trim().parse::<usize>().ok());
        for (index, pd) in pds.into_iter().enumerate() {
            // SAFETY: pd comes from this instance.
            let props = unsafe { instance.get_physical_device_properties(pd) };
            let name = props
                .device_name_as_c_str()
                .map(|c: &CStr| c.to_string_lossy().into_owned())
                .unwrap_or_default();
            names.push(format!("{index}: {name}"));
            if props.api_version < vk::API_VERSION_1_1 {
                continue;
            }
            // SAFETY: pd comes from this instance.
            let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
            let Some(q) = families
                .iter()
                .position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE))
            else {
                continue;
            };
            let chosen = match (wanted_index, wanted) {
                (Some(k), _) => k == index,
                (None, Some(w)) => name.contains(w),
                (None, None) => true,
            };
            if !chosen {
                continue;
            }
            found.push((
                rank(props.device_type),
                pd,
                q as u32,
                name,
                props.device_type,
            ));
        }
        found.sort_by_key(|f| f.0);
        let Some((_, pd, queue_family, name, kind)) = found.into_iter().next() else {
            return Err(VulkanError::NoDevice(match wanted {
                Some(w) => format!(
                    " matching R4D_VULKAN_DEVICE={w} (devices: {})",
                    names.join(", ")
                ),
                None => format!(
                    " with Vulkan 1.1 and a compute queue (devices: {})",
                    if names.is_empty() {
                        "none".to_string()
                    } else {
                        names.join(", ")
                    }
                ),
            }));
        };
        let prio = [1.0f32];
        let qci = [vk::DeviceQueueCreateInfo::default()
            .queue_family_index(queue_family)
            .queue_priorities(&prio)];
        // Native float atomics where the device has VK_EXT_shader_atomic_float's buffer add.
        let atomic_ext = ash::ext::shader_atomic_float::NAME;
        // SAFETY: pd comes from this instance.
        let has_ext = unsafe { instance.enumerate_device_extension_properties(pd) }
            .map_err(vk_err("vkEnumerateDeviceExtensionProperties"))?
            .iter()
            .any(|e| e.extension_name_as_c_str().is_ok_and(|n| n == atomic_ext));
        let float_atomics = allow_float_atomics && has_ext && {
            let mut af = vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT::default();
            let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut af);
            // SAFETY: pd comes from this instance (Vulkan 1.1 core query).
            unsafe { instance.get_physical_device_features2(pd, &mut f2) };
            af.shader_buffer_float32_atomic_add == vk::TRUE
        };
        let ext_names = [atomic_ext.as_ptr()];
        let mut enable = vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT::default()
            .shader_buffer_float32_atomic_add(true);
        let mut dci = vk::DeviceCreateInfo::default().queue_create_infos(&qci);
        if float_atomics {
            dci = dci
                .enabled_extension_names(&ext_names)
                .push_next(&mut enable);
        }
        // SAFETY: valid create info; destroyed in Drop.
        let device =
            unsafe { instance.create_device(pd, &dci, None) }.map_err(vk_err("vkCreateDevice"))?;
        // SAFETY: the family and index exist (one queue was requested).
        let queue = unsafe { device.get_device_queue(queue_family, 0) };
        let allocator = Allocator::new(&AllocatorCreateDesc {
            instance: instance.clone(),
            device: device.clone(),
            physical_device: pd,
            debug_settings: Default::default(),
            buffer_device_address: false,
            allocation_sizes: Default::default(),
        })
        .map_err(|e| {
            // SAFETY: nothing was created from the device.
            unsafe { device.destroy_device(None) };
            VulkanError::Alloc(e.to_string())
        })?;
        // SAFETY: pd belongs to the instance.
        let props = unsafe { instance.get_physical_device_properties(pd) };
        let timestamp_bits = timestamp_bits(&instance, pd, queue_family);
        let cache_path = cache_path(&props);
        let pipeline_cache = load_cache(&device, &props, cache_path.as_deref());
        Ok(Arc::new(Device {
            timestamp_period_ns: props.limits.timestamp_period,
            timestamp_bits,
            pipeline_cache,
            cache_path,
            _entry: entry,
            validation: validation.take(),
            instance,
            device,
            queue: Mutex::new(queue),
            queue_family,
            allocator: Mutex::new(Some(allocator)),
            pipelines: Mutex::new(HashMap::new()),
            name,
            kind,
            float_atomics,
            in_use: AtomicU64::new(0),
            peak: AtomicU64::new(0),
            uploaded: AtomicU64::new(0),
            downloaded: AtomicU64::new(0),
            graveyard: Mutex::new(Vec::new()),
            graveyard_bytes: AtomicU64::new(0),
            owned: true,
        }))
    }

    /// A buffer of at least `bytes` bytes at `location` (not zeroed). `counted`: included in
    /// the memory report (the engine's buffers; not staging or per-recording blocks).
    pub fn buffer(
        self: &Arc<Self>,
        label: &str,
        bytes: u64,
        location: MemoryLocation,
        counted: bool,
    ) -> Result<VkBuffer, VulkanError> {
        // Vulkan has no empty buffers; storage offsets and sizes are multiples of 4.
        let size = bytes.max(4).div_ceil(4) * 4;
        let info = vk::BufferCreateInfo::default()
            .size(size)
            .usage(
                vk::BufferUsageFlags::STORAGE_BUFFER
                    | vk::BufferUsageFlags::UNIFORM_BUFFER
                    | vk::BufferUsageFlags::TRANSFER_SRC
                    | vk::BufferUsageFlags::TRANSFER_DST,
            )
            .sharing_mode(vk::SharingMode::EXCLUSIVE);
        // SAFETY: valid create info; the buffer is destroyed in VkBuffer's Drop.
        let buffer =
            unsafe { self.device.create_buffer(&info, None) }.map_err(vk_err("vkCreateBuffer"))?;
        // SAFETY: the buffer was created from this device.
        let requirements = unsafe { self.device.get_buffer_memory_requirements(buffer) };
        let mut guard = self.allocator.lock().unwrap_or_else(|e| e.into_inner());
        let allocator = guard.as_mut().ok_or(VulkanError::Lost)?;
        let allocation = allocator
            .allocate(&AllocationCreateDesc {
                name: label,
                requirements,
                location,
                linear: true,
                allocation_scheme: AllocationScheme::GpuAllocatorManaged,
            })
            .map_err(|e| {
                // SAFETY: the buffer is unused.
                unsafe { self.device.destroy_buffer(buffer, None) };
                VulkanError::OutOfMemory {
                    label: label.to_string(),
                    bytes: size,
                    message: e.to_string(),
                }
            })?;
        // SAFETY: the memory is unbound, large enough, and outlives the buffer.
        let bound = unsafe {
            self.device
                .bind_buffer_memory(buffer, allocation.memory(), allocation.offset())
        };
        if let Err(result) = bound {
            // SAFETY: the buffer is unused; its memory goes back to the allocator.
            unsafe { self.device.destroy_buffer(buffer, None) };
            let _ = allocator.free(allocation);
            return Err(VulkanError::Vk {
                what: "vkBindBufferMemory",
                result,
            });
        }
        drop(guard);
        if counted {
            let now = self.in_use.fetch_add(size, Ordering::Relaxed) + size;
            self.peak.fetch_max(now, Ordering::Relaxed);
        }
        Ok(VkBuffer {
            buffer,
            size,
            allocation: Mutex::new(Some(allocation)),
            counted,
            owned: true,
            dev: self.clone(),
        })
    }

    /// The pipeline of `kernel` (built once, then cached).
    pub fn pipeline(&self, kernel: &'static Kernel) -> Result<Arc<Pipeline>, VulkanError> {
        let mut cache = self.pipelines.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(p) = cache.get(kernel.name) {
            return Ok(p.clone());
        }
        let d = &self.device;
        let bindings: Vec<vk::DescriptorSetLayoutBinding> = kernel
            .bindings
            .iter()
            .enumerate()
            .map(|(i, b)| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(i as u32)
                    .descriptor_type(match b.kind {
                        BindingKind::Uniform => vk::DescriptorType::UNIFORM_BUFFER,
                        BindingKind::Storage { .. } => vk::DescriptorType::STORAGE_BUFFER,
                    })
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        let words = kernel.spirv_words();
        // SAFETY: valid create infos; every object is destroyed in Device's Drop.
        unsafe {
            let set_layout = d
                .create_descriptor_set_layout(
                    &vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings),
                    None,
                )
                .map_err(vk_err("vkCreateDescriptorSetLayout"))?;
            let layouts = [set_layout];
            let layout = d
                .create_pipeline_layout(
                    &vk::PipelineLayoutCreateInfo::default().set_layouts(&layouts),
                    None,
                )
                .map_err(vk_err("vkCreatePipelineLayout"))?;
            let module = d
                .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)
                .map_err(vk_err("vkCreateShaderModule"))?;
            let stage = vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::COMPUTE)
                .module(module)
                .name(c"main");
            let info = [vk::ComputePipelineCreateInfo::default()
                .stage(stage)
                .layout(layout)];
            let pipeline = d
                .create_compute_pipelines(self.pipeline_cache, &info, None)
                .map_err(|(_, result)| VulkanError::Vk {
                    what: "vkCreateComputePipelines",
                    result,
                })?[0];
            let p = Arc::new(Pipeline {
                layout,
                set_layout,
                pipeline,
                module,
            });
            cache.insert(kernel.name, p.clone());
            Ok(p)
        }
    }
}

impl Device {
    /// A device the host application created ([`crate::HostDevice`]); it stays the host's.
    pub fn from_host(h: crate::HostDevice) -> Result<Arc<Device>, VulkanError> {
        let crate::HostDevice {
            entry,
            instance,
            physical_device,
            device,
            queue_family,
            queue_index,
            float_atomics,
        } = h;
        // SAFETY: the host guarantees the handles are valid and belong together.
        let props = unsafe { instance.get_physical_device_properties(physical_device) };
        let name = props
            .device_name_as_c_str()
            .map(|c: &CStr| c.to_string_lossy().into_owned())
            .unwrap_or_default();
        // SAFETY: the host created the device with this queue.
        let queue = unsafe { device.get_device_queue(queue_family, queue_index) };
        let timestamp_bits = timestamp_bits(&instance, physical_device, queue_family);
        let allocator = Allocator::new(&AllocatorCreateDesc {
            instance: instance.clone(),
            device: device.clone(),
            physical_device,
            debug_settings: Default::default(),
            buffer_device_address: false,
            allocation_sizes: Default::default(),
        })
        .map_err(|e| VulkanError::Alloc(e.to_string()))?;
        let cache_path = cache_path(&props);
        let pipeline_cache = load_cache(&device, &props, cache_path.as_deref());
        Ok(Arc::new(Device {
            timestamp_period_ns: props.limits.timestamp_period,
            timestamp_bits,
            pipeline_cache,
            cache_path,
            _entry: entry,
            validation: None,
            instance,
            device,
            queue: Mutex::new(queue),
            queue_family,
            allocator: Mutex::new(Some(allocator)),
            pipelines: Mutex::new(HashMap::new()),
            name,
            kind: props.device_type,
            float_atomics,
            in_use: AtomicU64::new(0),
            peak: AtomicU64::new(0),
            uploaded: AtomicU64::new(0),
            downloaded: AtomicU64::new(0),
            graveyard: Mutex::new(Vec::new()),
            graveyard_bytes: AtomicU64::new(0),
            owned: false,
        }))
    }

    /// Frees the dropped buffers. Call only when no submission that could use them is
    /// pending (the engine calls it after waiting for its fence).
    pub fn collect(&self) {
        let dead = std::mem::take(&mut *self.graveyard.lock().unwrap_or_else(|e| e.into_inner()));
        self.graveyard_bytes.store(0, Ordering::Relaxed);
        if dead.is_empty() {
            return;
        }
        let mut guard = self.allocator.lock().unwrap_or_else(|e| e.into_inner());
        for (buffer, allocation) in dead {
            // SAFETY: no pending submission uses the buffer (see above).
            unsafe { self.device.destroy_buffer(buffer, None) };
            if let (Some(a), Some(allocator)) = (allocation, guard.as_mut()) {
                let _ = allocator.free(a);
            }
        }
    }
}

impl VkBuffer {
    /// The Vulkan buffer (to share it with the host application: valid while this value
    /// lives; usage storage, uniform, transfer source and destination).
    pub fn handle(&self) -> vk::Buffer {
        self.buffer
    }

    /// Its size in bytes (a multiple of 4, at least what was asked for).
    pub fn size(&self) -> u64 {
        self.size
    }

    /// A buffer of the host application's, for the engine's kernels to use.
    ///
    /// # Safety
    /// `buffer` must be a buffer of `dev`'s device, at least `size` bytes long, created with
    /// storage-buffer and transfer usage, bound to memory, and alive until the engine has
    /// finished with it (after the engine's next read or `VulkanEngine::finish`); the engine
    /// never destroys it.
    pub(crate) unsafe fn import(dev: &Arc<Device>, buffer: vk::Buffer, size: u64) -> VkBuffer {
        VkBuffer {
            buffer,
            size,
            allocation: Mutex::new(None),
            counted: false,
            owned: false,
            dev: dev.clone(),
        }
    }

    /// Runs `f` on the buffer's mapped bytes (host-visible buffers only).
    pub(crate) fn mapped<R>(&self, f: impl FnOnce(&mut [u8]) -> R) -> Result<R, VulkanError> {
        let mut a = self.allocation.lock().unwrap_or_else(|e| e.into_inner());
        let slice = a
            .as_mut()
            .and_then(|a| a.mapped_slice_mut())
            .ok_or(VulkanError::NotMapped)?;
        Ok(f(slice))
    }
}

impl Drop for VkBuffer {
    fn drop(&mut self) {
        if !self.owned {
            return;
        }
        let a = self
            .allocation
            .get_mut()
            .unwrap_or_else(|e| e.into_inner())
            .take();
        // A pending command buffer may still use the buffer: destroyed once the engine has
        // waited for it (Device::collect).
        self.dev
            .graveyard
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push((self.buffer, a));
        self.dev
            .graveyard_bytes
            .fetch_add(self.size, Ordering::Relaxed);
        if self.counted {
            self.dev.in_use.fetch_sub(self.size, Ordering::Relaxed);
        }
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        // SAFETY: the last handle is gone: no buffer, submission or pipeline is in use.
        unsafe {
            let _ = self.device.device_wait_idle();
            self.collect();
            for (_, p) in self
                .pipelines
                .get_mut()
                .unwrap_or_else(|e| e.into_inner())
                .drain()
            {
                self.device.destroy_pipeline(p.pipeline, None);
                self.device.destroy_shader_module(p.module, None);
                self.device.destroy_pipeline_layout(p.layout, None);
                self.device
                    .destroy_descriptor_set_layout(p.set_layout, None);
            }
            if self.pipeline_cache != vk::PipelineCache::null() {
                if let (Some(path), Ok(data)) = (
                    &self.cache_path,
                    self.device.get_pipeline_cache_data(self.pipeline_cache),
                ) {
                    // Best effort: a cache that cannot be saved costs compile time only.
                    if let Some(dir) = path.parent() {
                        let _ = std::fs::create_dir_all(dir);
                    }
                    let mut file = CACHE_MAGIC.to_vec();
                    file.extend_from_slice(cache_checksum(&data).as_bytes());
                    file.extend_from_slice(&data);
                    let _ = r4d_fsio::write_atomic(path, &file);
                }
                self.device
                    .destroy_pipeline_cache(self.pipeline_cache, None);
            }
            // The allocator frees its memory blocks before the device goes.
            drop(
                self.allocator
                    .get_mut()
                    .unwrap_or_else(|e| e.into_inner())
                    .take(),
            );
            if self.owned {
                self.device.destroy_device(None);
                if let Some(v) = self.validation.take() {
                    v.utils.destroy_debug_utils_messenger(v.messenger, None);
                }
                self.instance.destroy_instance(None);
            }
        }
    }
}
