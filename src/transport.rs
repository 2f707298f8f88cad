//! The only code that opens a real serial port.
//!
//! Everything above this module (instrument client, stage drivers) is generic over
//! `AsyncRead + AsyncWrite`, so a pseudo-terminal, an in-memory pipe or a scripted transcript
//! can stand in for the port. A device that disappears (EOF, EIO, ENXIO, ENODEV) is reported
//! as [`TransportError::Vanished`] so the scan layer can suspend and reconnect.
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
        _ if source.raw_os_error() == Some(libc::ENXIO)
            || source.raw_os_error() == Some(libc::ENODEV) =>
        {
            TransportError::NotFound { path, source }
        }
        _ => TransportError::Open { path, source },
    }
}

/// Opens the port 8 data bits, 1 stop bit, with the given baud, parity and flow control,
/// exclusively (TIOCEXCL), so a second process cannot interleave bytes.
pub fn open(settings: &SerialSettings) -> Result<SerialStream, TransportError> {
    if !std::path::Path::new(&settings.path).exists() {
        return Err(TransportError::NotFound {
            path: settings.path.clone(),
            source: io::Error::new(io::ErrorKind::NotFound, "no such device node"),
        });
    }
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
