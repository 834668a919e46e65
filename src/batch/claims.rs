//! Every output of a run claimed before any work (issue 45): an output on an input, two
//! outputs on one path, an image written where the frames are read, and files gpustar did not
//! write are refused before the first frame (see [`crate::io::guard`]).

use crate::error::Result;
use crate::io::guard::Claims;
use crate::io::inputs::Input;
use crate::products::Products;
use crate::streaks::export::Exports;
use std::path::Path;

/// What a run reads and where its records go, for [`check_outputs`].
pub struct RunFiles<'a> {
    /// The directories the frames were listed from, and whether their subdirectories were
    /// too (none for `solve`'s one frame).
    pub dirs: Vec<(&'a Path, bool)>,
    pub inputs: &'a [Input],
    /// The other files read, with what they are: the catalog, camera, dark, TLEs.
    pub read: Vec<(&'a Path, &'static str)>,
    /// `-o`; None with `stdout` when the records go to standard output.
    pub records: Option<&'a Path>,
    pub stdout: bool,
    /// `--resume`: the run that wrote the exports goes on.
    pub resume: bool,
}

/// Claim the records, the exports and every per-frame product of a run, and check each can
/// be written; `products` learns which inputs' products keep their extension.
pub fn check_outputs(f: &RunFiles, exports: &Exports, products: &mut Products) -> Result<()> {
    let mut claims = Claims::new();
    for &(dir, recursive) in &f.dirs {
        claims.input_dir(dir, recursive);
    }
    for i in f.inputs {
        claims.input(&i.path, "a frame");
    }
    for (path, what) in &f.read {
        claims.input(path, what);
    }
    match f.records {
        Some(p) => claims.output(p, "-o")?,
        None if f.stdout => claims.stdout(),
        None => {}
    }
    exports.check_paths(&mut claims, products.overwrite, f.resume)?;
    products.check(f.inputs, &mut claims)
}
