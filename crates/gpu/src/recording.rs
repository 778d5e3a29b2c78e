//! A recording: the commands of a GPU stage over buffer handles, built once by
//! [`crate::Gpu`] and executed by an engine ([`crate::GpuEngine::execute`]).

use bytemuck::Pod;
use r4d_shaders::Kernel;

/// What a command refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Resource {
    /// The `i`-th buffer registered with [`Recording::buf`] (the engine's own buffers).
    Buffer(usize),
    /// The `i`-th uniform of [`Recording::uniforms`] (created by the engine for this
    /// recording only).
    Uniform(usize),
    /// The `i`-th storage block of [`Recording::data`] (created by the engine for this
    /// recording only, read-only to the kernels).
    Data(usize),
    /// The `i`-th zero-filled scratch buffer of [`Recording::scratch`] (created by the engine
    /// for this recording only: prefix-sum partials, histograms).
    Scratch(usize),
}

/// One command.
#[derive(Clone, Debug)]
pub enum Command {
    /// Runs `kernel` over `groups` workgroups with `bindings` at bindings 0, 1, ... of group 0
    /// (the engine picks the kernel's compare-exchange variant where the device has no float
    /// atomics).
    Dispatch {
        /// The kernel.
        kernel: &'static Kernel,
        /// Workgroups along x, y, z.
        groups: [u32; 3],
        /// One resource per binding of the kernel.
        bindings: Vec<Resource>,
    },
    /// Zeroes a whole buffer.
    Clear(Resource),
    /// Copies `bytes` bytes of `src` from byte `src_offset` into `dst` at `dst_offset`.
    Copy {
        /// Source.
        src: Resource,
        /// Byte offset in the source (a multiple of 4).
        src_offset: u64,
        /// Destination.
        dst: Resource,
        /// Byte offset in the destination (a multiple of 4).
        dst_offset: u64,
        /// Bytes (a multiple of 4).
        bytes: u64,
    },
}

impl Command {
    /// The resources a dispatch binds (empty for other commands).
    pub fn bindings(&self) -> &[Resource] {
        match self {
            Command::Dispatch { bindings, .. } => bindings,
            _ => &[],
        }
    }
}

/// Commands over buffer handles of type `R` (an engine's raw buffer), in execution order.
#[derive(Debug)]
pub struct Recording<'a, R> {
    /// Buffers the commands use, registered by [`Recording::buf`].
    pub buffers: Vec<&'a R>,
    /// Uniform blocks (bytes), one buffer each.
    pub uniforms: Vec<Vec<u8>>,
    /// Read-only storage blocks (bytes), one buffer each.
    pub data: Vec<Vec<u8>>,
    /// Sizes in bytes of the zero-filled scratch buffers.
    pub scratch: Vec<u64>,
    /// The commands.
    pub commands: Vec<Command>,
}

impl<R> Default for Recording<'_, R> {
    fn default() -> Self {
        Recording {
            buffers: Vec::new(),
            uniforms: Vec::new(),
            data: Vec::new(),
            scratch: Vec::new(),
            commands: Vec::new(),
        }
    }
}

/// Most workgroups along one dimension (WebGPU's guaranteed minimum); larger 1D dispatches
/// continue along y.
pub const MAX_GROUPS_PER_DIM: u32 = 65535;

impl<'a, R> Recording<'a, R> {
    /// An empty recording.
    pub fn new() -> Self {
        Self::default()
    }

    /// Registers a buffer.
    pub fn buf(&mut self, b: &'a R) -> Resource {
        self.buffers.push(b);
        Resource::Buffer(self.buffers.len() - 1)
    }

    /// A uniform block holding `v`.
    pub fn uniform<T: Pod>(&mut self, v: &T) -> Resource {
        self.uniforms.push(bytemuck::bytes_of(v).to_vec());
        Resource::Uniform(self.uniforms.len() - 1)
    }

    /// A read-only storage block holding `v`.
    pub fn data<T: Pod>(&mut self, v: &[T]) -> Resource {
        self.data.push(bytemuck::cast_slice(v).to_vec());
        Resource::Data(self.data.len() - 1)
    }

    /// A zero-filled scratch buffer of at least `bytes` bytes, alive for this recording.
    pub fn scratch(&mut self, bytes: u64) -> Resource {
        self.scratch.push(bytes);
        Resource::Scratch(self.scratch.len() - 1)
    }

    /// Dispatches `kernel` over `threads` invocations (workgroups of its reflected size, split
    /// over y beyond [`MAX_GROUPS_PER_DIM`]); nothing for zero threads.
    pub fn dispatch(&mut self, kernel: &'static Kernel, threads: u32, bindings: &[Resource]) {
        if threads == 0 {
            return;
        }
        let groups = threads.div_ceil(kernel.threads_per_group());
        let g = if groups <= MAX_GROUPS_PER_DIM {
            [groups, 1, 1]
        } else {
            [MAX_GROUPS_PER_DIM, groups.div_ceil(MAX_GROUPS_PER_DIM), 1]
        };
        self.dispatch_groups(kernel, g, bindings);
    }

    /// Dispatches `kernel` over a grid of workgroups.
    pub fn dispatch_groups(
        &mut self,
        kernel: &'static Kernel,
        groups: [u32; 3],
        bindings: &[Resource],
    ) {
        debug_assert_eq!(
            bindings.len(),
            kernel.bindings.len(),
            "{}: binding count",
            kernel.name
        );
        self.commands.push(Command::Dispatch {
            kernel,
            groups,
            bindings: bindings.to_vec(),
        });
    }

    /// Zeroes a buffer.
    pub fn clear(&mut self, r: Resource) {
        self.commands.push(Command::Clear(r));
    }

    /// Copies the first `bytes` bytes of `src` to the start of `dst` (nothing for zero bytes).
    pub fn copy(&mut self, src: Resource, dst: Resource, bytes: u64) {
        self.copy_range(src, 0, dst, 0, bytes);
    }

    /// Copies `bytes` bytes from `src` at `src_offset` to `dst` at `dst_offset`.
    pub fn copy_range(
        &mut self,
        src: Resource,
        src_offset: u64,
        dst: Resource,
        dst_offset: u64,
        bytes: u64,
    ) {
        if bytes > 0 {
            self.commands.push(Command::Copy {
                src,
                src_offset,
                dst,
                dst_offset,
                bytes,
            });
        }
    }

    /// The kernels dispatched, in order (for tests and traces).
    pub fn kernels(&self) -> Vec<&'static str> {
        self.commands
            .iter()
            .filter_map(|c| match c {
                Command::Dispatch { kernel, .. } => Some(kernel.name),
                _ => None,
            })
            .collect()
    }
}
