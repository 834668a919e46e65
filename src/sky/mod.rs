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

pub use azel::az_el;
pub use earth::earth_orientation;
pub use header::{Exposure, exposure_from_header};
pub(crate) use keyword::{parse_number, value};
pub(crate) use station::checked_station;
pub use station::{Station, parse_station, station_from_header};
pub(crate) use time::{DAYSEC, DJM0, Scale, parse_hms};
pub use time::{
    Hms, Utc, Ymd, iso_of_julian_year, julian_year, now_utc_iso, parse_iso, plausible_mjd,
};

#[cfg(test)]
mod tests;
