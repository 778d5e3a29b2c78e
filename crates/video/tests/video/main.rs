//! The video crate's integration tests, in one binary: MP4 round trips and errors, and MP4
//! files written by another project's code (ffmpeg).

mod ffmpeg_fixtures;
mod mp4;
