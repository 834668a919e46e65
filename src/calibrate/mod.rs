//! Camera calibration from solved star frames: one camera (fx, fy, cx, cy, k1, k2) fitted
//! jointly to the identified stars of many frames, each frame with its own attitude, by
//! Levenberg–Marquardt on the pixel residuals (detected pixel − projected catalog star).
//!
//! The frames must share one camera; their stars come from solving them with a rough camera
//! (often just a focal length). The attitudes absorb everything a rotation can explain, so
//! what is left to the camera is the shape of the projection: the scale (fx, fy), the
//! distortion (k1, k2), and — through the perspective of a wide field — the principal point.

mod fit;
mod session;

pub use fit::{
    Fit, FitOptions, FrameStars, MIN_FRAME_STARS, MIN_FRAMES_FOR_PRINCIPAL_POINT, MIN_STARS, Star,
    fit,
};
pub use session::{
    CENTRE_SD_PX, CENTRE_SHIFT_SIGMAS, Calibration, Step, calibrate, camera_file, centre_step,
};
