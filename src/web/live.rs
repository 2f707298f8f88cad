//! The live view the page shows, fed from the runner's status: the status with when its state
//! began and the last fault; the scan's height map, a row per committed line (bucket means
//! across x); the last committed line's profile (bucket minima and maxima, so no spike is
//! lost); the last scan's result (verdict, Ra, Sa, warnings).
//!
//! The feed runs on the page's own thread, never the scan's: it wakes on a status change, at
//! most [`MIN_INTERVAL`] after its last publication (changes in between are taken together),
//! and reads the lines' files the scan has already written through the scan store's own reader
//! ([`ScanStore::load_line`]) on a blocking thread. It publishes one immutable [`View`] in a
//! `watch` channel, its parts serialised once; each page's stream keeps a [`Cursor`] of what it
//! has sent and sends only what is newer ([`Cursor::next_events`]), so a page that falls
//! behind skips to the latest status and is never queued for.
//!
//! Layer 4 (process edge): depends on the scan's status, store and journal types and the scan
//! index's reader ([`crate::jobs::index::read_entry`]); reads scan directories.

use crate::jobs::index::read_entry;
use crate::scan::faults::NoFaults;
use crate::scan::journal::JOURNAL_FILE;
use crate::scan::status::{State, Status};
use crate::scan::store::ScanStore;
use chrono::{DateTime, SecondsFormat, Utc};
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, SystemTime};
use tokio::sync::watch;

/// Shortest time between two publications: at most four a second.
pub const MIN_INTERVAL: Duration = Duration::from_millis(250);

/// Columns of a height-map row.
pub const MAP_COLUMNS: usize = 400;

/// Buckets of the profile's envelope.
pub const PROFILE_BUCKETS: usize = 1000;

/// A serialised part with the sequence number of its last change.
#[derive(Debug, Clone, PartialEq)]
pub struct Versioned {
    /// Grows with every change of any part.
    pub seq: u64,
    /// The JSON.
    pub json: Arc<str>,
}

/// The scan whose height map is shown.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanView {
    /// Its id.
    pub id: String,
    /// `{"scan_id", "lines_total", "columns"}`.
    pub header: Arc<str>,
    /// One row per line, in the order they were read.
    pub rows: Vec<Versioned>,
}

/// What the page shows, as published.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct View {
    /// `{"status": …, "since": …, "last_fault": …}`.
    pub status: Option<Versioned>,
    /// The scan shown.
    pub scan: Option<Arc<ScanView>>,
    /// The last committed line's profile.
    pub profile: Option<Versioned>,
    /// The last finished scan's result.
    pub result: Option<Versioned>,
}

/// What one page's stream has sent.
#[derive(Debug, Clone, Default)]
pub struct Cursor {
    status: u64,
    scan: Option<String>,
    row: u64,
    profile: u64,
    result: u64,
}

/// An event of the page's stream: its name and its JSON.
pub type Event = (&'static str, Arc<str>);

impl Cursor {
    /// The events that bring a page from what it has to `view`: `scan` (a new height map),
    /// `rows` (a JSON array of new rows), `profile`, `result`, `status`.
    pub fn next_events(&mut self, view: &View) -> Vec<Event> {
        let mut out: Vec<Event> = Vec::new();
        if let Some(scan) = &view.scan {
            if self.scan.as_deref() != Some(&scan.id) {
                self.scan = Some(scan.id.clone());
                self.row = 0;
                out.push(("scan", scan.header.clone()));
            }
            let new: Vec<&Versioned> = scan.rows.iter().filter(|r| r.seq > self.row).collect();
            if !new.is_empty() {
                let mut rows = String::from("[");
                for (i, r) in new.iter().enumerate() {
                    if i > 0 {
                        rows.push(',');
                    }
                    rows.push_str(&r.json);
                    self.row = self.row.max(r.seq);
                }
                rows.push(']');
                out.push(("rows", rows.into()));
            }
        }
        let mut part = |name: &'static str, v: &Option<Versioned>, seen: &mut u64| {
            if let Some(v) = v {
                if v.seq > *seen {
                    *seen = v.seq;
                    out.push((name, v.json.clone()));
                }
            }
        };
        part("profile", &view.profile, &mut self.profile);
        part("result", &view.result, &mut self.result);
        part("status", &view.status, &mut self.status);
        out
    }
}

/// Means of `values` over `buckets` equal runs (fewer when there are fewer values); a run's
/// non-finite values are left out, an all-non-finite run is `None`.
pub fn bucket_means(values: &[f64], buckets: usize) -> Vec<Option<f64>> {
    runs(values, buckets)
        .map(|run| {
            let finite: Vec<f64> = run.iter().copied().filter(|v| v.is_finite()).collect();
            (!finite.is_empty()).then(|| finite.iter().sum::<f64>() / finite.len() as f64)
        })
        .collect()
}

/// Minimum and maximum of `values` over `buckets` equal runs (fewer when there are fewer
/// values), non-finite values left out.
pub fn bucket_envelope(values: &[f64], buckets: usize) -> Vec<Option<(f64, f64)>> {
    runs(values, buckets)
        .map(|run| {
            run.iter().copied().filter(|v| v.is_finite()).fold(
                None,
                |acc: Option<(f64, f64)>, v| match acc {
                    None => Some((v, v)),
                    Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
                },
            )
        })
        .collect()
}

/// `buckets` runs of `values` (fewer if there are fewer values) covering them all, the
/// longer runs spread evenly.
fn runs(values: &[f64], buckets: usize) -> impl Iterator<Item = &[f64]> {
    let n = values.len();
    let b = buckets.min(n).max(1);
    (0..b)
        .filter(move |_| n > 0)
        .map(move |i| &values[i * n / b..(i + 1) * n / b])
}

/// A number for the page: 5 significant digits are far below what a display shows.
fn short(v: Option<f64>) -> Value {
    match v {
        Some(v) if v.is_finite() => {
            let s = format!("{v:.5e}");
            s.parse::<f64>().map_or(Value::Null, |x| json!(x))
        }
        _ => Value::Null,
    }
}

/// The row and profile JSON of one stored line.
fn line_parts(index: u32, y_mm: f64, pitch_mm: f64, heights: &[f64]) -> (String, String) {
    let length_mm = pitch_mm * heights.len().saturating_sub(1) as f64;
    let row = json!({
        "index": index,
        "y_mm": short(Some(y_mm)),
        "values": bucket_means(heights, MAP_COLUMNS).into_iter().map(short).collect::<Vec<_>>(),
    });
    let env = bucket_envelope(heights, PROFILE_BUCKETS);
    let profile = json!({
        "index": index,
        "y_mm": short(Some(y_mm)),
        "points": heights.len(),
        "length_mm": short(Some(length_mm)),
        "min_um": env.iter().map(|e| short(e.map(|e| e.0))).collect::<Vec<_>>(),
        "max_um": env.iter().map(|e| short(e.map(|e| e.1))).collect::<Vec<_>>(),
    });
    (row.to_string(), profile.to_string())
}

/// A line read for the view.
struct ReadLine {
    index: u32,
    stamp: Option<SystemTime>,
    row: String,
    profile: String,
}

fn stamp(dir: &Path, index: u32) -> Option<SystemTime> {
    std::fs::metadata(dir.join("lines").join(crate::scan::store::csv_name(index)))
        .and_then(|m| m.modified())
        .ok()
}

/// Reads the complete lines of `dir` that are not in `known` (index → the CSV's modification
/// time when read) or changed since; lines that cannot be read are skipped (the scan's own
/// checks report them).
fn read_new_lines(dir: &Path, known: &BTreeMap<u32, Option<SystemTime>>) -> Vec<ReadLine> {
    let Ok(store) = ScanStore::open(dir, Arc::new(NoFaults)) else {
        return Vec::new();
    };
    let Ok((complete, _)) = store.stored_indices() else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for index in complete {
        let st = stamp(dir, index);
        if known.get(&index).is_some_and(|k| *k == st) {
            continue;
        }
        let Ok(line) = store.load_line(index) else {
            continue;
        };
        let (row, profile) = line_parts(
            index,
            line.y_mm(),
            line.profile.pitch_x_mm,
            &line.profile.heights_um,
        );
        out.push(ReadLine {
            index,
            stamp: st,
            row,
            profile,
        });
    }
    out
}

/// The result of the scan in `dir`: its state, verdict, means and warnings.
fn read_result(dir: &Path) -> Option<String> {
    let name = dir.file_name()?.to_str()?;
    let (entry, _) = read_entry(name, dir).ok()?;
    let warnings: Vec<String> = std::fs::read(dir.join("report.json"))
        .ok()
        .and_then(|b| serde_json::from_slice::<Value>(&b).ok())
        .and_then(|r| serde_json::from_value(r.get("warnings")?.clone()).ok())
        .unwrap_or_default();
    let report = dir.join("report.html").is_file();
    let mut v = serde_json::to_value(&entry).ok()?;
    v["warning_texts"] = json!(warnings);
    v["report_html"] = json!(report);
    Some(v.to_string())
}

/// The newest scan directory of `out` (scan ids begin with their UTC start time).
fn newest_scan(out: &Path) -> Option<PathBuf> {
    std::fs::read_dir(out)
        .ok()?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.join(JOURNAL_FILE).is_file())
        .max_by(|a, b| a.file_name().cmp(&b.file_name()))
}

fn rfc3339(t: DateTime<Utc>) -> String {
    t.to_rfc3339_opts(SecondsFormat::Secs, true)
}

/// The feed's state between publications.
#[derive(Default)]
struct Feed {
    seq: u64,
    view: View,
    dir: Option<PathBuf>,
    lines_total: u32,
    known: BTreeMap<u32, Option<SystemTime>>,
    lines_done: Option<u32>,
    since: Option<(State, Option<String>, DateTime<Utc>)>,
    last_fault: Option<(String, DateTime<Utc>)>,
    result_of: Option<PathBuf>,
}

impl Feed {
    fn next(&mut self) -> u64 {
        self.seq += 1;
        self.seq
    }

    /// Shows the scan in `dir` from now on (its map starts empty).
    fn show_scan(&mut self, dir: PathBuf, lines_total: u32) {
        let id = dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let header = json!({"scan_id": id, "lines_total": lines_total, "columns": MAP_COLUMNS});
        self.view.scan = Some(Arc::new(ScanView {
            id,
            header: header.to_string().into(),
            rows: Vec::new(),
        }));
        self.view.profile = None;
        self.known.clear();
        self.lines_done = None;
        self.lines_total = lines_total;
        self.dir = Some(dir);
    }

    /// Adds lines read from the scan shown.
    fn add_lines(&mut self, lines: Vec<ReadLine>) {
        if lines.is_empty() {
            return;
        }
        let mut scan = self.view.scan.as_deref().cloned();
        let mut last_profile = None;
        for l in lines {
            let seq = self.next();
            if let Some(s) = &mut scan {
                s.rows.push(Versioned {
                    seq,
                    json: l.row.into(),
                });
            }
            self.known.insert(l.index, l.stamp);
            last_profile = Some(Versioned {
                seq,
                json: l.profile.into(),
            });
        }
        self.view.scan = scan.map(Arc::new);
        self.view.profile = last_profile;
    }

    /// The status part, with when the state (and reason) began and the last fault.
    fn set_status(&mut self, status: &Status, now: DateTime<Utc>) {
        let key = (status.state, status.reason.clone());
        let since = match &self.since {
            Some((s, r, t)) if (*s, r.clone()) == key => *t,
            _ => now,
        };
        self.since = Some((key.0, key.1, since));
        if status.state == State::Suspended {
            if let Some(r) = &status.reason {
                if self.last_fault.as_ref().map(|f| &f.0) != Some(r) {
                    self.last_fault = Some((r.clone(), since));
                }
            }
        }
        let fault = self
            .last_fault
            .as_ref()
            .map(|(r, t)| json!({"reason": r, "at": rfc3339(*t)}));
        let v = json!({"status": status, "since": rfc3339(since), "last_fault": fault});
        let seq = self.next();
        self.view.status = Some(Versioned {
            seq,
            json: v.to_string().into(),
        });
    }
}

/// Runs the feed until the status channel closes: publishes into `tx` at most every
/// [`MIN_INTERVAL`]. `out` is the output directory (its newest scan is shown at start).
pub async fn run(mut status: watch::Receiver<Status>, out: PathBuf, tx: watch::Sender<Arc<View>>) {
    let mut feed = Feed::default();
    // The newest scan on the station, until the runner names one.
    let newest = {
        let out = out.clone();
        tokio::task::spawn_blocking(move || {
            let dir = newest_scan(&out)?;
            let total = read_entry(dir.file_name()?.to_str()?, &dir)
                .map(|(e, _)| e.lines_planned)
                .unwrap_or(0);
            let lines = read_new_lines(&dir, &BTreeMap::new());
            let result = read_result(&dir);
            Some((dir, total, lines, result))
        })
        .await
        .ok()
        .flatten()
    };
    if let Some((dir, total, lines, result)) = newest {
        feed.show_scan(dir.clone(), total);
        feed.add_lines(lines);
        if let Some(r) = result {
            let seq = feed.next();
            feed.view.result = Some(Versioned {
                seq,
                json: r.into(),
            });
        }
        feed.result_of = Some(dir);
    }
    let mut last = tokio::time::Instant::now() - MIN_INTERVAL;
    loop {
        tokio::time::sleep_until(last + MIN_INTERVAL).await;
        let s = status.borrow_and_update().clone();
        update(&mut feed, &s).await;
        tx.send_replace(Arc::new(feed.view.clone()));
        last = tokio::time::Instant::now();
        if status.changed().await.is_err() {
            break;
        }
    }
}

/// Brings the feed to status `s`: the scan shown, its new lines, the result, the status.
async fn update(feed: &mut Feed, s: &Status) {
    if let Some(d) = &s.scan_dir {
        let d = PathBuf::from(d);
        if feed.dir.as_ref() != Some(&d) {
            feed.show_scan(d, s.lines_total);
        }
    }
    if s.scan_dir.is_some() && s.lines_total != feed.lines_total {
        feed.lines_total = s.lines_total;
        if let Some(scan) = &feed.view.scan {
            let header =
                json!({"scan_id": scan.id, "lines_total": s.lines_total, "columns": MAP_COLUMNS});
            feed.view.scan = Some(Arc::new(ScanView {
                header: header.to_string().into(),
                ..(**scan).clone()
            }));
        }
    }
    let running = s.scan_dir.is_some();
    if let Some(dir) = feed.dir.clone() {
        if running && feed.lines_done != Some(s.lines_done) {
            let known = feed.known.clone();
            let lines = tokio::task::spawn_blocking(move || read_new_lines(&dir, &known))
                .await
                .unwrap_or_default();
            feed.add_lines(lines);
            feed.lines_done = Some(s.lines_done);
        }
    }
    if let Some(stop) = &s.last_stop {
        if !stop.dir.is_empty() && feed.result_of.as_deref() != Some(Path::new(&stop.dir)) {
            let dir = PathBuf::from(&stop.dir);
            feed.result_of = Some(dir.clone());
            // The lines of the scan's last moments, then its result.
            let known = feed.known.clone();
            let shown = feed.dir.as_deref() == Some(dir.as_path());
            let (lines, result) = tokio::task::spawn_blocking(move || {
                let lines = if shown {
                    read_new_lines(&dir, &known)
                } else {
                    Vec::new()
                };
                (lines, read_result(&dir))
            })
            .await
            .unwrap_or_default();
            feed.add_lines(lines);
            if let Some(r) = result {
                let seq = feed.next();
                feed.view.result = Some(Versioned {
                    seq,
                    json: r.into(),
                });
            }
            if stop.status == crate::scan::ending::StopStatus::Fail {
                feed.last_fault = Some((stop.reason.clone(), Utc::now()));
            }
        }
    }
    feed.set_status(s, Utc::now());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bucket_means_cover_every_value_once() {
        let v: Vec<f64> = (0..10).map(f64::from).collect();
        let m = bucket_means(&v, 3);
        // Runs [0,1,2] [3,4,5] [6,7,8,9].
        assert_eq!(m, vec![Some(1.0), Some(4.0), Some(7.5)]);
        // Fewer values than buckets: one per value.
        assert_eq!(bucket_means(&v[..2], 400), vec![Some(0.0), Some(1.0)]);
        assert!(bucket_means(&[], 400).is_empty());
        assert_eq!(
            bucket_means(&[f64::NAN, 2.0, f64::NAN, f64::NAN], 2),
            vec![Some(2.0), None]
        );
    }

    #[test]
    fn the_envelope_keeps_a_single_spike() {
        let mut v = vec![0.0; 10_000];
        v[4321] = 9.5;
        v[77] = -3.0;
        let e = bucket_envelope(&v, 1000);
        assert_eq!(e.len(), 1000);
        assert_eq!(e[432], Some((0.0, 9.5)));
        assert_eq!(e[7], Some((-3.0, 0.0)));
        let hi = e
            .iter()
            .filter_map(|x| x.map(|x| x.1))
            .fold(f64::MIN, f64::max);
        assert_eq!(hi, 9.5);
    }

    fn view_with(rows: &[(u64, &str)], id: &str) -> View {
        View {
            status: Some(Versioned {
                seq: 100,
                json: "{\"s\":1}".into(),
            }),
            scan: Some(Arc::new(ScanView {
                id: id.into(),
                header: format!("{{\"scan_id\":\"{id}\"}}").into(),
                rows: rows
                    .iter()
                    .map(|(seq, j)| Versioned {
                        seq: *seq,
                        json: (*j).into(),
                    })
                    .collect(),
            })),
            profile: None,
            result: None,
        }
    }

    #[test]
    fn a_cursor_sends_only_what_is_new_and_starts_a_new_scan_from_its_first_row() {
        let mut c = Cursor::default();
        let v = view_with(&[(1, "{\"index\":0}"), (2, "{\"index\":1}")], "A");
        let e = c.next_events(&v);
        let names: Vec<&str> = e.iter().map(|x| x.0).collect();
        assert_eq!(names, ["scan", "rows", "status"]);
        assert_eq!(&*e[1].1, "[{\"index\":0},{\"index\":1}]");
        // Nothing new: nothing sent.
        assert!(c.next_events(&v).is_empty());
        // One more row, and a new status.
        let mut v = view_with(
            &[
                (1, "{\"index\":0}"),
                (2, "{\"index\":1}"),
                (5, "{\"index\":2}"),
            ],
            "A",
        );
        v.status.as_mut().unwrap().seq = 101;
        let e = c.next_events(&v);
        assert_eq!(e.len(), 2);
        assert_eq!(&*e[0].1, "[{\"index\":2}]");
        // Another scan: its header and every row, though their numbers are lower.
        let v = view_with(&[(3, "{\"index\":0}")], "B");
        let e = c.next_events(&v);
        assert_eq!(e[0].0, "scan");
        assert_eq!(&*e[1].1, "[{\"index\":0}]");
    }

    #[test]
    fn the_status_part_says_since_when_and_keeps_the_last_fault() {
        let mut feed = Feed::default();
        let t0: DateTime<Utc> = "2026-12-06T03:00:00Z".parse().unwrap();
        let t1: DateTime<Utc> = "2026-12-06T03:05:00Z".parse().unwrap();
        let t2: DateTime<Utc> = "2026-12-06T03:09:00Z".parse().unwrap();
        let mut s = Status::idle();
        s.state = State::Suspended;
        s.reason = Some("disk full".into());
        feed.set_status(&s, t0);
        // The same state and reason later: still since t0.
        s.lines_done = 3;
        feed.set_status(&s, t1);
        let v: Value = serde_json::from_str(&feed.view.status.as_ref().unwrap().json).unwrap();
        assert_eq!(v["since"], "2026-12-06T03:00:00Z");
        assert_eq!(v["status"]["reason"], "disk full");
        assert_eq!(v["last_fault"]["reason"], "disk full");
        // Scanning again: since changes, the fault stays as the last one.
        s.state = State::Scanning;
        s.reason = None;
        feed.set_status(&s, t2);
        let v: Value = serde_json::from_str(&feed.view.status.as_ref().unwrap().json).unwrap();
        assert_eq!(v["since"], "2026-12-06T03:09:00Z");
        assert_eq!(v["last_fault"]["at"], "2026-12-06T03:00:00Z");
    }
}
