//! Part assignment against the synthetic scenes' analytic labels: the three-part scene and the
//! plant (masks ray-cast from the solids, independent of the renderer). One binary; run one
//! module with `cargo test -p r4d-segment --test segment -- MODULE::`.

mod segment;
mod segment_plant;
