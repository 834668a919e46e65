//! What identifying a frame found, before it becomes a record: a solution, or why there is
//! none.

use super::detect::Detection;
use super::refine;
use crate::catalog::RefCatalog;
use std::sync::Arc;

/// What the identification of one frame found (before it becomes a record).
#[derive(Clone, Debug)]
pub struct Solution {
    pub detections: Vec<Detection>,
    pub outcome: Outcome,
    /// The frame's own observation epoch (FITS DATE-OBS), if it has one.
    pub epoch: Option<f64>,
}

/// Why a frame is not solved: the record's `reason`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unsolved {
    /// Fewer detections than a pattern needs.
    TooFewStars,
    /// No geometrically consistent set of candidates (or no quad hypothesis accepted).
    NoConsistentMatch,
    /// A solution was found, and failed the false-match test.
    LowConfidence,
    /// No camera for the frame: streaks alone, reduced through its header's WCS.
    NoCamera,
}

impl Unsolved {
    /// Every reason (the record schema lists them).
    pub const ALL: [Unsolved; 4] = [
        Unsolved::TooFewStars,
        Unsolved::NoConsistentMatch,
        Unsolved::LowConfidence,
        Unsolved::NoCamera,
    ];

    /// The reason as records write it.
    pub fn as_str(self) -> &'static str {
        match self {
            Unsolved::TooFewStars => "too_few_stars",
            Unsolved::NoConsistentMatch => "no_consistent_match",
            Unsolved::LowConfidence => "low_confidence",
            Unsolved::NoCamera => "no_camera",
        }
    }
}

impl std::fmt::Display for Unsolved {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

// One per frame, moved rarely: boxing the solution would buy nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
pub enum Outcome {
    /// The refined solution, and the reference stars its matches' ids index.
    Solved(refine::Refined, Arc<RefCatalog>),
    Unsolved(Unsolved),
}
