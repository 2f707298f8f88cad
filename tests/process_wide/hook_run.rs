//! The notification hook as a real process: its environment, its timeout, and a command
//! that cannot be started.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use surfscan::hook::{Hook, HookOutcome, HookSettings};
use surfscan::scan::event::{ScanEvent, ScanEventKind as HookStatus};

fn event(kind: HookStatus) -> ScanEvent {
    ScanEvent {
        scan_id: "G-0142".into(),
        kind,
        reason: "stage following error on line 12".into(),
        dir: PathBuf::from("/var/lib/surfscan/scans/G-0142"),
        time: "2026-03-01T10:00:00Z".parse().unwrap(),
        internal: false,
        results: None,
    }
}

fn script(dir: &Path, name: &str, body: &str) -> PathBuf {
    use std::os::unix::fs::PermissionsExt;
    let p = dir.join(name);
    std::fs::write(&p, format!("#!/bin/sh\n{body}\n")).unwrap();
    std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o755)).unwrap();
    p
}

fn hook(command: Vec<String>, timeout_s: u64) -> Hook {
    let settings = HookSettings { command, timeout_s };
    settings.validate().unwrap();
    Hook::new(&settings).expect("a command is configured")
}

// The guard is held across awaits on purpose: it keeps the process-wide environment change
// away from the other tests of this binary, and nothing inside this test contends for it.
#[allow(clippy::await_holding_lock)]
#[tokio::test]
async fn the_hook_sees_the_scan_s_variables() {
    let _env = crate::process_state();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("env.txt");
    let s = script(
        dir.path(),
        "hook.sh",
        r#"printf '%s|%s|%s|%s|%s|%s|%s\n' "$SURFSCAN_SCAN_ID" "$SURFSCAN_STATUS" "$SURFSCAN_REASON" "$SURFSCAN_SCAN_DIR" "${SURFSCAN_INTERNAL-unset}" "$1" "${NOTIFY_SOCKET-unset}" > "$2""#,
    );
    let h = hook(
        vec![
            s.display().to_string(),
            "first arg with spaces".into(),
            out.display().to_string(),
        ],
        10,
    );
    // The daemon's own systemd variables must not reach the hook.
    std::env::set_var("NOTIFY_SOCKET", "/run/systemd/notify");
    let outcome = h.fire(event(HookStatus::Fail)).await.unwrap();
    assert!(matches!(outcome, HookOutcome::Succeeded), "{outcome:?}");
    assert_eq!(
        std::fs::read_to_string(&out).unwrap(),
        "G-0142|fail|stage following error on line 12|/var/lib/surfscan/scans/G-0142|0|first arg with spaces|unset\n"
    );
    // A bug that ended the scan: `SURFSCAN_INTERNAL` is 1.
    let bug = ScanEvent {
        internal: true,
        ..event(HookStatus::Fail)
    };
    let outcome = h.run(&bug).await;
    assert!(matches!(outcome, HookOutcome::Succeeded), "{outcome:?}");
    let line = std::fs::read_to_string(&out).unwrap();
    assert_eq!(line.split('|').nth(4), Some("1"), "{line}");
    // Every other run sets it too, to 0.
    for (status, word) in [
        (HookStatus::Success, "success"),
        (HookStatus::Abort, "abort"),
        (HookStatus::Suspended, "suspended"),
    ] {
        let outcome = h.run(&event(status)).await;
        assert!(matches!(outcome, HookOutcome::Succeeded), "{outcome:?}");
        let line = std::fs::read_to_string(&out).unwrap();
        let fields: Vec<&str> = line.split('|').collect();
        assert_eq!((fields[1], fields[4]), (word, "0"), "{line}");
    }
}

/// The `SURFSCAN_*` names in `text`.
fn surfscan_names(text: &str) -> std::collections::BTreeSet<String> {
    text.split(|c: char| !(c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_'))
        .filter(|w| w.starts_with("SURFSCAN_"))
        .map(str::to_owned)
        .collect()
}

/// The hook's variables are exactly the rows of docs/integration.md's table, the one full
/// list the configuration's example, systemd/README.md and the module doc point to: a
/// variable added to the hook and not to that table (or one the table names and the hook
/// does not set) fails here.
#[allow(clippy::await_holding_lock)]
#[tokio::test]
async fn the_hook_sets_the_variables_its_one_documented_list_names() {
    let _env = crate::process_state();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("env.txt");
    let s = script(dir.path(), "env.sh", r#"env > "$1""#);
    let h = hook(vec![s.display().to_string(), out.display().to_string()], 10);
    let outcome = h.run(&event(HookStatus::Fail)).await;
    assert!(matches!(outcome, HookOutcome::Succeeded), "{outcome:?}");
    let inherited: Vec<String> = std::env::vars().map(|(k, _)| k).collect();
    let mut set: std::collections::BTreeSet<String> = std::fs::read_to_string(&out)
        .unwrap()
        .lines()
        .filter_map(|l| l.split_once('=').map(|(k, _)| k.to_owned()))
        .filter(|k| k.starts_with("SURFSCAN_"))
        .collect();
    set.retain(|k| !inherited.contains(k));

    let doc =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/integration.md"))
            .unwrap();
    let section = doc
        .split("\n## ")
        .find(|s| s.starts_with("The notification hook\n"))
        .expect("the section");
    let documented: std::collections::BTreeSet<String> = section
        .lines()
        .filter(|l| l.starts_with("| `SURFSCAN_"))
        .flat_map(|l| surfscan_names(l.split('|').nth(1).unwrap_or_default()))
        .collect();
    assert_eq!(set, documented);
    assert_eq!(documented.len(), 11, "{documented:?}");
}

#[tokio::test]
async fn a_non_zero_exit_is_reported() {
    let dir = tempfile::tempdir().unwrap();
    let s = script(dir.path(), "fails.sh", "exit 3");
    let outcome = hook(vec![s.display().to_string()], 10)
        .run(&event(HookStatus::Success))
        .await;
    match outcome {
        HookOutcome::Failed(exit) => assert_eq!(exit.code(), Some(3)),
        other => panic!("expected a failure, got {other:?}"),
    }
}

fn gone_or_zombie(pid: u32) -> bool {
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Err(_) => true,
        // The state follows the parenthesised command name.
        Ok(stat) => stat
            .rsplit_once(')')
            .map(|(_, rest)| rest.trim_start().starts_with('Z'))
            .unwrap_or(false),
    }
}

#[tokio::test]
async fn a_hook_that_hangs_is_killed_with_what_it_started() {
    let dir = tempfile::tempdir().unwrap();
    let pidfile = dir.path().join("sleep.pid");
    let s = script(
        dir.path(),
        "hangs.sh",
        &format!("sleep 300 &\necho $! > {}\nwait", pidfile.display()),
    );
    let t0 = Instant::now();
    let outcome = hook(vec![s.display().to_string()], 1)
        .fire(event(HookStatus::Suspended))
        .await
        .unwrap();
    let took = t0.elapsed();
    assert!(matches!(outcome, HookOutcome::TimedOut), "{outcome:?}");
    assert!(
        took >= Duration::from_millis(950) && took < Duration::from_secs(5),
        "{took:?}"
    );
    let pid: u32 = std::fs::read_to_string(&pidfile)
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(3);
    while !gone_or_zombie(pid) {
        assert!(
            Instant::now() < deadline,
            "the hook's child {pid} survived the timeout"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Collects formatted log output for one test.
#[derive(Clone, Default)]
struct Captured(Arc<Mutex<Vec<u8>>>);

impl std::io::Write for Captured {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[test]
fn a_missing_command_is_logged_not_fatal() {
    let logs = Captured::default();
    let sink = logs.clone();
    let subscriber = tracing_subscriber::fmt()
        .with_writer(move || sink.clone())
        .with_ansi(false)
        .finish();
    let _guard = tracing::subscriber::set_default(subscriber);
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let h = hook(vec!["/nonexistent/scan-done".into(), "--mail".into()], 5);
    let outcome = rt.block_on(h.run(&event(HookStatus::Abort)));
    match &outcome {
        HookOutcome::NotStarted(e) => assert_eq!(e.kind(), std::io::ErrorKind::NotFound),
        other => panic!("expected NotStarted, got {other:?}"),
    }
    let text = String::from_utf8(logs.0.lock().unwrap().clone()).unwrap();
    assert!(text.contains("WARN"), "{text}");
    assert!(text.contains("/nonexistent/scan-done --mail"), "{text}");
    assert!(text.contains("could not be started"), "{text}");
    assert!(text.contains("G-0142"), "{text}");
}

#[test]
fn settings_are_kebab_case_with_a_30_s_default_and_closed() {
    let s: HookSettings =
        toml::from_str("command = [\"/usr/local/bin/scan-done\", \"-v\"]").unwrap();
    assert_eq!(s.timeout_s, 30);
    assert_eq!(s.command, vec!["/usr/local/bin/scan-done", "-v"]);
    let s: HookSettings = toml::from_str("command = [\"x\"]\ntimeout-s = 5").unwrap();
    assert_eq!(s.timeout_s, 5);
    assert!(toml::from_str::<HookSettings>("command = [\"x\"]\ntimeout_s = 5").is_err());
    assert!(toml::from_str::<HookSettings>("command = \"x --y\"").is_err());
    let empty: HookSettings = toml::from_str("").unwrap();
    assert!(Hook::new(&empty).is_none());
    assert!(HookSettings {
        command: vec![String::new()],
        timeout_s: 30
    }
    .validate()
    .is_err());
    let zero = HookSettings {
        command: vec!["x".into()],
        timeout_s: 0,
    };
    assert!(zero
        .validate()
        .unwrap_err()
        .to_string()
        .contains("timeout-s"));
}
