//! `[archive]` in the station configuration: the directory each completed scan directory is
//! copied to (a `file://` URL: a share of the lab's, NFS or SMB, mounted on the station);
//! validated when the configuration is read, so a wrong value stops the start (exit 78) with
//! the key named.
//!
//! Layer 4 (process edge): serde types and their checks.

use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// `[archive]`: the raw-data archive.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct ArchiveSettings {
    /// `file:///DIR`.
    pub url: String,
}

/// Reads `file:///DIR` into the directory.
pub fn parse_target(url: &str) -> Result<PathBuf, String> {
    if let Some(rest) = url.strip_prefix("file://") {
        if !rest.starts_with('/') {
            return Err(format!(
                "{url:?}: a file:// archive needs an absolute directory, e.g. file:///mnt/archive"
            ));
        }
        Ok(PathBuf::from(rest))
    } else if url.starts_with("s3://") {
        Err(format!(
            "{url:?}: this version archives to a directory only (an S3 bucket mounted with s3fs or rclone mount is one); write file:///DIR"
        ))
    } else {
        Err(format!(
            "{url:?} is not an archive URL; write file:///DIR (a mounted share)"
        ))
    }
}

impl ArchiveSettings {
    /// Checks every key; the error names the key (`archive.…`) and what to write.
    pub fn validate(&self) -> Result<PathBuf, (&'static str, String)> {
        parse_target(&self.url).map_err(|m| ("archive.url", m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_are_read_or_refused_with_the_form_to_write() {
        assert_eq!(
            parse_target("file:///mnt/archive").unwrap(),
            PathBuf::from("/mnt/archive")
        );
        assert!(parse_target("file://relative")
            .unwrap_err()
            .contains("absolute"));
        assert!(parse_target("/mnt/archive")
            .unwrap_err()
            .contains("file:///DIR"));
        assert!(parse_target("s3://lab-archive/x")
            .unwrap_err()
            .contains("directory only"));
    }
}
