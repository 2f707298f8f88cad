//! The `[report]` table: who issues the report and how it is printed — the laboratory's
//! name, address and logo in the printed header, the paper size, and the roles of the
//! signature block. A scan keeps the header it was made with: the table is part of the
//! configuration its journal records, and [`LabHeader::of_frozen_config`] reads it back.
//!
//! Layer 4 (reporting): no dependency beyond serde.

use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// The paper a printed report is laid out for (CSS `@page size`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum Paper {
    /// ISO 216 A4, 210 mm × 297 mm.
    #[default]
    A4,
    /// US Letter, 8.5 in × 11 in.
    Letter,
}

/// `[report]`: the issuing laboratory and the printed layout. Every key is optional.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, rename_all = "kebab-case", deny_unknown_fields)]
pub struct LabHeader {
    /// The laboratory's name, first line of the printed header.
    pub lab: String,
    /// Its address; a `\n` starts a new line.
    pub address: String,
    /// A logo (PNG, JPEG or SVG) embedded in the header; read when the report is written, so
    /// a missing file costs the logo (with a warning), never the report.
    pub logo: Option<PathBuf>,
    /// `"A4"` or `"Letter"`.
    pub paper: Paper,
    /// The roles of the signature block, in order (each gets name, signature and date).
    pub signatures: Vec<String>,
    /// Also write each line's Rk figure as a PNG (`rk/NNNN.png`) beside its SVG. Off by
    /// default: the page embeds the SVG, and the PNGs cost most of a 31-line analysis's work.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub line_png: bool,
}

impl Default for LabHeader {
    fn default() -> Self {
        LabHeader {
            lab: String::new(),
            address: String::new(),
            logo: None,
            paper: Paper::default(),
            signatures: vec!["Measured by".into(), "Approved by".into()],
            line_png: false,
        }
    }
}

impl LabHeader {
    /// The `[report]` table of a configuration as a scan's journal recorded it (the whole
    /// configuration serialized); the default header when it has none or it cannot be read
    /// (a journal of an older version).
    pub fn of_frozen_config(config: &serde_json::Value) -> LabHeader {
        serde_json::from_value(config["report"].clone()).unwrap_or_default()
    }

    /// The media type of the logo by its file name's extension, `None` for one a page cannot
    /// show.
    pub fn logo_media_type(&self) -> Option<&'static str> {
        let ext = self
            .logo
            .as_ref()?
            .extension()?
            .to_str()?
            .to_ascii_lowercase();
        match ext.as_str() {
            "png" => Some("image/png"),
            "jpg" | "jpeg" => Some("image/jpeg"),
            "svg" => Some("image/svg+xml"),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frozen_configuration_gives_its_header_or_the_default() {
        let c = serde_json::json!({"report": {"lab": "Lab", "paper": "Letter", "signatures": ["Checked by"]}});
        let h = LabHeader::of_frozen_config(&c);
        assert_eq!(h.lab, "Lab");
        assert_eq!(h.paper, Paper::Letter);
        assert_eq!(h.signatures, vec!["Checked by".to_string()]);
        let none = LabHeader::of_frozen_config(&serde_json::json!({}));
        assert_eq!(none, LabHeader::default());
        assert_eq!(none.signatures.len(), 2);
        let bad = LabHeader::of_frozen_config(&serde_json::json!({"report": {"paper": "A3"}}));
        assert_eq!(bad, LabHeader::default());
    }

    #[test]
    fn the_logo_type_follows_its_extension() {
        let with = |p: &str| LabHeader {
            logo: Some(PathBuf::from(p)),
            ..LabHeader::default()
        };
        assert_eq!(with("a/logo.PNG").logo_media_type(), Some("image/png"));
        assert_eq!(with("logo.svg").logo_media_type(), Some("image/svg+xml"));
        assert_eq!(with("logo.gif").logo_media_type(), None);
        assert_eq!(LabHeader::default().logo_media_type(), None);
    }
}
