//! The sky side of an observation: the one time type and ISO parser ([`time`]), exposure times
//! from FITS headers ([`header`]), the observing station ([`station`]), Earth orientation from
//! the bundled IERS table ([`earth`]), topocentric Az/El ([`azel`]) and orbital elements
//! propagated to the station ([`tle`]).
//!
//! Time scales, leap seconds and the ICRS -> observed chain come from `sofars`, a Rust port of
//! the IAU SOFA library; results made with it should acknowledge "IAU SOFA". Az/El is what
//! astropy's ICRS -> AltAz gives with pressure 0 (see the tests for the agreement).
//!
//! Longitudes are east-positive, as FITS defines `OBSGEO-L` and `SITELONG`; some observatories
//! write `SITELONG` west-positive, and such headers need `--station` instead.

pub mod azel;
pub mod earth;
pub mod header;
pub mod hint;
mod keyword;
pub mod station;
pub mod time;
pub mod tle;

pub use azel::*;
pub use earth::*;
pub use header::*;
pub(crate) use keyword::{parse_number, value};
pub use station::*;
pub use time::*;

#[cfg(test)]
mod tests;
