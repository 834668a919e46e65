//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::PathBuf;

/// `../shared` beside the project (real frames, Hipparcos-2), if present. A user's clone has
/// none: the caller's test is then skipped with a printed reason. In CI (`CI=true`) a missing
/// `../shared` fails the test instead, so CI never skips these checks silently.
pub fn shared_dir(test: &str) -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared");
    if dir.join("data/real").is_dir() {
        return Some(dir);
    }
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("{test}: ../shared is missing, and CI must run this test");
    }
    eprintln!("SKIPPED {test}: ../shared (real frames and hip2.dat) is not beside the project");
    None
}

/// The gpustar binary under test.
pub fn gpustar() -> std::process::Command {
    let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_gpustar"));
    // Keep table caches out of the user's home.
    c.env(
        "GPUSTAR_CACHE_DIR",
        std::env::temp_dir().join("gpustar-test-cache"),
    );
    c
}
