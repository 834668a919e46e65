//! gpustar's integration tests as one binary: one module per stage (the same name as its
//! kernel in `shaders/`, its CPU twin in `src/cpu/` and its GPU host code in `src/gpu/`), plus
//! end-to-end runs of the binary, real frames, faults and the WGSL layouts. One binary links
//! wgpu once, where one per file linked it 30 times.
//!
//! Tests that need a GPU adapter or `../shared` print `SKIPPED <test>: <why>` when these are
//! absent; with `CI=true` they fail instead (see `common`).

mod common;

mod astrometry_products;
mod attitude;
mod backend;
mod bad_input;
mod batch_inputs;
mod catalog;
mod catalog_files;
mod centroid;
mod components;
mod confidence;
mod config;
mod dark;
mod end_to_end;
mod explain;
mod faults;
mod fits;
mod formats;
mod frames;
mod fz;
mod gpu_pipeline;
mod help;
mod hint;
mod imports;
mod layout;
mod noise;
mod outputs;
mod parity;
mod pattern;
mod pixel_aspect;
mod psf_fit;
mod radial;
mod real;
mod refine;
mod report;
mod resume;
mod scale;
mod select;
mod sequence;
mod simd;
mod simulate_narrow;
mod spread;
mod streaks;
mod streaks_cli;
mod table;
mod threshold;
mod tile_clip;
mod tracklets_cli;
mod triangle;
mod unseen;
mod vote;
mod wcs;
