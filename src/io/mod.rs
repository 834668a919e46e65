//! Files in and out: images and FITS ([`frame`], [`fits`], [`dark`]; raw colour mosaics
//! detected on their luminance, [`bayer`]), pixels already in memory
//! ([`array`](mod@array)), the inputs of a run ([`inputs`]), world coordinate systems ([`wcs`]), and the
//! record file ([`output`]), and the guard every file gpustar writes passes ([`guard`]).

pub mod array;
pub mod bayer;
pub mod dark;
pub mod fits;
pub mod frame;
pub mod guard;
pub mod inputs;
pub mod output;
pub mod wcs;
