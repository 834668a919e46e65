//! Lost-in-space identification of one frame, stage by stage: [`detect`] → [`identify`] (the
//! vote) or [`radial`] (ring features) with [`triangle`] checks → [`attitude`] (Wahba) →
//! [`refine`] (match, refit, false-match probability; [`explain`]: the brightest detections
//! explained). [`Solver`] holds one camera's catalog
//! selection and distance table and runs the stages after each kernel; [`driver`] is the flow
//! of passes, written once over the backends' [`kernels`]; [`hinted`] makes a solver for the
//! region a pointing hint names.

pub mod attitude;
mod bands;
pub mod detect;
pub mod driver;
pub mod explain;
pub mod hinted;
pub mod identify;
pub mod kernels;
mod mag_limit;
mod outcome;
pub mod radial;
pub mod refine;
mod report;
pub mod scale_free;
mod settings;
mod solver;
pub mod triangle;

pub use bands::*;
pub use mag_limit::*;
pub use outcome::{Outcome, Solution, Unsolved};
pub use report::*;
pub use settings::{Parity, Settings};
pub use solver::*;
