//! The examples run as tests (`cargo test` runs their `main`), so every one is checked by the
//! suite: each asserts its own result.

#[path = "../../examples/frame_loop.rs"]
mod frame_loop;

#[path = "../../examples/fit_video.rs"]
mod fit_video;

#[path = "../../examples/custom_loss.rs"]
mod custom_loss;

#[path = "../../examples/counting_backend.rs"]
mod counting_backend;

#[test]
fn frame_loop_writes_its_frames() {
    frame_loop::main().unwrap();
}

#[test]
fn fit_video_recovers_e() {
    fit_video::main().unwrap();
}

#[test]
fn custom_loss_recovers_e() {
    custom_loss::main().unwrap();
}

#[test]
fn counting_backend_gives_the_cpus_fit() {
    counting_backend::main().unwrap();
}
