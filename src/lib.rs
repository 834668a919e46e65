//! gpustar: lost-in-space star identification and attitude determination for archives of sky
//! frames.
//!
//! The pipeline, one folder per part:
//! [`io`] (decode frames and FITS headers) → [`solve`] (detect → identify by vote, or radial
//! features → attitude → refine) → [`record`] → [`io::output`] (JSON Lines or CSV).
//! The pixel and voting kernels are WGSL in `shaders/` with CPU twins of the same names in
//! [`cpu`] and host code in [`gpu`]. [`catalog`] prepares the reference stars and the sorted
//! distance table; [`pipeline`] runs one frame on either backend; [`batch`] runs many files;
//! [`streaks`] finds and reduces satellite streaks, with times, stations and Az/El from [`sky`];
//! [`sequence`] tracks sequences of frames and rejects moving particles; [`calibrate`] fits the
//! camera; [`products`] writes WCS headers and annotated images; [`simulate`] makes and scores
//! synthetic sets; [`report`] summarises a run's records (text and an HTML page). [`simd`] runs
//! the CPU's hot loops compiled again for AVX2 where it has it.

pub mod batch;
pub mod calibrate;
pub mod camera;
pub mod catalog;
pub mod choice;
pub mod config;
pub mod cpu;
pub mod error;
pub mod files;
pub mod front;
pub mod gpu;
pub mod io;
pub mod pipeline;
pub mod products;
pub mod record;
pub mod report;
pub mod sequence;
pub mod simd;
pub mod simulate;
pub mod sky;
pub mod solve;
pub mod streaks;

// The library's API: what a user needs to solve frames, read the records and handle errors.
// Everything else stays reachable through its module.
pub use batch::{RunOptions, RunSummary, run};
pub use camera::Camera;
pub use catalog::Catalog;
pub use error::{Error, Result};
pub use io::frame::Frame;
pub use pipeline::{Backend, CameraSource, Pipeline};
pub use record::{MatchRecord, Record, Status};
pub use sequence::SequenceOptions;
pub use sky::{Station, Utc};
pub use solve::{Settings, Solver};
pub use streaks::StreakOptions;

#[cfg(test)]
mod fuzz;
