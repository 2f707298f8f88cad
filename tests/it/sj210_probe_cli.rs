//! `surfscan probe` end to end over a pseudo-terminal: the real transport opens the pty
//! slave, a scripted fake instrument answers on the master, and the transcript written with
//! `--record` must hold every frame and no command that moves the stylus.

use std::fs::File;
use std::io::{Read, Write};
use std::sync::mpsc;
use std::time::Duration;
use surfscan::cli::probe::{run, Args};

const SCRIPT: &[(&str, &[u8])] = &[
    ("RDSTU00", b"OK000\r"),
    ("RDSJ 01", b"OKV1.01\r"),
    ("RDSJ 00", b"OK000\r"),
    ("RDSTU01", b"OK000\r"),
    ("RDCON", b"OK3120504.0012\r"),
    ("RDPAR", b"OK02\r"),
    ("CTOFF01", b"OK\r"),
    ("RDPSA", b"OK12.5\r"),
];

#[test]
fn probe_is_read_only_and_records_every_frame() {
    let pty = nix::pty::openpty(None, None).unwrap();
    let slave_path = nix::unistd::ttyname(&pty.slave).unwrap();
    let mut master = File::from(pty.master);
    let (tx, rx) = mpsc::channel::<Result<Vec<String>, String>>();
    std::thread::spawn(move || {
        let mut seen = Vec::new();
        for (expect, reply) in SCRIPT {
            let mut line = Vec::new();
            loop {
                let mut b = [0u8; 1];
                match master.read(&mut b) {
                    Ok(1) if b[0] == b'\r' => break,
                    Ok(1) => line.push(b[0]),
                    other => {
                        let _ = tx.send(Err(format!("read ended {other:?} before {expect:?}")));
                        return;
                    }
                }
            }
            let got = String::from_utf8_lossy(&line).to_string();
            if got != *expect {
                let _ = tx.send(Err(format!("expected {expect:?}, got {got:?}")));
                return;
            }
            seen.push(got);
            if master.write_all(reply).is_err() {
                let _ = tx.send(Err("write failed".into()));
                return;
            }
        }
        let _ = tx.send(Ok(seen));
        // Keep the master open until the client is done with the port.
        let mut sink = [0u8; 64];
        while let Ok(n) = master.read(&mut sink) {
            if n == 0 {
                break;
            }
        }
    });
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("probe.toml");
    std::fs::write(
        &config,
        format!(
            "[instrument]\nport = \"{}\"\nbaud = 38400\n[instrument.timeouts]\nfirst-byte-ms = 3000\n",
            slave_path.display()
        ),
    )
    .unwrap();
    let record = dir.path().join("t.txt");
    run(Args {
        config,
        record: Some(record.clone()),
        trace: false,
        notes: "pty test".into(),
        readout: false,
        forms: Vec::new(),
        passthrough: None,
        for_s: None,
    })
    .unwrap();
    let seen = rx.recv_timeout(Duration::from_secs(20)).unwrap().unwrap();
    assert_eq!(seen.len(), SCRIPT.len());
    drop(pty.slave);
    let text = std::fs::read_to_string(&record).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "# surfscan transcript v1");
    assert_eq!(lines[2], "# model: sj210");
    assert_eq!(lines[3], "# firmware: V1.01");
    assert!(lines[4].starts_with("# date: "));
    assert_eq!(lines[5], "# notes: pty test");
    let records: Vec<(&str, &str)> = lines[6..]
        .iter()
        .map(|l| {
            let mut it = l.splitn(3, ' ');
            let _t = it.next().unwrap();
            (it.next().unwrap(), it.next().unwrap())
        })
        .collect();
    assert_eq!(records.len(), 2 * SCRIPT.len());
    for (i, (cmd, reply)) in SCRIPT.iter().enumerate() {
        assert_eq!(records[2 * i], (">", format!("{cmd}\\r").as_str()));
        let want = String::from_utf8_lossy(reply).replace('\r', "\\r");
        assert_eq!(records[2 * i + 1], ("<", want.as_str()));
    }
    assert!(
        !text.contains("CTSTA"),
        "a read-only probe must not start a trace"
    );
}
