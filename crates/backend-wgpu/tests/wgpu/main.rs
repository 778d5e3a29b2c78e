//! The wgpu backend's integration tests, in one binary: the WGSL constitutive models against
//! the Rust reference, and the splat renderer and its gradients against the golden scenes.

mod constitutive;
mod splat;
