//! Where a frame's camera comes from: a camera file, `--fov-deg`, `--scale-arcsec`, or the
//! pixel scale the frame's own header states.

use crate::camera::Camera;
use crate::error::{Result, error, fail};
use crate::io::fits::scale::PixelScale;
use std::collections::BTreeMap;

/// The smallest frame side gpustar solves: a few tiles of background and room for stars.
pub const MIN_SIDE: u32 = 16;

/// Where the camera model comes from.
#[derive(Clone, Debug)]
pub enum CameraSource {
    /// A camera file: frames of another size are errors.
    Fixed(Camera),
    /// `--fov-deg` (and `--pixel-aspect`): centred, no distortion, sized by each frame.
    Fov { fov_x_deg: f64, pixel_aspect: f64 },
    /// `--scale-arcsec`: as `Fov`, from the angle one pixel at the centre subtends (the field
    /// then grows with each frame's width), as solve-field's `arcsecperpix` and ASTAP's scale.
    Scale {
        arcsec_per_px: f64,
        pixel_aspect: f64,
    },
    /// Neither a camera nor a scale given: each frame's camera from the pixel scale its header
    /// states (`io::fits::scale`: CD, CDELT, PIXSCALE/SECPIX, FOCALLEN with XPIXSZ), searched
    /// within `Settings::scale_range`; a frame whose header states none gets an error record.
    /// These frames are solved by the CPU twins (the GPU keeps its tables by frame size).
    Header,
    /// None (`--streaks --astrometry header` alone): stars are not identified (records are
    /// `unsolved`, reason `no_camera`); streaks are reduced through each header's WCS.
    None,
}

impl CameraSource {
    /// `--fov-deg` alone: square pixels.
    pub fn fov(fov_x_deg: f64) -> CameraSource {
        CameraSource::Fov {
            fov_x_deg,
            pixel_aspect: 1.0,
        }
    }

    /// The camera of frames of this size (and, with [`CameraSource::Header`], of this stated
    /// scale), or why there is none.
    pub fn camera_for(
        &self,
        width: u32,
        height: u32,
        scale: Option<&PixelScale>,
    ) -> Result<Camera> {
        // A pixel scale s gives the pinhole's focal length 1 / tan(s) pixels, so the field is
        // 2 atan(width / 2 · tan(s)).
        let scaled = |arcsec_per_px: f64| {
            let half = width as f64 / 2.0 * (arcsec_per_px / 3600.0).to_radians().tan();
            2.0 * half.atan().to_degrees()
        };
        let (fov_x_deg, pixel_aspect) = match (self, scale) {
            (CameraSource::Fixed(c), _) => {
                if (c.width, c.height) != (width, height) {
                    let size = crate::io::frame::wrong_size(width, height, (c.width, c.height));
                    return Err(error!(Input, "{size}"));
                }
                return Ok(c.clone());
            }
            (CameraSource::None, _) => fail!(Config, "no camera given"),
            (CameraSource::Header, None) => fail!(
                Input,
                "the header states no pixel scale (a CD or CDELT WCS, PIXSCALE, SECPIX, or \
                 FOCALLEN with XPIXSZ): give --camera, --fov-deg or --scale-arcsec"
            ),
            (CameraSource::Header, Some(s)) => (scaled(s.arcsec_per_px), s.pixel_aspect),
            (
                CameraSource::Fov {
                    fov_x_deg,
                    pixel_aspect,
                },
                _,
            ) => (*fov_x_deg, *pixel_aspect),
            (
                CameraSource::Scale {
                    arcsec_per_px,
                    pixel_aspect,
                },
                _,
            ) => (scaled(*arcsec_per_px), *pixel_aspect),
        };
        if width < MIN_SIDE || height < MIN_SIDE {
            fail!(
                Input,
                "image is {width}x{height}: too small to hold a star field (gpustar needs at \
                 least {MIN_SIDE} pixels a side)"
            );
        }
        Ok(Camera::from_fov(width, height, fov_x_deg)?.with_pixel_aspect(pixel_aspect))
    }

    /// With [`CameraSource::Header`]: the pixel scale a frame's header keywords state, if any.
    pub fn header_scale(&self, keywords: &BTreeMap<String, String>) -> Option<PixelScale> {
        matches!(self, CameraSource::Header)
            .then(|| crate::io::fits::scale::pixel_scale(keywords))
            .flatten()
    }

    /// The stated scale a frame's solver is made for: scales within 0.01 % of each other share
    /// one (the search around them covers far more), where the CD matrices of an archive's
    /// solved frames, differing in their last digits, would otherwise build a table each.
    pub(crate) fn shared_scale(s: &PixelScale) -> PixelScale {
        let step = |x: f64| ((x.ln() / 1e-4).round() * 1e-4).exp();
        PixelScale {
            arcsec_per_px: step(s.arcsec_per_px),
            pixel_aspect: step(s.pixel_aspect),
            keywords: s.keywords,
        }
    }
}
