//! What this build is: the package version and the git commit it was built from (recorded
//! by `build.rs`; "unknown" for a build outside a git checkout without `SURFSCAN_COMMIT`).
//! `--version` prints it and every scan records it, so a result can be traced to the code
//! that produced it.
//!
//! Layer 0 (vocabulary): depends on nothing.

/// The package version (Cargo.toml).
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// The git commit of the build (12 hex digits), or "unknown".
pub const COMMIT: &str = env!("SURFSCAN_COMMIT");

/// `0.1.0 (commit 0123456789ab)`: what `surfscan --version` prints after the name.
pub const LONG_VERSION: &str = concat!(
    env!("CARGO_PKG_VERSION"),
    " (commit ",
    env!("SURFSCAN_COMMIT"),
    ")"
);

/// `surfscan 0.1.0 (commit 0123456789ab)`: the software named in reports and records.
pub fn software() -> String {
    format!("surfscan {LONG_VERSION}")
}
