//! The outbox: what a publisher has still to deliver, on disk, so that a broker that is away
//! delays a message and a restart loses none.
//!
//! One directory per publisher (`<output dir>/outbox/mqtt/`), one file per message named by
//! its sequence number (`0000000000000042.json`), written atomically and durably
//! ([`crate::atomic`]) before the publisher is told of it, and removed only when the broker
//! has acknowledged it (QoS 1 `PUBACK`). Messages go out oldest first, one at a time, so a
//! subscriber sees them in the order they happened. The message's `id` is its sender's
//! (see [`super::message_id`]), stored with it, so a message sent again after a reconnection
//! carries the same one; the next sequence number is kept in `next-id` so that a file name is
//! never reused, even after the outbox was emptied.
//!
//! Bounded: beyond `capacity` messages the oldest is removed (and the caller told, to log
//! it). A file that cannot be read back (damaged by a crash of the disk) is moved to
//! `damaged/` and named in the log; it never stops the rest.
//!
//! Layer 4 (process edge): depends on [`crate::atomic`] and serde_json; plain blocking file
//! I/O (callers run it off the scan's path).

use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::fs;
use std::io::{self, Write as _};
use std::path::{Path, PathBuf};

/// A message waiting to be delivered.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Message {
    /// Its sequence number in this outbox.
    pub seq: u64,
    /// Where it goes below the publisher's root (`events`, `results`).
    pub topic: String,
    /// The JSON sent, its `id` member included.
    pub payload: serde_json::Value,
}

/// The outbox of one publisher.
#[derive(Debug)]
pub struct Outbox {
    dir: PathBuf,
    capacity: u64,
    next: u64,
    waiting: VecDeque<u64>,
}

const NEXT_ID: &str = "next-id";

fn file_name(seq: u64) -> String {
    format!("{seq:016}.json")
}

fn seq_of(name: &str) -> Option<u64> {
    let digits = name.strip_suffix(".json")?;
    (digits.len() == 16 && digits.bytes().all(|b| b.is_ascii_digit()))
        .then(|| digits.parse().ok())
        .flatten()
}

impl Outbox {
    /// Opens (creating it if need be) the outbox in `dir`.
    pub fn open(dir: &Path, capacity: u64) -> io::Result<Outbox> {
        fs::create_dir_all(dir)?;
        let mut waiting = Vec::new();
        for entry in fs::read_dir(dir)? {
            let entry = entry?;
            let name = entry.file_name();
            let name = name.to_string_lossy();
            if let Some(seq) = seq_of(&name) {
                waiting.push(seq);
            } else if name.starts_with('.') && name.contains(".tmp") {
                // A write cut off by a crash: the message was never acknowledged to anyone.
                let _ = fs::remove_file(entry.path());
            }
        }
        waiting.sort_unstable();
        let stored = match fs::read_to_string(dir.join(NEXT_ID)) {
            Ok(t) => t.trim().parse::<u64>().unwrap_or(0),
            Err(e) if e.kind() == io::ErrorKind::NotFound => 0,
            Err(e) => return Err(e),
        };
        let next = stored.max(waiting.last().map_or(1, |s| s + 1)).max(1);
        Ok(Outbox {
            dir: dir.to_path_buf(),
            capacity: capacity.max(1),
            next,
            waiting: waiting.into(),
        })
    }

    /// Messages waiting.
    pub fn len(&self) -> u64 {
        self.waiting.len() as u64
    }

    /// True when nothing waits.
    pub fn is_empty(&self) -> bool {
        self.waiting.is_empty()
    }

    /// Stores a message for `topic` durably; returns how many of the oldest were removed to
    /// stay within the capacity.
    pub fn push(
        &mut self,
        topic: &str,
        payload: serde_json::Map<String, serde_json::Value>,
    ) -> io::Result<u64> {
        let seq = self.next;
        let message = Message {
            seq,
            topic: topic.to_owned(),
            payload: serde_json::Value::Object(payload),
        };
        let text = serde_json::to_vec(&message).map_err(io::Error::other)?;
        // The counter first: a crash between the two writes skips a number, never reuses one.
        crate::atomic::write_atomically(&self.dir.join(NEXT_ID), |w| writeln!(w, "{}", seq + 1))?;
        self.next = seq + 1;
        crate::atomic::write_atomically(&self.dir.join(file_name(seq)), |w| w.write_all(&text))?;
        self.waiting.push_back(seq);
        let mut dropped = 0;
        while self.len() > self.capacity {
            if let Some(old) = self.waiting.pop_front() {
                self.remove(old)?;
                dropped += 1;
            }
        }
        Ok(dropped)
    }

    /// The oldest message waiting. A file that cannot be read is moved to `damaged/` (its
    /// path returned in the second member, for the log) and the next one is tried.
    pub fn head(&mut self) -> io::Result<(Option<Message>, Vec<PathBuf>)> {
        let mut damaged = Vec::new();
        while let Some(&seq) = self.waiting.front() {
            let path = self.dir.join(file_name(seq));
            let parsed = match fs::read(&path) {
                Ok(bytes) => serde_json::from_slice::<Message>(&bytes).ok(),
                Err(e) if e.kind() == io::ErrorKind::NotFound => {
                    self.waiting.pop_front();
                    continue;
                }
                Err(e) => return Err(e),
            };
            match parsed {
                Some(m) if m.seq == seq => return Ok((Some(m), damaged)),
                _ => {
                    let aside = self.dir.join("damaged");
                    fs::create_dir_all(&aside)?;
                    let to = aside.join(file_name(seq));
                    fs::rename(&path, &to)?;
                    damaged.push(to);
                    self.waiting.pop_front();
                }
            }
        }
        Ok((None, damaged))
    }

    /// The message `seq` was delivered: its file goes.
    pub fn ack(&mut self, seq: u64) -> io::Result<()> {
        if let Some(i) = self.waiting.iter().position(|s| *s == seq) {
            self.waiting.remove(i);
        }
        self.remove(seq)
    }

    fn remove(&self, seq: u64) -> io::Result<()> {
        match fs::remove_file(self.dir.join(file_name(seq))) {
            Ok(()) => {}
            Err(e) if e.kind() == io::ErrorKind::NotFound => {}
            Err(e) => return Err(e),
        }
        fs::File::open(&self.dir)?.sync_all()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn obj(v: serde_json::Value) -> serde_json::Map<String, serde_json::Value> {
        v.as_object().unwrap().clone()
    }

    #[test]
    fn messages_come_back_in_order_across_a_reopen_and_files_are_never_reused() {
        let d = tempfile::tempdir().unwrap();
        let mut o = Outbox::open(d.path(), 100).unwrap();
        o.push("events", obj(json!({"kind":"started","id":"a"})))
            .unwrap();
        o.push("events", obj(json!({"kind":"success","id":"b"})))
            .unwrap();
        drop(o);
        let mut o = Outbox::open(d.path(), 100).unwrap();
        let (m, _) = o.head().unwrap();
        let m = m.unwrap();
        assert_eq!((m.seq, &m.payload["kind"]), (1, &json!("started")));
        assert_eq!(m.payload["id"], "a");
        o.ack(m.seq).unwrap();
        let m = o.head().unwrap().0.unwrap();
        assert_eq!((m.seq, &m.payload["id"]), (2, &json!("b")));
        o.ack(m.seq).unwrap();
        assert!(o.head().unwrap().0.is_none());
        // Emptied and reopened: the next message gets a new file, after the last one.
        let mut o = Outbox::open(d.path(), 100).unwrap();
        o.push("events", obj(json!({"id":"c"}))).unwrap();
        assert_eq!(o.head().unwrap().0.unwrap().seq, 3);
    }

    #[test]
    fn beyond_its_capacity_the_oldest_message_goes() {
        let d = tempfile::tempdir().unwrap();
        let mut o = Outbox::open(d.path(), 2).unwrap();
        for k in 0..3 {
            let dropped = o.push("events", obj(json!({"k": k}))).unwrap();
            assert_eq!(dropped, u64::from(k == 2));
        }
        assert_eq!(o.len(), 2);
        assert_eq!(o.head().unwrap().0.unwrap().payload["k"], 1);
    }

    #[test]
    fn a_damaged_file_is_set_aside_and_the_next_is_delivered() {
        let d = tempfile::tempdir().unwrap();
        let mut o = Outbox::open(d.path(), 10).unwrap();
        o.push("events", obj(json!({"k": 1}))).unwrap();
        o.push("events", obj(json!({"k": 2}))).unwrap();
        fs::write(d.path().join(file_name(1)), b"{\"seq\":1,\"topi").unwrap();
        fs::write(d.path().join(".0000000000000009.json.tmp"), b"x").unwrap();
        let mut o = Outbox::open(d.path(), 10).unwrap();
        assert!(!d.path().join(".0000000000000009.json.tmp").exists());
        let (m, damaged) = o.head().unwrap();
        assert_eq!(m.unwrap().payload["k"], 2);
        assert_eq!(damaged, vec![d.path().join("damaged").join(file_name(1))]);
    }
}
