//! The shipped build handles a panic as the code assumes (`src/panics.rs`): the release
//! profile, which the Debian package and so the daemon are built with, unwinds. The tests
//! run in the test profile, which always unwinds, so without this check a release build set
//! to abort would pass them all while every catch in it was dead code; `src/panics.rs` also
//! refuses to compile without unwinding, which the package's build (CI's last phase) meets.

/// `[profile.release] panic` is `"unwind"`.
#[test]
fn the_release_profile_unwinds() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/Cargo.toml");
    let manifest: toml::Table = std::fs::read_to_string(path).unwrap().parse().unwrap();
    let panic = manifest
        .get("profile")
        .and_then(|p| p.get("release"))
        .and_then(|r| r.get("panic"))
        .and_then(|v| v.as_str());
    assert_eq!(
        panic,
        Some("unwind"),
        "{path}: the release profile must unwind (src/panics.rs says why)"
    );
}
