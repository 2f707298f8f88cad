//! Results into the lab's quality systems: a recipe's scan through `surfscan scan` writes
//! `<scan-id>.dfq` and `<scan-id>.qif` into the `[export]` drop directories. The DFQ is read
//! back by `tests/python/dfq_read.py` (written from the Q-DAS field list, not from the writer)
//! and compared with report.json and the journal; the QIF is validated by xmllint against the
//! official QIF 3.0 schemas (`tests/data/qif/`) and its numbers read with roxmltree. Drop
//! directories that are away (missing, read-only) are named in the daemon's status, the scan
//! waits in the queue across a restart, and the files arrive once they are back; a full one
//! is named and keeps no partial file; `surfscan export` writes a scan again.

use crate::common::{append_config, json_from, reference_script, scan_command, Rig, RigOptions};
use crate::daemon_e2e as e2e;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use surfscan::scan::journal::{read_journal, Record};

/// The scans' traces are one sampling length long: the callouts say so (`Ra1`).
const RECIPE: &str = r#"description = "Turned coupon, face A"
[plan]
lines = 6
y-step-mm = 0.01
[specification]
limits = ["U Ra1 50", "L Ra1 0.001", "Rz1 max 400"]
"#;

/// xmllint's verdict on `file` against the QIF 3.0 schemas.
fn assert_valid_qif(file: &Path) {
    crate::common::assert_validates(
        file,
        "tests/data/qif/schema/QIFDocument.xsd",
        "the QIF 3.0 schemas",
    );
}

fn read_dfq(file: &Path) -> Value {
    json_from(reference_script("dfq_read.py").arg(file))
}

fn scan_dirs(out: &Path) -> Vec<PathBuf> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(out)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.join("journal.jsonl").exists())
        .collect();
    dirs.sort();
    dirs
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * b.abs().max(1.0)
}

/// The parameter's value on each line of the report, in its order.
fn line_values(report: &Value, parameter: &str) -> Vec<Option<f64>> {
    report["lines"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l[format!("{parameter}_um")].as_f64())
        .collect()
}

/// Checks the DFQ against report.json and the journal, field by field.
fn check_dfq(dfq: &Value, report: &Value, records: &[Record]) {
    let start = records
        .iter()
        .find_map(|r| match r {
            Record::Start(s) => Some(s),
            _ => None,
        })
        .unwrap();
    assert_eq!(dfq["part"]["K1001"], "coupon");
    assert_eq!(dfq["part"]["K1002"], "Turned coupon, face A");
    // One characteristic per specified parameter: Ra (both limits) and Rz.
    let limits = report["specification"]["limits"].as_array().unwrap();
    assert_eq!(limits.len(), 3, "{limits:?}");
    assert_eq!(dfq["K0100"], 2);
    let chars = dfq["characteristics"].as_object().unwrap();
    let index_of = |p: &str| {
        chars
            .iter()
            .find(|(_, c)| c["K2001"] == p)
            .map(|(i, _)| i.clone())
            .unwrap_or_else(|| panic!("no characteristic {p}: {chars:?}"))
    };
    for l in limits {
        let p = l["parameter"].as_str().unwrap();
        let c = &chars[&index_of(p)];
        let key = if l["side"] == "lower" {
            "K2110"
        } else {
            "K2111"
        };
        assert!(
            close(c[key].as_f64().unwrap(), l["limit_um"].as_f64().unwrap()),
            "{p} {key}: {c:?} vs {l:?}"
        );
        assert_eq!(c["K2142"], "µm");
        assert!(c["K2002"].as_str().unwrap().contains("cut-off"), "{c:?}");
        assert!(
            c["K2002"]
                .as_str()
                .unwrap()
                .contains(l["callout"].as_str().unwrap()),
            "{c:?}"
        );
    }
    // Ra has both limits, so a nominal between them; Rz only an upper limit.
    let ra = &chars[&index_of("Ra")];
    assert!(
        close(ra["K2101"].as_f64().unwrap(), (50.0 + 0.001) / 2.0),
        "{ra:?}"
    );
    assert!(chars[&index_of("Rz")].get("K2110").is_none());
    assert!(chars[&index_of("Rz")].get("K2101").is_none());

    // Each line's value, its time, the batch, the operator and the part ident.
    let mut times: std::collections::BTreeMap<u32, String> = Default::default();
    for r in records {
        if let Record::Line(l) = r {
            times.insert(l.id.index, l.time.format("%Y-%m-%dT%H:%M:%S").to_string());
        }
    }
    let indices: Vec<u32> = report["lines"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["index"].as_u64().unwrap() as u32)
        .collect();
    assert_eq!(indices.len(), 6);
    for p in ["Ra", "Rz"] {
        let want: Vec<f64> = line_values(report, p)
            .into_iter()
            .map(Option::unwrap)
            .collect();
        let got = dfq["values"][index_of(p)].as_array().unwrap();
        assert_eq!(got.len(), want.len(), "{p}: {got:?}");
        for ((v, w), index) in got.iter().zip(&want).zip(&indices) {
            assert!(close(v["K0001"].as_f64().unwrap(), *w), "{p}: {v:?} vs {w}");
            assert_eq!(v["K0004"], times[index].as_str(), "{p}: {v:?}");
            // The batch is the scan's start (the id's time without `T` and `Z`: K0006 holds
            // 14 characters); the operator, a name and not a catalogue number (K0008 is
            // one), is in the value's text with the whole scan id.
            let id = start.scan_id.as_str();
            assert_eq!(v["K0006"], format!("{}{}", &id[..8], &id[9..15]), "{v:?}");
            assert!(v.get("K0008").is_none(), "{v:?}");
            assert_eq!(v["K0009"], format!("scan {id}; operator R. Tester"));
            assert_eq!(v["K0014"], "coupon A-17");
        }
    }
}

/// Checks the QIF's numbers against report.json.
fn check_qif(text: &str, report: &Value) {
    let doc = roxmltree::Document::parse(text).unwrap();
    let named = |name: &str| -> Vec<roxmltree::Node<'_, '_>> {
        doc.descendants()
            .filter(|n| n.tag_name().name() == name)
            .collect()
    };
    let child_text = |n: roxmltree::Node<'_, '_>, name: &str| -> Option<String> {
        n.children()
            .find(|c| c.tag_name().name() == name)
            .and_then(|c| c.text().map(str::to_owned))
    };
    // The instrument as a measurement resource, the part, the specimen.
    let device = named("MeasurementDevice");
    assert_eq!(device.len(), 1);
    assert_eq!(
        child_text(device[0], "ModelNumber").as_deref(),
        report["traceability"]["instrument_model"].as_str()
    );
    assert_eq!(named("Part").len(), 1);
    assert_eq!(
        child_text(named("Part")[0], "ModelNumber").as_deref(),
        Some("coupon")
    );
    assert_eq!(
        child_text(named("ActualComponent")[0], "SerialNumber").as_deref(),
        Some("coupon A-17")
    );
    // The characteristics with their limits.
    let defs = named("UserDefinedLinearCharacteristicDefinition");
    assert_eq!(defs.len(), 2);
    let def = |p: &str| {
        *defs
            .iter()
            .find(|d| child_text(**d, "Name").as_deref() == Some(p))
            .unwrap()
    };
    let tol = |p: &str, side: &str| -> Option<f64> {
        let t = def(p)
            .children()
            .find(|c| c.tag_name().name() == "Tolerance")?;
        child_text(t, side)?.parse().ok()
    };
    assert_eq!(tol("Ra", "MaxValue"), Some(50.0));
    assert_eq!(tol("Ra", "MinValue"), Some(0.001));
    assert_eq!(tol("Rz", "MaxValue"), Some(400.0));
    assert_eq!(tol("Rz", "MinValue"), None);
    // Per characteristic: the mean with U, and each line's value.
    let stats: Vec<&Value> = report["uncertainty"]["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .collect();
    let measurements = named("UserDefinedLinearCharacteristicMeasurement");
    assert_eq!(
        measurements.len(),
        2 * (1 + 6),
        "a mean and six lines per parameter"
    );
    for p in ["Ra", "Rz"] {
        let item = named("UserDefinedLinearCharacteristicItem")
            .into_iter()
            .find(|n| child_text(*n, "Name").as_deref() == Some(p))
            .unwrap()
            .attribute("id")
            .unwrap()
            .to_owned();
        let mine: Vec<_> = measurements
            .iter()
            .filter(|m| child_text(**m, "CharacteristicItemId").as_deref() == Some(&item))
            .collect();
        let st = stats
            .iter()
            .find(|s| s["parameter"] == format!("{p}_um"))
            .unwrap();
        let mean = mine
            .iter()
            .find(|m| child_text(***m, "Description").unwrap().contains("mean"))
            .unwrap();
        let value = mean
            .children()
            .find(|c| c.tag_name().name() == "Value")
            .unwrap();
        assert!(close(
            value.text().unwrap().parse().unwrap(),
            st["mean"].as_f64().unwrap()
        ));
        assert!(close(
            value
                .attribute("combinedUncertainty")
                .unwrap()
                .parse()
                .unwrap(),
            st["U"].as_f64().unwrap()
        ));
        let mut per_line: Vec<f64> = mine
            .iter()
            .filter(|m| {
                child_text(***m, "Description")
                    .unwrap()
                    .contains(" of line ")
            })
            .map(|m| child_text(**m, "Value").unwrap().parse().unwrap())
            .collect();
        let mut want: Vec<f64> = line_values(report, p)
            .into_iter()
            .map(Option::unwrap)
            .collect();
        per_line.sort_by(f64::total_cmp);
        want.sort_by(f64::total_cmp);
        assert_eq!(per_line.len(), 6);
        for (g, w) in per_line.iter().zip(&want) {
            assert!(close(*g, *w), "{p}: {per_line:?} vs {want:?}");
        }
    }
    // The verdict as the inspection status.
    let want = match report["specification"]["verdict"].as_str().unwrap() {
        "conforms" => "PASS",
        "does not conform" => "FAIL",
        _ => "UNKNOWN",
    };
    let status = named("InspectionStatusEnum");
    assert!(!status.is_empty());
    assert!(status.iter().all(|s| s.text() == Some(want)), "{want}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_recipe_scan_exports_a_dfq_and_a_qif_that_read_back_as_its_report() {
    let rig = Rig::start(RigOptions {
        lines: 6,
        ..RigOptions::default()
    })
    .await;
    let config = rig.config("out");
    let recipes = rig.tmp.path().join("recipes");
    std::fs::create_dir_all(&recipes).unwrap();
    std::fs::write(recipes.join("coupon.toml"), RECIPE).unwrap();
    let spc = rig.tmp.path().join("spc");
    let qifs = rig.tmp.path().join("qif");
    std::fs::create_dir_all(&spc).unwrap();
    std::fs::create_dir_all(&qifs).unwrap();
    append_config(
        &config,
        &format!(
            "\n[jobs]\nrecipes = {:?}\n\n[export]\ndfq-dir = {:?}\nqif-dir = {:?}\n",
            recipes.display().to_string(),
            spc.display().to_string(),
            qifs.display().to_string()
        ),
    );
    let out = tokio::time::timeout(
        std::time::Duration::from_secs(120),
        scan_command(&config, &[])
            .args(["--recipe", "coupon"])
            .output(),
    )
    .await
    .expect("the scan ends within 120 s")
    .unwrap();
    assert!(
        matches!(out.status.code(), Some(0) | Some(3)),
        "{}",
        crate::common::describe(&out)
    );
    let dirs = scan_dirs(&rig.out_dir("out"));
    assert_eq!(dirs.len(), 1);
    let dir = &dirs[0];
    let id = dir.file_name().unwrap().to_str().unwrap().to_owned();
    let report: Value =
        serde_json::from_slice(&std::fs::read(dir.join("report.json")).unwrap()).unwrap();
    let records = read_journal(&dir.join("journal.jsonl")).unwrap().records;

    // Exactly the two files, nothing half-written beside them.
    let listing = |d: &Path| -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    };
    assert_eq!(listing(&spc), [format!("{id}.dfq")]);
    assert_eq!(listing(&qifs), [format!("{id}.qif")]);
    let dfq_path = spc.join(format!("{id}.dfq"));
    let qif_path = qifs.join(format!("{id}.qif"));
    check_dfq(&read_dfq(&dfq_path), &report, &records);
    assert_valid_qif(&qif_path);
    check_qif(&std::fs::read_to_string(&qif_path).unwrap(), &report);

    // `surfscan export` writes the same files again, elsewhere.
    let again = rig.tmp.path().join("again");
    std::fs::create_dir_all(&again).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .args(["export", "--dfq-dir"])
        .arg(&again)
        .arg("--qif-dir")
        .arg(&again)
        .arg(dir)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", crate::common::describe(&o));
    assert_eq!(
        std::fs::read(again.join(format!("{id}.dfq"))).unwrap(),
        std::fs::read(&dfq_path).unwrap()
    );
    assert_eq!(
        std::fs::read(again.join(format!("{id}.qif"))).unwrap(),
        std::fs::read(&qif_path).unwrap()
    );
    // A directory that is not there: named, exit 74, nothing created.
    let gone = rig.tmp.path().join("gone");
    let o = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .args(["export", "--dfq-dir"])
        .arg(&gone)
        .arg(dir)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(74), "{err}");
    assert!(err.contains(&gone.display().to_string()), "{err}");
    assert!(!gone.exists());
    rig.shutdown().await;
}

fn run(args: &[&str], path: &Path) {
    let o = Command::new(args[0])
        .args(&args[1..])
        .arg(path)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "{args:?} {}: {}",
        path.display(),
        String::from_utf8_lossy(&o.stderr)
    );
}

/// A read-only bind mount of a directory on itself, undone when dropped.
struct ReadOnly(PathBuf);

impl Drop for ReadOnly {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.0).output();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn drop_directories_away_are_named_and_the_files_arrive_once_they_are_back() {
    let r = e2e::rig().await;
    let spc = r.dir.path().join("spc");
    let qifs = r.dir.path().join("qif");
    std::fs::create_dir(&qifs).unwrap();
    append_config(
        &r.config,
        &format!(
            "\n[export]\ndfq-dir = {:?}\nqif-dir = {:?}\n",
            spc.display().to_string(),
            qifs.display().to_string()
        ),
    );
    // The QIF directory read-only (EROFS, which root cannot write past either).
    let o = Command::new("mount")
        .args(["--bind"])
        .arg(&qifs)
        .arg(&qifs)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mount = ReadOnly(qifs.clone());
    run(&["mount", "-o", "remount,ro,bind"], &qifs);

    let mut d = crate::mqtt_broker::spawn_logged(&r);
    crate::mqtt_broker::wait_socket(&r).await;
    e2e::start_scan(&r, "exp-1").await;
    let s = e2e::wait_status(&r, "the scan ended", |s| {
        s.starts > 0 && s.state == surfscan::scan::status::State::Idle && s.last_stop.is_some()
    })
    .await;
    assert_eq!(
        s.last_stop.as_ref().unwrap().status,
        surfscan::scan::ending::StopStatus::Success,
        "{s:?}"
    );
    // Both faults named in the status; the scan is complete regardless.
    let s = e2e::wait_status(&r, "the export's fault named", |s| {
        s.links
            .get("export")
            .is_some_and(|l| !l.ok && l.queued == 1)
    })
    .await;
    let link = &s.links["export"];
    assert!(
        link.message.contains(&spc.display().to_string())
            && link.message.contains("[export] dfq-dir"),
        "{link:?}"
    );
    let s = e2e::wait_status(&r, "the read-only directory named", |s| {
        s.links
            .get("export")
            .is_some_and(|l| l.message.contains("[export] qif-dir"))
    })
    .await;
    assert!(
        s.links["export"].message.contains("read-only"),
        "{:?}",
        s.links["export"]
    );
    assert!(!spc.exists(), "the station created the drop directory");
    let dir = e2e::scan_dir(&r);
    assert!(dir.join("report.json").exists());
    let id = dir.file_name().unwrap().to_str().unwrap().to_owned();

    // A restart while they are away: the scan waits in the queue on disk and the new
    // process names the same faults.
    e2e::sigterm(&d);
    assert!(e2e::wait_exit(&mut d).success());
    assert_eq!(
        std::fs::read_dir(r.out().join("outbox/export"))
            .unwrap()
            .filter(|e| e.as_ref().unwrap().path().extension() == Some("json".as_ref()))
            .count(),
        1
    );
    let mut d = crate::mqtt_broker::spawn_logged(&r);
    crate::mqtt_broker::wait_socket(&r).await;
    e2e::wait_status(&r, "the fault named after the restart", |s| {
        s.links
            .get("export")
            .is_some_and(|l| !l.ok && l.queued == 1 && l.message.contains("[export] dfq-dir"))
    })
    .await;

    // Both back: the files arrive, the link is well again.
    std::fs::create_dir(&spc).unwrap();
    drop(mount);
    let s = e2e::wait_status(&r, "the queue emptied", |s| {
        s.links.get("export").is_some_and(|l| l.ok && l.queued == 0)
    })
    .await;
    assert!(s.links["export"].message.contains("exported"), "{s:?}");
    let dfq = spc.join(format!("{id}.dfq"));
    let qif = qifs.join(format!("{id}.qif"));
    // Without a specification: Ra, Rq and Rz without limits, every line's value.
    let v = read_dfq(&dfq);
    let dfq_text = String::from_utf8_lossy(&std::fs::read(&dfq).unwrap()).into_owned();
    assert_eq!(v["K0100"], 3, "{dfq_text}");
    assert_eq!(v["characteristics"]["1"]["K2001"], "Ra");
    assert!(v["characteristics"]["1"].get("K2111").is_none());
    assert_eq!(
        v["values"]["1"].as_array().map(Vec::len),
        Some(e2e::LINES as usize),
        "{dfq_text}"
    );
    assert_valid_qif(&qif);
    let log = std::fs::read_to_string(r.dir.path().join("daemon.log")).unwrap();
    assert!(log.contains("[export] dfq-dir"), "{log}");
    let done = std::fs::read_dir(r.out().join("outbox/export/done"))
        .unwrap()
        .count();
    assert_eq!(done, 1);
    e2e::sigterm(&d);
    e2e::wait_exit(&mut d);
}

/// A tmpfs mounted on a directory, unmounted when dropped.
struct Tmpfs(PathBuf);

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.0).output();
    }
}

#[test]
fn a_full_drop_directory_is_named_and_keeps_no_partial_file() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("spc");
    std::fs::create_dir(&dir).unwrap();
    let o = Command::new("mount")
        .args(["-t", "tmpfs", "-o", "size=8k", "tmpfs"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let _mount = Tmpfs(dir.clone());
    let big = vec![b'K'; 64 * 1024];
    let e = surfscan::publish::export::drop_file(
        surfscan::publish::export::Format::Qif,
        &dir,
        "s.qif",
        &big,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("full") && e.contains("[export] qif-dir"), "{e}");
    assert_eq!(
        std::fs::read_dir(&dir).unwrap().count(),
        0,
        "a file was left"
    );
}

#[test]
fn a_bad_export_table_exits_78_naming_the_key() {
    crate::common::assert_tables_refused(
        "export",
        &[
            ("dfq-dir = \"spc/in\"", "export.dfq-dir"),
            ("qif-dir = \"\"", "export.qif-dir"),
            ("", "export"),
            ("csv-dir = \"/srv\"", "csv-dir"),
        ],
    );
}
