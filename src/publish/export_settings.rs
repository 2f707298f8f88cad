//! `[export]` in the station configuration: the drop directories of the lab's quality
//! systems, one `<scan-id>.dfq` (Q-DAS, for SPC) and one `<scan-id>.qif` (QIF 3.0 Results)
//! per completed scan; validated when the configuration is read, so a wrong value stops the
//! start (exit 78) with the key named.
//!
//! Layer 4 (process edge): serde types and their checks.

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// `[export]`: results into the lab's systems.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct ExportSettings {
    /// Where each scan's `<scan-id>.dfq` goes (an SPC system's watched directory).
    #[serde(default)]
    pub dfq_dir: Option<PathBuf>,
    /// Where each scan's `<scan-id>.qif` goes.
    #[serde(default)]
    pub qif_dir: Option<PathBuf>,
}

fn check_dir(key: &'static str, dir: &Path) -> Result<(), (&'static str, String)> {
    if dir.as_os_str().is_empty() || !dir.is_absolute() {
        return Err((
            key,
            format!(
                "{:?} must be an absolute directory (the drop directory of the lab's system, e.g. \"/srv/spc/in\")",
                dir.display().to_string()
            ),
        ));
    }
    Ok(())
}

impl ExportSettings {
    /// Checks every key; the error names the key (`export.…`) and what to write.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        if self.dfq_dir.is_none() && self.qif_dir.is_none() {
            return Err((
                "export",
                "names no drop directory: write dfq-dir = \"DIR\" and/or qif-dir = \"DIR\", or remove [export]".into(),
            ));
        }
        if let Some(d) = &self.dfq_dir {
            check_dir("export.dfq-dir", d)?;
        }
        if let Some(d) = &self.qif_dir {
            check_dir("export.qif-dir", d)?;
        }
        Ok(())
    }

    /// The configured targets: (format, directory).
    pub fn targets(&self) -> Vec<(super::export::Format, &Path)> {
        let mut v = Vec::new();
        if let Some(d) = &self.dfq_dir {
            v.push((super::export::Format::Dfq, d.as_path()));
        }
        if let Some(d) = &self.qif_dir {
            v.push((super::export::Format::Qif, d.as_path()));
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_or_missing_directories_are_refused_naming_the_key() {
        let s = |dfq: Option<&str>, qif: Option<&str>| ExportSettings {
            dfq_dir: dfq.map(PathBuf::from),
            qif_dir: qif.map(PathBuf::from),
        };
        assert_eq!(s(None, None).validate().unwrap_err().0, "export");
        assert_eq!(
            s(Some("spc/in"), None).validate().unwrap_err().0,
            "export.dfq-dir"
        );
        assert_eq!(
            s(Some("/srv/spc"), Some("")).validate().unwrap_err().0,
            "export.qif-dir"
        );
        assert!(s(Some("/srv/spc"), Some("/srv/qif")).validate().is_ok());
    }
}
