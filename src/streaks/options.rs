//! What `--streaks` asks for: the detection settings and how streak ends are reduced.

use super::identify::IdentifySettings;
use crate::cpu::streak_filter::StreakParams;
use crate::cpu::threshold::DetectParams;
use crate::sky;

/// Settings of streak detection.
#[derive(Clone, Copy, Debug)]
pub struct StreakSettings {
    /// The mask's threshold, in noise sigmas of the smoothed image.
    pub k_sigma: f32,
    /// Shortest streak reported (pixels between its ends in the frame).
    pub min_length_px: f64,
    /// Smallest matched-filter SNR reported (a 40 px streak of peak SNR 3 per pixel has about
    /// 30; the false lines of fixed-pattern noise that pass the other tests, 10 to 12).
    pub min_snr: f64,
    /// Shortest track that may be broken or modulated (a tumbling object's): shorter ones
    /// must be steady, since the point-source test ([`chain`]) has too little track to go on.
    pub min_tumbling_px: f64,
    /// Smallest [`StreakFit::local_snr`]: the track must stand above the same filter run
    /// beside it (fixed-pattern noise, compression blocks and diffuse light make lines of
    /// single-pixel SNR 20–30 that stand 2–4 there; independently simulated streaks 9 and up).
    pub min_local_snr: f64,
    /// Largest RMS distance of the track's local centroids from the line: an orbit's arc
    /// over one exposure is straight (independently simulated streaks: at most 0.65 px).
    pub max_fit_rms_px: f64,
    /// Narrowest profile (Gaussian σ, pixels) taken for a streak: a defective column is a
    /// pixel wide (σ ≈ 0.3), anything the optics drew is as wide as the PSF.
    pub min_sigma_px: f64,
    /// Widest profile (Gaussian σ, pixels): a fit this wide has found no line but a patch.
    pub max_sigma_px: f64,
}

impl StreakSettings {
    /// The defaults (`Default`), as a constant: the run configuration's (`config`) come
    /// from here.
    pub const DEFAULT: StreakSettings = StreakSettings {
        k_sigma: 3.5,
        min_length_px: 25.0,
        min_snr: 20.0,
        min_sigma_px: 0.5,
        max_sigma_px: 8.0,
        max_fit_rms_px: 1.0,
        min_local_snr: 5.0,
        min_tumbling_px: 80.0,
    };
}

impl Default for StreakSettings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl StreakSettings {
    /// The mask parameters of a `p`-sized frame whose tiles were made with detection
    /// threshold `k_detect`.
    pub fn params(&self, p: &DetectParams, k_detect: f32) -> StreakParams {
        StreakParams::new(p, self.k_sigma, k_detect)
    }
}

/// What `--streaks` asks for: detection settings and how the ends are reduced.
#[derive(Clone, Debug)]
pub struct StreakOptions {
    pub settings: StreakSettings,
    /// `--station`; else each frame's header says.
    pub station: Option<sky::Station>,
    /// `--dut1`: UT1 − UTC (s) instead of the bundled table's.
    pub dut1_s: Option<f64>,
    pub astrometry: Astrometry,
    /// `--tle`: the objects streaks are matched to, shared by the frames.
    pub tle: Option<std::sync::Arc<sky::tle::TleCatalog>>,
    pub identify: IdentifySettings,
}

crate::choice! {
    /// Where the RA/Dec of streak ends come from (`--astrometry`).
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum Astrometry {
        Auto = "auto", "gpustar's solution, else the header's WCS when it has one",
        Solve = "solve", "gpustar's solution only",
        Header = "header", "The FITS header's celestial WCS only (TAN or TAN-SIP), for fields too \
            narrow for the catalog",
    }
}
