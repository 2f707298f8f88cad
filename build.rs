//! Build script: records the git commit the binary is built from, for `--version` and for
//! the software version every scan records. A packager building from a source archive (no
//! `.git`) sets `SURFSCAN_COMMIT`; otherwise the commit reads "unknown".

use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    if !out.status.success() {
        return None;
    }
    let s = String::from_utf8(out.stdout).ok()?.trim().to_string();
    (!s.is_empty()).then_some(s)
}

fn main() {
    println!("cargo:rerun-if-env-changed=SURFSCAN_COMMIT");
    let given = std::env::var("SURFSCAN_COMMIT")
        .ok()
        .filter(|s| !s.trim().is_empty());
    let commit = given.or_else(|| {
        let commit = git(&["rev-parse", "--short=12", "HEAD"])?;
        // Rebuild when HEAD moves: the worktree's HEAD (a checkout of another branch or
        // commit) and the one branch ref it points to (a commit on that branch). Watching
        // every branch would rebuild the library whenever any other branch or worktree of
        // the repository commits.
        if let Some(dir) = git(&["rev-parse", "--git-dir"]) {
            println!("cargo:rerun-if-changed={dir}/HEAD");
        }
        if let Some(common) = git(&["rev-parse", "--git-common-dir"]) {
            // A path that does not exist would make every build rerun this script, so only
            // existing files are watched: the loose ref, or packed-refs when the ref is packed
            // (packing deletes the loose file, which is a change too).
            let watch = |path: String| {
                if std::path::Path::new(&path).exists() {
                    println!("cargo:rerun-if-changed={path}");
                }
            };
            if let Some(branch) = git(&["symbolic-ref", "-q", "HEAD"]) {
                watch(format!("{common}/{branch}"));
            }
            watch(format!("{common}/packed-refs"));
        }
        Some(commit)
    });
    println!(
        "cargo:rustc-env=SURFSCAN_COMMIT={}",
        commit.unwrap_or_else(|| "unknown".to_string())
    );
}
