//! # r4d-frames: frames and videos
//!
//! The video types every layer of resonance4d shares, below the losses and the codecs:
//! [`Video`] (`(T, H, W, 3)` RGB in f32 or f64, row 0 at the top), [`Video8`] (8-bit values
//! `k / 255`), [`ReferenceVideo`] (a reference kept compact) and [`io`] (PNG folders and
//! `.npy` files). A malformed video is a [`FrameError`] naming the input.
//!
//! ```
//! use r4d_frames::{Video, Video8};
//! let v = Video::<f32>::from_frames(2, 2, vec![vec![1.0; 12], vec![0.0; 12]]).unwrap();
//! assert_eq!((v.frames(), v.height(), v.width()), (2, 2, 2));
//! let bytes = Video8::from_exact(&v).unwrap();
//! assert_eq!(bytes.data()[0], 255);
//! ```

mod error;
pub mod io;
mod video;
mod video8;

pub use error::{FrameError, Input};
pub use r4d_math::Real;
pub use video::{check_shape, Video};
pub use video8::{ReferenceVideo, Video8};
