//! Files in and out: images and FITS ([`frame`], [`fits`], [`dark`]), the inputs of a run
//! ([`inputs`]), world coordinate systems ([`wcs`]), and the record file ([`output`]).

pub mod dark;
pub mod fits;
pub mod frame;
pub mod inputs;
pub mod output;
pub mod wcs;
