//! The built-in catalog, parsed once at build time: `catalog/hip2_hp9.csv` becomes
//! `$OUT_DIR/hip2_hp9.bin`, which `Catalog::builtin` decodes in a fraction of a millisecond
//! where parsing the CSV's 78,000 lines would take most of a one-frame run.
//!
//! Each star is 44 bytes, little-endian: the HIP number (u32), then ra_rad, dec_rad,
//! pmra_mas_yr, pmdec_mas_yr and hp_mag (f64), parsed with the standard library's parser as
//! `Catalog::parse` parses them; a test holds the two catalogs equal, star by star.

use std::io::Write;
use std::path::Path;

fn main() {
    let csv = "catalog/hip2_hp9.csv";
    println!("cargo:rerun-if-changed={csv}");
    println!("cargo:rerun-if-changed=build.rs");
    let text = std::fs::read_to_string(csv).unwrap_or_else(|e| panic!("cannot read {csv}: {e}"));
    let mut out = Vec::with_capacity(44 * 80_000);
    let rows = text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#') && !l.starts_with("hip,"));
    for (n, line) in rows.enumerate() {
        let fields: Vec<&str> = line.split(',').collect();
        let bad = || -> ! { panic!("{csv}: row {}: expected 'hip,5 numbers': {line:?}", n + 1) };
        if fields.len() != 6 {
            bad();
        }
        let hip: u32 = fields[0].parse().unwrap_or_else(|_| bad());
        out.extend_from_slice(&hip.to_le_bytes());
        for f in &fields[1..] {
            let v: f64 = f.parse().unwrap_or_else(|_| bad());
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    let dir = std::env::var("OUT_DIR").expect("cargo sets OUT_DIR");
    let path = Path::new(&dir).join("hip2_hp9.bin");
    std::fs::File::create(&path)
        .and_then(|mut f| f.write_all(&out))
        .unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
}
