//! gpustar: lost-in-space star identification and attitude determination for archives of sky
//! frames.
//!
//! The pipeline, one module per stage:
//! [`frame`] (decode) → [`detect`] (`cpu::threshold` → `cpu::components` → `cpu::centroid` →
//! `cpu::psf_fit`) → [`identify`] (pair ranges → `cpu::vote` → `cpu::select` → verification;
//! or [`radial`]: `cpu::radial` → `cpu::select` → triangles, [`triangle`]) → [`attitude`]
//! (Wahba by SVD) → [`refine`] (match, refit, false-match probability) → [`record`].
//! [`catalog`] and [`table`] prepare the reference stars and the sorted distance table;
//! [`solve`] ties a camera to them; [`batch`] and [`run`] run many files ([`output`] writes
//! and resumes the records); [`streaks`] finds and reduces satellite streaks (times, Az/El,
//! TDM and IOD); [`sequence`] tracks sequences of frames and rejects moving particles;
//! [`calibrate`] fits the camera; [`simulate`] and [`evaluate`] make and score synthetic
//! sets.

pub mod annotate;
pub mod attitude;
pub mod batch;
pub mod calibrate;
pub mod camera;
pub mod catalog;
pub mod cli;
pub mod cpu;
pub mod dark;
pub mod detect;
pub mod evaluate;
pub mod fits;
pub mod frame;
pub mod gpu;
pub mod identify;
pub mod inputs;
pub mod output;
pub mod products;
pub mod radial;
pub mod record;
pub mod refine;
pub mod run;
pub mod sequence;
pub mod simulate;
pub mod solve;
pub mod streaks;
pub mod table;
pub mod triangle;
pub mod wcs;

#[cfg(test)]
mod fuzz;
