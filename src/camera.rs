//! The camera model: pinhole with optional radial distortion and mirroring
//! (conventions of spec/INTERFACE.md: x = column, y = row, (0,0) = centre of the top-left
//! pixel; camera +X = increasing column, +Y = increasing row, +Z = boresight).

use crate::error::{Context, Error, IntoKind, Result, fail};
use nalgebra::Vector3;
use serde::Deserialize;
use std::path::Path;

/// A camera as read from its TOML file (or made from `--fov-deg`).
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub width: u32,
    pub height: u32,
    /// Focal length in pixels along x (columns).
    pub fx: f64,
    /// Focal length in pixels along y (rows); equals `fx` for square pixels.
    pub fy: f64,
    /// Principal point, pixels.
    pub cx: f64,
    pub cy: f64,
    /// Radial distortion on the normalised radius: r_d = r (1 + k1 r² + k2 r⁴).
    pub k1: f64,
    pub k2: f64,
    /// The image is a mirror image of the sky (+Y then points to decreasing row).
    pub mirrored: bool,
}

/// The TOML file as written by users (spec/INTERFACE.md "Camera file").
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraFile {
    width: u32,
    height: u32,
    fov_x_deg: Option<f64>,
    fx_px: Option<f64>,
    fy_px: Option<f64>,
    cx_px: Option<f64>,
    cy_px: Option<f64>,
    #[serde(default)]
    k1: f64,
    #[serde(default)]
    k2: f64,
    #[serde(default)]
    mirrored: bool,
    /// Optional: the faintest catalog magnitude this camera sees (overrides the default).
    mag_limit: Option<f64>,
}

impl Camera {
    /// A centred pinhole camera with square pixels and the given horizontal FOV, where the
    /// FOV is the angle between the midpoints of the left and right image edges.
    pub fn from_fov(width: u32, height: u32, fov_x_deg: f64) -> Result<Camera> {
        if width == 0 || height == 0 {
            fail!(Config, "camera size must be positive, got {width}x{height}");
        }
        if !(fov_x_deg > 0.0 && fov_x_deg < 170.0) {
            fail!(
                Config,
                "field of view must be between 0 and 170 degrees, got {fov_x_deg}"
            );
        }
        let fx = width as f64 / 2.0 / (fov_x_deg.to_radians() / 2.0).tan();
        Ok(Camera {
            width,
            height,
            fx,
            fy: fx,
            cx: (width as f64 - 1.0) / 2.0,
            cy: (height as f64 - 1.0) / 2.0,
            k1: 0.0,
            k2: 0.0,
            mirrored: false,
        })
    }

    /// This camera with pixels `pixel_aspect` (height / width) times as tall as wide: the
    /// focal length in pixel heights is `fx / pixel_aspect` (a Lodestar's 8.3 × 8.6 µm pixels:
    /// 0.965).
    pub fn with_pixel_aspect(mut self, pixel_aspect: f64) -> Camera {
        self.fy = self.fx / pixel_aspect;
        self
    }

    /// Read a camera TOML file; returns the camera and its optional `mag_limit`.
    pub fn from_toml_file(path: &Path) -> Result<(Camera, Option<f64>)> {
        let text = crate::files::read_regular_text(path, "camera file")?;
        Camera::from_toml(&text).with_context(|| format!("camera file {}", path.display()))
    }

    pub fn from_toml(text: &str) -> Result<(Camera, Option<f64>)> {
        let f: CameraFile = toml::from_str(text).into_kind(Error::Config)?;
        let mut cam = match (f.fov_x_deg, f.fx_px) {
            (Some(fov), None) => Camera::from_fov(f.width, f.height, fov)?,
            (None, Some(fx)) if fx > 0.0 => {
                let mut c = Camera::from_fov(f.width, f.height, 10.0)?;
                c.fx = fx;
                c.fy = fx;
                c
            }
            (Some(_), Some(_)) => fail!(Config, "give fov_x_deg or fx_px, not both"),
            _ => fail!(
                Config,
                "give fov_x_deg (degrees) or fx_px (a positive focal length in pixels)"
            ),
        };
        if let Some(fy) = f.fy_px {
            if fy <= 0.0 {
                fail!(Config, "fy_px must be positive");
            }
            cam.fy = fy;
        }
        if let Some(cx) = f.cx_px {
            cam.cx = cx;
        }
        if let Some(cy) = f.cy_px {
            cam.cy = cy;
        }
        cam.k1 = f.k1;
        cam.k2 = f.k2;
        cam.mirrored = f.mirrored;
        Ok((cam, f.mag_limit))
    }

    /// Unit vector in the camera frame of pixel (x, y).
    pub fn pixel_to_vector(&self, x: f64, y: f64) -> Vector3<f64> {
        let xd = (x - self.cx) / self.fx;
        let mut yd = (y - self.cy) / self.fy;
        if self.mirrored {
            yd = -yd;
        }
        let (xu, yu) = self.undistort(xd, yd);
        Vector3::new(xu, yu, 1.0).normalize()
    }

    /// Pixel of a camera-frame direction, or None behind the camera.
    pub fn vector_to_pixel(&self, v: &Vector3<f64>) -> Option<(f64, f64)> {
        if v.z <= 1e-9 {
            return None;
        }
        let (xu, yu) = (v.x / v.z, v.y / v.z);
        let s = self.distortion_factor(xu * xu + yu * yu);
        let (xd, mut yd) = (xu * s, yu * s);
        if self.mirrored {
            yd = -yd;
        }
        Some((self.cx + self.fx * xd, self.cy + self.fy * yd))
    }

    /// Is (x, y) on the image (pixel centres from 0 to W−1, edges half a pixel beyond)?
    pub fn contains(&self, x: f64, y: f64) -> bool {
        x >= -0.5 && y >= -0.5 && x <= self.width as f64 - 0.5 && y <= self.height as f64 - 0.5
    }

    fn distortion_factor(&self, r2: f64) -> f64 {
        1.0 + self.k1 * r2 + self.k2 * r2 * r2
    }

    /// Invert the radial distortion by fixed-point iteration (converges for the mild
    /// distortion of star cameras; |k1 r²| well below 1).
    fn undistort(&self, xd: f64, yd: f64) -> (f64, f64) {
        if self.k1 == 0.0 && self.k2 == 0.0 {
            return (xd, yd);
        }
        let (mut xu, mut yu) = (xd, yd);
        for _ in 0..20 {
            let s = self.distortion_factor(xu * xu + yu * yu);
            xu = xd / s;
            yu = yd / s;
        }
        (xu, yu)
    }

    /// Angle per pixel at the principal point along x (radians): the scale the tolerances use.
    pub fn ifov_rad(&self) -> f64 {
        1.0 / self.fx.min(self.fy)
    }

    /// Angle between the midpoints of the left and right edges (degrees).
    pub fn fov_x_deg(&self) -> f64 {
        let yc = (self.height as f64 - 1.0) / 2.0;
        angle(
            &self.pixel_to_vector(-0.5, yc),
            &self.pixel_to_vector(self.width as f64 - 0.5, yc),
        )
        .to_degrees()
    }

    /// Angle between the midpoints of the top and bottom edges (degrees).
    pub fn fov_y_deg(&self) -> f64 {
        let xc = (self.width as f64 - 1.0) / 2.0;
        angle(
            &self.pixel_to_vector(xc, -0.5),
            &self.pixel_to_vector(xc, self.height as f64 - 0.5),
        )
        .to_degrees()
    }

    /// The largest angle between two points of the image: the longer diagonal (radians).
    pub fn diagonal_rad(&self) -> f64 {
        let (w, h) = (self.width as f64 - 0.5, self.height as f64 - 0.5);
        let d1 = angle(
            &self.pixel_to_vector(-0.5, -0.5),
            &self.pixel_to_vector(w, h),
        );
        let d2 = angle(
            &self.pixel_to_vector(w, -0.5),
            &self.pixel_to_vector(-0.5, h),
        );
        d1.max(d2)
    }

    /// Camera-frame vector of the image centre pixel ((W−1)/2, (H−1)/2).
    pub fn centre_vector(&self) -> Vector3<f64> {
        let (x, y) = self.centre_pixel();
        self.pixel_to_vector(x, y)
    }

    /// The image centre, ((W − 1)/2, (H − 1)/2) with pixel centres at integers.
    pub fn centre_pixel(&self) -> (f64, f64) {
        (
            (self.width as f64 - 1.0) / 2.0,
            (self.height as f64 - 1.0) / 2.0,
        )
    }
}

/// Angle between two unit vectors, accurate at all angles (atan2 of cross and dot).
pub fn angle(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.cross(b).norm().atan2(a.dot(b))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fov_round_trips() {
        let c = Camera::from_fov(1024, 768, 11.4).unwrap();
        assert!((c.fov_x_deg() - 11.4).abs() < 1e-12);
        assert!(c.fov_y_deg() < 11.4 && c.fov_y_deg() > 8.0);
        assert!(c.diagonal_rad().to_degrees() > 14.0);
    }

    #[test]
    fn pixel_vector_round_trip_with_distortion_and_mirror() {
        let (mut c, _) = Camera::from_toml(
            "width = 752\nheight = 290\nfx_px = 2000.0\nfy_px = 1040.0\nk1 = -0.05\nk2 = 0.01\nmirrored = true\ncx_px = 380.2\n",
        )
        .unwrap();
        for &(x, y) in &[(0.0, 0.0), (751.0, 289.0), (12.3, 200.7), (380.2, 144.5)] {
            let v = c.pixel_to_vector(x, y);
            let (x2, y2) = c.vector_to_pixel(&v).unwrap();
            assert!(
                (x - x2).abs() < 1e-9 && (y - y2).abs() < 1e-9,
                "{x},{y} -> {x2},{y2}"
            );
        }
        // Mirroring flips the sign of camera Y for rows below the centre.
        let v = c.pixel_to_vector(380.2, 250.0);
        assert!(v.y < 0.0);
        c.mirrored = false;
        assert!(c.pixel_to_vector(380.2, 250.0).y > 0.0);
    }

    #[test]
    fn toml_errors_say_what_is_wrong() {
        let e = Camera::from_toml("width = 10\nheight = 10\n").unwrap_err();
        assert!(format!("{e:#}").contains("fov_x_deg"));
        let e = Camera::from_toml("width = 10\nheight = 10\nfov_x_deg = 5\nfoo = 1\n").unwrap_err();
        assert!(format!("{e:#}").contains("foo"));
    }
}
