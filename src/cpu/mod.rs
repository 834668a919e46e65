//! The CPU twins of the GPU kernels: one module per stage, named as in `shaders/` and
//! `src/gpu/`, written as loops over what the GPU runs in parallel. `--backend cpu` runs them.

pub mod centroid;
pub mod components;
pub mod pattern;
pub mod psf_fit;
pub mod radial;
pub mod select;
pub mod streak_filter;
pub mod threshold;
pub mod tile_clip;
pub mod vote;
