//! The import check (`scripts/import_cycles.py`; the fixtures name their modules after layers
//! of docs/ARCHITECTURE.md, which the check also requires): gpustar's own sources have no cycle and no
//! upward import, and the check sees the forms a cycle hides in (`use super::{…}`, a path
//! through a parent's re-export, a child module named without `self::`).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The check run on `src`, or None (with a printed reason) where python3 is missing; in CI
/// (`CI=true`) a missing python3 fails the test instead.
fn check(test: &str, src: &Path) -> Option<Output> {
    let out = Command::new("python3")
        .arg(root().join("scripts/import_cycles.py"))
        .arg(src)
        .output();
    match out {
        Ok(o) => Some(o),
        Err(e) => {
            if std::env::var("CI").is_ok_and(|v| v == "true") {
                panic!("{test}: python3 could not run ({e}), and CI must run this test");
            }
            eprintln!("SKIPPED {test}: python3 could not run: {e}");
            None
        }
    }
}

/// A throwaway source tree: `files` as (path under src, text).
fn tree(name: &str, files: &[(&str, &str)]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("gpustar-imports-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    for (path, text) in files {
        let p = dir.join(path);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, text).unwrap();
    }
    dir
}

#[test]
fn gpustar_has_no_import_cycle_and_no_upward_import() {
    let Some(out) = check("gpustar_has_no_import_cycle", &root().join("src")) else {
        return;
    };
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("cycles: 0; upward imports: 0"), "{text}");
}

/// A child that takes its parent's item through a grouped `use super::{…}` while the parent
/// calls into the child: a cycle, which the check names and fails on.
#[test]
fn a_grouped_super_import_cycle_is_caught() {
    let dir = tree(
        "super",
        &[
            ("lib.rs", "pub mod solve;\n"),
            (
                "solve/mod.rs",
                "mod b;\npub struct Shared;\npub fn run() { b::work(); }\n",
            ),
            (
                "solve/b.rs",
                "use super::{Shared, run as _r};\npub fn work() -> Shared { Shared }\n",
            ),
        ],
    );
    let Some(out) = check("a_grouped_super_import_cycle_is_caught", &dir) else {
        return;
    };
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(!out.status.success(), "{text}");
    assert!(text.contains("cycle: solve <-> solve::b"), "{text}");

    // The same items in a file of their own, re-exported by the parent: no cycle, because
    // `super::Shared` resolves through the re-export to the file that defines it.
    std::fs::write(
        dir.join("solve/mod.rs"),
        "mod b;\nmod shared;\npub use shared::Shared;\npub fn run() { b::work(); }\n",
    )
    .unwrap();
    std::fs::write(dir.join("solve/shared.rs"), "pub struct Shared;\n").unwrap();
    std::fs::write(
        dir.join("solve/b.rs"),
        "use super::{Shared};\npub fn work() -> Shared { Shared }\n",
    )
    .unwrap();
    let out = check("a_grouped_super_import_cycle_is_caught", &dir).unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Siblings that import each other through nested groups, one of them by a path written
/// inline; a test module's imports do not count.
#[test]
fn a_sibling_cycle_through_nested_groups_is_caught() {
    let dir = tree(
        "siblings",
        &[
            ("lib.rs", "pub mod sky;\n"),
            ("sky/mod.rs", "pub mod p;\npub mod q;\n"),
            (
                "sky/p.rs",
                "use crate::sky::{q::{self, Q}};\npub struct P;\npub fn f(_: Q) { q::g() }\n",
            ),
            (
                "sky/q.rs",
                "pub struct Q;\npub fn g() { let _ = super::p::P; }\n",
            ),
        ],
    );
    let Some(out) = check("a_sibling_cycle_through_nested_groups_is_caught", &dir) else {
        return;
    };
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(!out.status.success(), "{text}");
    assert!(text.contains("cycle: sky::p <-> sky::q"), "{text}");

    // Only a test module of q names p: no cycle.
    std::fs::write(
        dir.join("sky/q.rs"),
        "pub struct Q;\npub fn g() {}\n#[cfg(test)]\nmod tests {\n    use super::super::p::P;\n}\n",
    )
    .unwrap();
    let out = check("a_sibling_cycle_through_nested_groups_is_caught", &dir).unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    // A doc link names its target as a use does (rustdoc resolves it): a cycle again.
    std::fs::write(
        dir.join("sky/q.rs"),
        "/// Made for [`P`](super::p::P).\npub struct Q;\npub fn g() {}\n",
    )
    .unwrap();
    let out = check("a_sibling_cycle_through_nested_groups_is_caught", &dir).unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("cycle: sky::p <-> sky::q"), "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}
