//! The only code that opens a real serial port.
//!
//! Everything above this module (instrument client, stage drivers) is generic over
//! `AsyncRead + AsyncWrite`, so a pseudo-terminal, an in-memory pipe or a scripted transcript
//! can stand in for the port. A device that disappears (EOF, EIO, ENXIO, ENODEV) is reported
//! as [`TransportError::Vanished`] so the scan layer can suspend and reconnect.
//!
//! Both drivers write through [`send`]: every write to a device has a deadline, and none
//! waits for the bytes to leave the wire (`flush` of a serial port is a blocking `tcdrain`,
//! which would hold a runtime thread for as long as the link takes no bytes).
//!
//! Layer 2 (I/O adapter): depends on tokio-serial only; nothing in the crate above layer 0.

use serde::{Deserialize, Serialize};
use std::io;
use std::time::Duration;
use thiserror::Error;
use tokio_serial::{SerialPortBuilderExt, SerialStream};

/// Parity setting of the link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Parity {
    /// No parity bit.
    #[default]
    None,
    /// Even parity.
    Even,
    /// Odd parity.
    Odd,
}

/// Flow control of the link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum FlowControl {
    /// No flow control.
    #[default]
    None,
    /// Hardware RTS/CTS.
    RtsCts,
}

/// Settings of one serial link: 8 data bits and 1 stop bit are fixed (SJ-210 manual
/// p. 17-12; GRBL and Zaber use 8N1 too).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SerialSettings {
    /// Device path; prefer a stable `/dev/serial/by-id/…` or udev symlink.
    pub path: String,
    /// Baud rate.
    pub baud: u32,
    /// Parity.
    pub parity: Parity,
    /// Flow control.
    pub flow_control: FlowControl,
}

/// Failure to open or use a serial link.
#[derive(Debug, Error)]
pub enum TransportError {
    /// The device node does not exist (unplugged, wrong path, udev rule missing).
    #[error("serial device {path} is not present: {source}. Check the cable and the udev symlink, or correct the port in the config")]
    NotFound {
        /// Path tried.
        path: String,
        /// Underlying error.
        source: io::Error,
    },
    /// Permission denied on the device node.
    #[error("no permission to open {path}: {source}. Add the service user to the 'dialout' group (or the group the udev rule sets)")]
    PermissionDenied {
        /// Path tried.
        path: String,
        /// Underlying error.
        source: io::Error,
    },
    /// Another process holds the port (exclusive open failed).
    #[error("serial device {path} is busy (held by another process): {source}. Stop the other program, or the daemon if you are running a foreground command")]
    Busy {
        /// Path tried.
        path: String,
        /// Underlying error.
        source: io::Error,
    },
    /// The device went away while in use (EOF / EIO / ENXIO / ENODEV).
    #[error("serial device {path} vanished: {detail}")]
    Vanished {
        /// Path in use.
        path: String,
        /// What was observed.
        detail: String,
    },
    /// The path names a regular file, a directory or another node that is not a terminal.
    #[error("{path} is {what}, not a serial device: set the port to the device node, e.g. /dev/ttyUSB0 or a /dev/serial/by-id/… link")]
    NotADevice {
        /// Path tried.
        path: String,
        /// What it is instead ("a regular file", "a directory", …).
        what: &'static str,
    },
    /// Any other error opening the port.
    #[error("cannot open serial device {path}: {source}")]
    Open {
        /// Path tried.
        path: String,
        /// Underlying error.
        source: io::Error,
    },
}

impl TransportError {
    /// True when the device is absent or gone (the scan suspends and reconnects).
    pub fn is_absent(&self) -> bool {
        matches!(
            self,
            TransportError::NotFound { .. } | TransportError::Vanished { .. }
        )
    }
}

/// Why [`send`] could not hand a command's bytes to the link.
#[derive(Debug, Error)]
pub enum SendError {
    /// The link stopped taking bytes: flow control holding the host back (CTS low with
    /// `flow-control = "rts-cts"`), a wedged USB-serial adapter, a device that reads nothing.
    #[error("the link took {written} of the command's {len} byte(s) and then none for {waited_ms} ms (flow control holding the host back: check the cable, the CTS line and the device's power; or a wedged USB-serial adapter: replug it)")]
    Stalled {
        /// Bytes the link took.
        written: usize,
        /// Bytes of the command.
        len: usize,
        /// The deadline, ms.
        waited_ms: u64,
    },
    /// The write failed.
    #[error(transparent)]
    Io(io::Error),
}

/// Hands `bytes` to the link within `deadline`, or says how far it got. It does not flush:
/// the bytes are the kernel's to send once written, and a reply's timeout covers their time
/// on the wire; waiting for the wire to drain (`tcdrain`) would block a thread without a
/// deadline.
pub async fn send<W: tokio::io::AsyncWrite + Unpin>(
    io: &mut W,
    bytes: &[u8],
    deadline: Duration,
) -> Result<(), SendError> {
    use tokio::io::AsyncWriteExt;
    let end = tokio::time::Instant::now() + deadline;
    let mut written = 0;
    while let Some(rest) = bytes.get(written..).filter(|r| !r.is_empty()) {
        match tokio::time::timeout_at(end, io.write(rest)).await {
            Err(_) => {
                return Err(SendError::Stalled {
                    written,
                    len: bytes.len(),
                    waited_ms: u64::try_from(deadline.as_millis()).unwrap_or(u64::MAX),
                })
            }
            Ok(Ok(0)) => return Err(SendError::Io(io::ErrorKind::WriteZero.into())),
            Ok(Ok(n)) => written += n,
            Ok(Err(e)) => return Err(SendError::Io(e)),
        }
    }
    Ok(())
}

/// True when an I/O error on an open port means the device has gone away.
pub fn is_vanished_io(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::UnexpectedEof | io::ErrorKind::BrokenPipe | io::ErrorKind::NotConnected
    ) || matches!(
        e.raw_os_error(),
        Some(libc::EIO) | Some(libc::ENXIO) | Some(libc::ENODEV) | Some(libc::EBADF)
    )
}

fn classify_open_error(path: &str, e: tokio_serial::Error) -> TransportError {
    let source: io::Error = e.into();
    let path = path.to_string();
    match source.kind() {
        io::ErrorKind::NotFound => TransportError::NotFound { path, source },
        io::ErrorKind::PermissionDenied => TransportError::PermissionDenied { path, source },
        _ if source.raw_os_error() == Some(libc::EBUSY) => TransportError::Busy { path, source },
        _ if source.raw_os_error() == Some(libc::ENOTTY) => TransportError::NotADevice {
            path,
            what: "not a terminal",
        },
        _ if source.raw_os_error() == Some(libc::ENXIO)
            || source.raw_os_error() == Some(libc::ENODEV) =>
        {
            TransportError::NotFound { path, source }
        }
        _ => TransportError::Open { path, source },
    }
}

/// Checks that `path` names a device node that could be a serial port (a character device,
/// following symlinks): absent is [`TransportError::NotFound`], a regular file, directory,
/// FIFO or socket is [`TransportError::NotADevice`].
pub fn check_device_node(path: &str) -> Result<(), TransportError> {
    use std::os::unix::fs::FileTypeExt;
    let meta = std::fs::metadata(path).map_err(|source| match source.kind() {
        io::ErrorKind::PermissionDenied => TransportError::PermissionDenied {
            path: path.to_string(),
            source,
        },
        _ => TransportError::NotFound {
            path: path.to_string(),
            source: io::Error::new(io::ErrorKind::NotFound, "no such device node"),
        },
    })?;
    let t = meta.file_type();
    let what = if t.is_char_device() {
        return Ok(());
    } else if t.is_file() {
        "a regular file"
    } else if t.is_dir() {
        "a directory"
    } else if t.is_fifo() {
        "a FIFO"
    } else if t.is_socket() {
        "a socket"
    } else {
        "a block device"
    };
    Err(TransportError::NotADevice {
        path: path.to_string(),
        what,
    })
}

/// Opens the port 8 data bits, 1 stop bit, with the given baud, parity and flow control,
/// exclusively (TIOCEXCL), so a second process cannot interleave bytes.
pub fn open(settings: &SerialSettings) -> Result<SerialStream, TransportError> {
    check_device_node(&settings.path)?;
    let parity = match settings.parity {
        Parity::None => tokio_serial::Parity::None,
        Parity::Even => tokio_serial::Parity::Even,
        Parity::Odd => tokio_serial::Parity::Odd,
    };
    let flow = match settings.flow_control {
        FlowControl::None => tokio_serial::FlowControl::None,
        FlowControl::RtsCts => tokio_serial::FlowControl::Hardware,
    };
    let mut stream = tokio_serial::new(&settings.path, settings.baud)
        .data_bits(tokio_serial::DataBits::Eight)
        .stop_bits(tokio_serial::StopBits::One)
        .parity(parity)
        .flow_control(flow)
        .timeout(Duration::from_millis(100))
        .open_native_async()
        .map_err(|e| classify_open_error(&settings.path, e))?;
    stream
        .set_exclusive(true)
        .map_err(|e| classify_open_error(&settings.path, e))?;
    Ok(stream)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A link that takes 4 bytes and then none (its reader stopped): the send gives up at the
    /// deadline and says how far it got; once the reader takes bytes again a send goes through.
    #[tokio::test(start_paused = true)]
    async fn a_link_that_stops_taking_bytes_fails_the_send_at_its_deadline() {
        use tokio::io::AsyncReadExt;
        let (mut host, mut device) = tokio::io::duplex(4);
        let t0 = tokio::time::Instant::now();
        let e = send(&mut host, b"RDSTU01\r", Duration::from_millis(500))
            .await
            .unwrap_err();
        assert!(
            matches!(
                e,
                SendError::Stalled {
                    written: 4,
                    len: 8,
                    waited_ms: 500
                }
            ),
            "{e:?}"
        );
        assert_eq!(t0.elapsed(), Duration::from_millis(500));
        assert!(
            e.to_string().contains("took 4 of the command's 8 byte(s)"),
            "{e}"
        );
        let mut got = [0u8; 4];
        device.read_exact(&mut got).await.unwrap();
        assert_eq!(&got, b"RDST");
        send(&mut host, b"OK\r", Duration::from_millis(500))
            .await
            .unwrap();
    }

    #[test]
    fn a_regular_file_or_directory_is_named_as_such_not_as_not_a_typewriter() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("port.txt");
        std::fs::write(&file, b"x").unwrap();
        let file = file.to_str().unwrap();
        let e = check_device_node(file).unwrap_err();
        assert!(
            matches!(
                e,
                TransportError::NotADevice {
                    what: "a regular file",
                    ..
                }
            ),
            "{e}"
        );
        assert!(
            e.to_string()
                .contains("is a regular file, not a serial device"),
            "{e}"
        );
        let e = check_device_node(dir.path().to_str().unwrap()).unwrap_err();
        assert!(e.to_string().contains("is a directory"), "{e}");
        let e = check_device_node("/nonexistent/ttyUSB9").unwrap_err();
        assert!(e.is_absent(), "{e}");
        // A character device passes (whether it is a serial port the open finds out).
        check_device_node("/dev/null").unwrap();
        let e = open(&SerialSettings {
            path: file.to_string(),
            baud: 9600,
            parity: Parity::None,
            flow_control: FlowControl::None,
        })
        .unwrap_err();
        assert!(matches!(e, TransportError::NotADevice { .. }), "{e}");
    }
}
