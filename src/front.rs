//! What the front ends (the command line and the Python package) build a run from, in one
//! place beside the facade of `lib.rs`: the run configuration and its sidecar, the solvers and
//! frames of a batch, the inputs, the outputs and exports. A front end reaches the library
//! through `gpustar::*` and `gpustar::front::*`; what it needs and these lack belongs here.

pub use crate::batch::claims::{RunFiles, check_outputs};
pub use crate::batch::{resumed_inputs, run, run_frames};
pub use crate::calibrate::{FitOptions, calibrate, camera_file};
pub use crate::catalog::{radec_to_vector, vector_to_radec};
pub use crate::choice::Choice;
pub use crate::config::sidecar::{self, Sidecar};
pub use crate::config::{RunConfig, ValueOrRange, check_fov};
pub use crate::io::array::Samples;
pub use crate::io::inputs::{self, Shard};
pub use crate::io::output::{Format, RecordWriter, open_output, restore_input_order};
pub use crate::io::wcs::wcs_header;
pub use crate::pipeline::{BackendChoice, Counts, Decoded, Solvers};
pub use crate::products::Products;
pub use crate::sequence::{Detected, Sequencer, sequence_of};
pub use crate::simulate::{SimSettings, render};
pub use crate::sky::hint::parse_hint;
pub use crate::sky::now_utc_iso;
pub use crate::solve::detect::Detection;
pub use crate::streaks::export::{Exports, NO_SITE};
