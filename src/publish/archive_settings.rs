//! `[archive]` in the station configuration: where each completed scan directory is copied
//! (an S3 bucket and prefix, or a `file://` directory such as an NFS mount) and with which
//! key; validated when the configuration is read, so a wrong value stops the start (exit 78)
//! with the key named.
//!
//! Layer 4 (process edge): serde types and their checks; reads the secret file only to check
//! it can be read.

use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// `[archive]`: the raw-data archive.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct ArchiveSettings {
    /// `s3://BUCKET/PREFIX` or `file:///DIR`.
    pub url: String,
    /// The S3 server's address, `http://HOST:PORT` or `https://HOST:PORT` (Garage, MinIO,
    /// Ceph, …); none for AWS itself.
    #[serde(default)]
    pub endpoint: Option<String>,
    /// The S3 region (`garage` for a Garage server's default); `us-east-1` by default.
    #[serde(default)]
    pub region: Option<String>,
    /// The access key id.
    #[serde(default)]
    pub access_key_id: Option<String>,
    /// A file holding the secret access key (its first line), so the configuration itself,
    /// which is recorded with every scan, holds no secret.
    #[serde(default)]
    pub secret_access_key_file: Option<PathBuf>,
    /// A PEM file of the certificate authorities an `https://` endpoint's certificate must
    /// chain to, for a store with the lab's own CA; the system's authorities are trusted too.
    #[serde(default)]
    pub ca_file: Option<PathBuf>,
    /// Days after which a scan directory is deleted from the station, once the archive is
    /// found again to hold a verified copy of it; none (the default) keeps every scan.
    #[serde(default)]
    pub delete_after_days: Option<u32>,
}

/// Where the archive is, as read from `url`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Target {
    /// A bucket and a key prefix (without leading or trailing `/`, maybe empty).
    S3 {
        /// The bucket.
        bucket: String,
        /// The prefix of every object.
        prefix: String,
    },
    /// A directory of the station's file system.
    File(PathBuf),
}

/// Reads `s3://BUCKET[/PREFIX]` or `file:///DIR`.
pub fn parse_target(url: &str) -> Result<Target, String> {
    if let Some(rest) = url.strip_prefix("s3://") {
        let (bucket, prefix) = rest.split_once('/').unwrap_or((rest, ""));
        let valid_bucket = (3..=63).contains(&bucket.len())
            && bucket
                .bytes()
                .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-' || b == b'.');
        if !valid_bucket {
            return Err(format!(
                "{url:?}: {bucket:?} is not a bucket name (3 to 63 lower-case letters, digits, '-' and '.'); write s3://BUCKET/PREFIX"
            ));
        }
        Ok(Target::S3 {
            bucket: bucket.to_owned(),
            prefix: prefix.trim_matches('/').to_owned(),
        })
    } else if let Some(rest) = url.strip_prefix("file://") {
        if !rest.starts_with('/') {
            return Err(format!(
                "{url:?}: a file:// archive needs an absolute directory, e.g. file:///mnt/archive"
            ));
        }
        Ok(Target::File(PathBuf::from(rest)))
    } else {
        Err(format!(
            "{url:?} is not an archive URL; write s3://BUCKET/PREFIX or file:///DIR"
        ))
    }
}

impl ArchiveSettings {
    /// Checks every key; the error names the key (`archive.…`) and what to write.
    pub fn validate(&self) -> Result<Target, (&'static str, String)> {
        let target = parse_target(&self.url).map_err(|m| ("archive.url", m))?;
        if let Some(e) = &self.endpoint {
            let rest = e
                .strip_prefix("http://")
                .or_else(|| e.strip_prefix("https://"));
            if rest.is_none_or(|r| r.trim_end_matches('/').is_empty()) {
                return Err((
                    "archive.endpoint",
                    format!("{e:?} is not a server address; write http://HOST:PORT or https://HOST:PORT"),
                ));
            }
        }
        if let Some(ca) = &self.ca_file {
            if !self
                .endpoint
                .as_deref()
                .is_some_and(|e| e.starts_with("https://"))
            {
                return Err((
                    "archive.ca-file",
                    "a CA file applies to an https:// endpoint only; set [archive] endpoint = \"https://HOST:PORT\" or remove ca-file".into(),
                ));
            }
            let pem = std::fs::read(ca).map_err(|e| {
                (
                    "archive.ca-file",
                    format!("cannot read {}: {e}", ca.display()),
                )
            })?;
            if super::tls::certificates(&pem).is_empty() {
                return Err((
                    "archive.ca-file",
                    format!("{} holds no PEM certificate", ca.display()),
                ));
            }
        }
        if let Target::S3 { .. } = target {
            match (&self.access_key_id, &self.secret_access_key_file) {
                (Some(_), Some(f)) => {
                    read_secret(f).map_err(|m| ("archive.secret-access-key-file", m))?;
                }
                (None, None) => {}
                (Some(_), None) => {
                    return Err((
                        "archive.secret-access-key-file",
                        "an access-key-id needs its secret: name the file holding it".into(),
                    ))
                }
                (None, Some(_)) => {
                    return Err((
                        "archive.access-key-id",
                        "a secret-access-key-file needs the key id it belongs to".into(),
                    ))
                }
            }
        } else if self.endpoint.is_some()
            || self.access_key_id.is_some()
            || self.secret_access_key_file.is_some()
        {
            return Err((
                "archive.url",
                "a file:// archive takes no endpoint or key; remove them or write s3://BUCKET/PREFIX"
                    .into(),
            ));
        }
        Ok(target)
    }
}

/// The first line of `path`, the secret.
pub fn read_secret(path: &std::path::Path) -> Result<String, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let line = text.lines().next().unwrap_or("").trim().to_owned();
    if line.is_empty() {
        return Err(format!(
            "{} is empty; its first line must be the secret access key",
            path.display()
        ));
    }
    Ok(line)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings(url: &str) -> ArchiveSettings {
        ArchiveSettings {
            url: url.into(),
            endpoint: None,
            region: None,
            access_key_id: None,
            secret_access_key_file: None,
            ca_file: None,
            delete_after_days: None,
        }
    }

    #[test]
    fn urls_are_read_or_refused_with_the_form_to_write() {
        assert_eq!(
            parse_target("s3://lab-archive/rough-3/").unwrap(),
            Target::S3 {
                bucket: "lab-archive".into(),
                prefix: "rough-3".into()
            }
        );
        assert_eq!(
            parse_target("s3://lab-archive").unwrap(),
            Target::S3 {
                bucket: "lab-archive".into(),
                prefix: String::new()
            }
        );
        assert_eq!(
            parse_target("file:///mnt/archive").unwrap(),
            Target::File("/mnt/archive".into())
        );
        assert!(parse_target("s3://Lab_Archive/x")
            .unwrap_err()
            .contains("bucket name"));
        assert!(parse_target("file://relative")
            .unwrap_err()
            .contains("absolute"));
        assert!(parse_target("/mnt/archive")
            .unwrap_err()
            .contains("s3://BUCKET"));
    }

    #[test]
    fn keys_come_in_pairs_and_a_file_archive_takes_none() {
        let mut s = settings("s3://lab-archive/x");
        s.access_key_id = Some("GK1".into());
        assert_eq!(
            s.validate().unwrap_err().0,
            "archive.secret-access-key-file"
        );
        let mut s = settings("s3://lab-archive/x");
        s.secret_access_key_file = Some("/nonexistent".into());
        assert_eq!(s.validate().unwrap_err().0, "archive.access-key-id");
        s.access_key_id = Some("GK1".into());
        let (key, msg) = s.validate().unwrap_err();
        assert_eq!(key, "archive.secret-access-key-file");
        assert!(msg.contains("/nonexistent"), "{msg}");
        let mut s = settings("file:///mnt/a");
        s.endpoint = Some("http://127.0.0.1:3900".into());
        assert_eq!(s.validate().unwrap_err().0, "archive.url");
        let mut s = settings("s3://lab-archive/x");
        s.endpoint = Some("127.0.0.1:3900".into());
        assert_eq!(s.validate().unwrap_err().0, "archive.endpoint");
    }
}
