//! `surfscan list`: the scans on the station — state, recipe, specimen, verdict, Ra and Sa
//! means, warnings — from the scan index ([`crate::jobs::index`]), refreshed from the
//! journals first; `--json` for programs.
//!
//! Exit status: 0, 2 usage (a date or verdict that cannot be read), 74 the output directory
//! or the index cannot be read, 78 the configuration cannot be read.
//!
//! Layer 5 (composition): depends on [`crate::jobs::index`] and the configuration's
//! `[output]` table.

use super::{CliError, Exit};
use crate::jobs::index::{Filter, ScanEntry};
use crate::numfmt::{fmt_opt, Quantity};
use crate::specification::Verdict;
use chrono::{DateTime, NaiveDate, Utc};
use std::path::PathBuf;

/// Arguments of `surfscan list`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Station configuration; only its `[output] dir` is read [default: /etc/surfscan/surfscan.toml].
    #[arg(long, value_name = "FILE", conflicts_with = "dir")]
    pub config: Option<PathBuf>,
    /// The output directory to list, instead of the configuration's.
    #[arg(long, value_name = "DIR")]
    pub dir: Option<PathBuf>,
    /// Only this specimen (`*` and `?` are wildcards).
    #[arg(long, value_name = "ID")]
    pub specimen: Option<String>,
    /// Only scans of this recipe (`*` and `?` are wildcards).
    #[arg(long, value_name = "NAME")]
    pub recipe: Option<String>,
    /// Only scans started at or after this date (YYYY-MM-DD, UTC) or instant (RFC 3339).
    #[arg(long, value_name = "DATE", value_parser = parse_since)]
    pub since: Option<DateTime<Utc>>,
    /// Only scans with this verdict: conforms, does-not-conform, not-decidable.
    #[arg(long, value_name = "VERDICT", value_parser = parse_verdict)]
    pub verdict: Option<Verdict>,
    /// One JSON array of the scans, for programs.
    #[arg(long)]
    pub json: bool,
}

fn parse_since(s: &str) -> Result<DateTime<Utc>, String> {
    if let Ok(d) = NaiveDate::parse_from_str(s, "%Y-%m-%d") {
        return Ok(d.and_hms_opt(0, 0, 0).expect("midnight exists").and_utc());
    }
    DateTime::parse_from_rfc3339(s)
        .map(|t| t.with_timezone(&Utc))
        .map_err(|_| {
            format!("{s:?} is not a date: write YYYY-MM-DD (UTC) or an RFC 3339 instant such as 2026-03-14T22:00:00Z")
        })
}

fn parse_verdict(s: &str) -> Result<Verdict, String> {
    Verdict::parse(s).ok_or_else(|| {
        format!("{s:?} is not a verdict: conforms, does-not-conform or not-decidable")
    })
}

/// The output directory: `--dir`, else the configuration's `[output] dir`.
fn output_dir(args: &Args) -> Result<PathBuf, CliError> {
    if let Some(d) = &args.dir {
        return Ok(d.clone());
    }
    let path = args
        .config
        .clone()
        .unwrap_or_else(|| PathBuf::from(super::DEFAULT_CONFIG));
    let table = super::read_toml_table(&path)?;
    table
        .get("output")
        .and_then(|o| o.get("dir"))
        .and_then(|d| d.as_str())
        .map(PathBuf::from)
        .ok_or_else(|| {
            CliError::new(
                Exit::Config,
                format!(
                    "config {}: output.dir: missing; it names the directory of the scans (or give --dir)",
                    path.display()
                ),
            )
        })
}

/// The scans in `out` passing `filter` ([`crate::jobs::index::listing`]).
pub fn scans(
    out: &std::path::Path,
    filter: &Filter,
) -> Result<(Vec<ScanEntry>, Vec<String>), CliError> {
    crate::jobs::index::listing(out, filter).map_err(|e| CliError::new(Exit::Io, e.to_string()))
}

fn text_table(rows: &[ScanEntry]) -> String {
    let header = [
        "SCAN", "STATE", "RECIPE", "SPECIMEN", "VERDICT", "Ra µm", "Sa µm", "WARN",
    ];
    let cells: Vec<[String; 8]> = rows
        .iter()
        .map(|e| {
            let state = if e.state == "success" || e.lines_done == e.lines_planned {
                e.state.clone()
            } else {
                format!("{} {}/{}", e.state, e.lines_done, e.lines_planned)
            };
            [
                e.scan_id.clone(),
                state,
                e.recipe.clone().unwrap_or_else(|| "-".into()),
                if e.specimen.is_empty() {
                    "-".into()
                } else {
                    e.specimen.clone()
                },
                e.verdict.map_or("-".into(), |v| v.as_str().to_owned()),
                fmt_or_dash(e.ra_mean_um),
                fmt_or_dash(e.sa_um),
                e.warnings.map_or("-".into(), |w| w.to_string()),
            ]
        })
        .collect();
    let mut width = header.map(|h| h.chars().count());
    for row in &cells {
        for (w, c) in width.iter_mut().zip(row) {
            *w = (*w).max(c.chars().count());
        }
    }
    let line = |row: &[String]| {
        let mut s = String::new();
        for (i, (c, w)) in row.iter().zip(width).enumerate() {
            let pad = w - c.chars().count();
            // Numbers right-aligned, text left-aligned.
            if (5..=7).contains(&i) {
                s.push_str(&" ".repeat(pad));
                s.push_str(c);
            } else {
                s.push_str(c);
                if i + 1 < row.len() {
                    s.push_str(&" ".repeat(pad));
                }
            }
            if i + 1 < row.len() {
                s.push_str("  ");
            }
        }
        s.trim_end().to_owned()
    };
    let mut out = line(&header.map(str::to_owned));
    out.push('\n');
    for row in &cells {
        out.push_str(&line(row));
        out.push('\n');
    }
    out
}

fn fmt_or_dash(v: Option<f64>) -> String {
    match v {
        Some(_) => fmt_opt(v, Quantity::HeightUm),
        None => "-".into(),
    }
}

/// Runs `surfscan list`.
pub fn run(args: Args) -> Result<(), CliError> {
    let out = output_dir(&args)?;
    let filter = Filter {
        specimen: args.specimen.clone(),
        recipe: args.recipe.clone(),
        since: args.since,
        verdict: args.verdict,
    };
    let (rows, notes) = scans(&out, &filter)?;
    for n in notes {
        tell!("surfscan: note: {n}");
    }
    if args.json {
        let text = serde_json::to_string_pretty(&rows)
            .map_err(|e| CliError::new(Exit::Io, e.to_string()))?;
        say!("{text}");
    } else if rows.is_empty() {
        say!("no scans in {} match", out.display());
    } else {
        say_text!("{}", text_table(&rows));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_and_verdicts_are_read_or_refused_with_the_accepted_forms() {
        assert_eq!(
            parse_since("2026-03-14").unwrap().to_rfc3339(),
            "2026-03-14T00:00:00+00:00"
        );
        assert_eq!(
            parse_since("2026-03-14T22:30:00+01:00")
                .unwrap()
                .to_rfc3339(),
            "2026-03-14T21:30:00+00:00"
        );
        assert!(parse_since("14.03.2026")
            .unwrap_err()
            .contains("YYYY-MM-DD"));
        assert_eq!(
            parse_verdict("does-not-conform"),
            Ok(Verdict::DoesNotConform)
        );
        assert!(parse_verdict("ok").unwrap_err().contains("not-decidable"));
    }
}
