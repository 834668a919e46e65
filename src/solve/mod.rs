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

pub use bands::{
    BAND_RATIO, Band, MAX_TABLE_ROWS, Pass, PassKind, RETRY_VOTE_STARS, SCALE_STEP, SPREAD_CELLS,
    SPREAD_TRIANGLE_STARS, STAGES, WALK_MAX_RATIO, WIDE_MATCH_RADIUS_PX, WIDE_MIN_STARS,
    WIDE_PAIR_TOL_PX, WIDE_SCALE_STEP, scale_bands, scale_hypotheses, scaled, spread_order,
};
pub use mag_limit::{
    AUTO_STARS_IN_VIEW, FEW_STARS_IN_VIEW, FULL_SKY_SR, SHALLOW_STARS_IN_VIEW, auto_mag_limit,
    auto_mag_limit_in, mag_limit_for, mag_limit_in, stars_in_view,
};
pub use outcome::{Outcome, Solution, Unsolved};
pub use report::{ORTHOGONALITY_WARN, attitude_quality};
pub use settings::{Parity, Settings};
pub use solver::{Prepared, Solver};
