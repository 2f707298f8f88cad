//! Headless Chromium for the HTML report tests: Debian's `chromium` (installed by
//! `.ci/run`), or `SURFSCAN_CHROMIUM`. A test that needs it fails, never skips, without it.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The browser to use; panics with the fix when there is none.
pub fn chromium() -> PathBuf {
    let p = std::env::var_os("SURFSCAN_CHROMIUM")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/usr/bin/chromium"));
    assert!(
        p.exists(),
        "no Chromium at {} for the HTML report test: run `bash .ci/run` (it installs Debian's chromium), `apt-get install chromium`, or set SURFSCAN_CHROMIUM",
        p.display()
    );
    p
}

/// The flags every headless run here starts with: no sandbox (containers), no GPU, nothing
/// fetched or synchronised behind the test's back.
pub const HEADLESS: &[&str] = &[
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
];

/// What Chromium made of a page: the DOM after load and the browser's console lines.
pub struct Rendered {
    /// `--dump-dom` output.
    pub dom: String,
    /// Console messages the browser logged (`…:CONSOLE…` lines of its log).
    pub console: Vec<String>,
}

/// Loads `page` headless (no network, a fresh profile) and returns the DOM and the console.
pub fn render(page: &Path) -> Rendered {
    let profile = tempfile::tempdir().unwrap();
    let out = Command::new(chromium())
        .args(HEADLESS)
        .args([
            "--enable-logging=stderr",
            "--v=0",
            "--virtual-time-budget=10000",
        ])
        .arg(format!("--user-data-dir={}", profile.path().display()))
        .arg("--dump-dom")
        .arg(format!("file://{}", page.display()))
        .output()
        .unwrap();
    let log = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "chromium failed: {log}");
    Rendered {
        dom: String::from_utf8_lossy(&out.stdout).into_owned(),
        console: log
            .lines()
            .filter(|l| l.contains(":CONSOLE"))
            .map(str::to_owned)
            .collect(),
    }
}

/// Prints `page` to `pdf` as the browser's print does (headless, a fresh profile, without
/// the browser's own header and footer: the page's CSS margin boxes are what is printed).
pub fn print_to_pdf(page: &Path, pdf: &Path) {
    let profile = tempfile::tempdir().unwrap();
    let out = Command::new(chromium())
        .args(HEADLESS)
        .args(["--no-pdf-header-footer", "--virtual-time-budget=10000"])
        .arg(format!("--user-data-dir={}", profile.path().display()))
        .arg(format!("--print-to-pdf={}", pdf.display()))
        .arg(format!("file://{}", page.display()))
        .output()
        .unwrap();
    assert!(
        out.status.success() && pdf.exists(),
        "chromium did not print {}: {}",
        page.display(),
        String::from_utf8_lossy(&out.stderr)
    );
}
