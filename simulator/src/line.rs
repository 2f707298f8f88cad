//! The line speed the host set on the instrument's pseudo-terminal, and what a host at another
//! rate than the instrument's gets: a real SJ-210 is set to one baud rate on its own panel, and
//! a host at another rate gets silence (the instrument sees no command in the noise) or line
//! noise (its reply read at the wrong rate), never an answer.
//!
//! A pty keeps the speed the client sets (`TCSETS2`, as the serialport crate uses) and hands it
//! back on `TCGETS2` from the simulator's side. Linux clears the parity bit on a pty, so only
//! the rate can be checked here.
//!
//! Depends on `libc` for the ioctl and on [`crate::stats`].

use crate::stats::SimStats;
use std::io;
use std::os::fd::{AsRawFd, OwnedFd};
use std::sync::Arc;

/// What the instrument does with a command sent at another rate than its own.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Mismatch {
    /// Nothing comes back.
    #[default]
    Silent,
    /// Noise without a line end comes back (the reply, as bits at the wrong rate).
    Noise,
}

/// The speed a host set on the pty, read through the simulator's own slave descriptor.
#[derive(Debug)]
pub struct HostLine {
    fd: OwnedFd,
}

impl HostLine {
    /// Reads the host's speed through `slave` (a duplicate of the simulator's descriptor).
    pub fn new(slave: OwnedFd) -> HostLine {
        HostLine { fd: slave }
    }

    /// The output speed the host set, in baud.
    pub fn baud(&self) -> io::Result<u32> {
        // SAFETY: termios2 is plain data; all-zero is a valid value to be overwritten.
        let mut t: libc::termios2 = unsafe { std::mem::zeroed() };
        // SAFETY: TCGETS2 writes one termios2 through the pointer, valid for the call; the
        // descriptor is owned by `self` and open.
        let rc = unsafe { libc::ioctl(self.fd.as_raw_fd(), libc::TCGETS2, &mut t) };
        if rc < 0 {
            return Err(io::Error::last_os_error());
        }
        Ok(t.c_ospeed)
    }
}

/// The instrument's rate and the host's line: whether a frame arrived at the right speed.
#[derive(Debug)]
pub struct LineGate {
    /// The rate the instrument is set to.
    pub baud: u32,
    /// What a mismatched host gets.
    pub mismatch: Mismatch,
    /// The host's side.
    pub host: HostLine,
    /// Where frames at the wrong rate are counted.
    pub stats: Arc<SimStats>,
}

impl LineGate {
    /// `None` when the host's rate matches (the instrument reads the frame and answers),
    /// else the bytes that come back instead (empty for silence): the instrument saw noise,
    /// so nothing it was asked happens. A speed that cannot be read counts as a match: the
    /// check simulates the wire, it is no reason to stop answering.
    pub fn garbled(&self) -> Option<Vec<u8>> {
        match self.host.baud() {
            Ok(b) if b != self.baud => {
                SimStats::bump(&self.stats.frames_at_wrong_rate);
                Some(match self.mismatch {
                    Mismatch::Silent => Vec::new(),
                    // What it sends back to what it could not read, at its own rate.
                    Mismatch::Noise => noise(b"NG031\r"),
                })
            }
            _ => None,
        }
    }
}

/// A reply as a host at the wrong rate reads it: fewer bytes, every one with the top bit set,
/// so never a CR or an `O`/`K`.
pub fn noise(reply: &[u8]) -> Vec<u8> {
    reply.iter().step_by(2).map(|b| (b ^ 0x55) | 0x80).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nix::sys::termios::{cfsetspeed, tcgetattr, tcsetattr, BaudRate, SetArg};
    use std::os::fd::AsFd;

    #[test]
    fn the_host_rate_is_read_through_the_pty_and_a_mismatch_is_silence_or_noise() {
        let pair = nix::pty::openpty(None, None).unwrap();
        let stats = Arc::new(SimStats::default());
        let gate = |mismatch| LineGate {
            baud: 38400,
            mismatch,
            host: HostLine::new(pair.slave.try_clone().unwrap()),
            stats: stats.clone(),
        };
        let set = |rate| {
            let mut t = tcgetattr(pair.slave.as_fd()).unwrap();
            cfsetspeed(&mut t, rate).unwrap();
            tcsetattr(pair.slave.as_fd(), SetArg::TCSANOW, &t).unwrap();
        };
        set(BaudRate::B38400);
        assert_eq!(gate(Mismatch::Silent).host.baud().unwrap(), 38400);
        assert_eq!(gate(Mismatch::Silent).garbled(), None);
        assert_eq!(SimStats::get(&stats.frames_at_wrong_rate), 0);
        set(BaudRate::B9600);
        assert_eq!(gate(Mismatch::Silent).host.baud().unwrap(), 9600);
        assert_eq!(gate(Mismatch::Silent).garbled(), Some(Vec::new()));
        let n = gate(Mismatch::Noise).garbled().unwrap();
        assert_eq!(n.len(), 3);
        assert!(n.iter().all(|b| *b >= 0x80), "{n:?}");
        assert_eq!(SimStats::get(&stats.frames_at_wrong_rate), 2);
    }
}
