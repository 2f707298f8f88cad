//! The control-socket client: connects, checks the daemon's greeting, sends requests and
//! reads messages, keeping each message's raw line for `--json` output.
//!
//! Errors are split by what the operator should do: the daemon is not reachable (start it),
//! it speaks another protocol version (install matching versions), the conversation broke
//! off (I/O), or it answered with an error of its own (printed as it said it).
//!
//! Layer 4 (process edge): depends on [`super::protocol`] and tokio.

use super::protocol::{Message, Request, PROTOCOL_VERSION};
use std::io;
use std::path::{Path, PathBuf};
use std::time::Duration;
use tokio::io::{AsyncBufReadExt, AsyncReadExt, AsyncWriteExt, BufReader};
use tokio::net::unix::{OwnedReadHalf, OwnedWriteHalf};
use tokio::net::UnixStream;

/// Longest message line the client accepts from the daemon, bytes.
pub const MAX_MESSAGE_BYTES: u64 = 1024 * 1024;

/// How long the daemon has to greet a new connection.
pub const GREETING_TIMEOUT: Duration = Duration::from_secs(5);

/// How long to wait for the answer to a request. The daemon bounds its own wait for the
/// scan runner (10 s), so this only fires when the daemon itself is stuck.
pub const REPLY_TIMEOUT: Duration = Duration::from_secs(30);

/// Why a conversation with the daemon failed.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// Nothing listens on the socket (missing file, connection refused, no permission).
    #[error("cannot reach the surfscan daemon at {path}: {source}; is the daemon running? systemctl status surfscan")]
    Unreachable {
        /// The socket path.
        path: PathBuf,
        /// The cause.
        source: io::Error,
    },
    /// The daemon speaks an incompatible protocol version.
    #[error("the daemon at {path} speaks control protocol {daemon} ({software}) but this surfscan speaks {client}; install matching surfscan versions for the daemon and the command line")]
    Incompatible {
        /// The socket path.
        path: PathBuf,
        /// The daemon's protocol version.
        daemon: u32,
        /// This client's protocol version.
        client: u32,
        /// The daemon's software string.
        software: String,
    },
    /// The daemon answered the connection with an error instead of its greeting (every
    /// connection slot is taken): it is there but cannot serve this one now.
    #[error("the surfscan daemon at {path} cannot serve this connection now: {message}")]
    Refused {
        /// The socket path.
        path: PathBuf,
        /// The daemon's own words.
        message: String,
    },
    /// The conversation broke off or the daemon sent something unreadable.
    #[error("control conversation with {path} failed: {cause}")]
    Io {
        /// The socket path.
        path: PathBuf,
        /// What happened.
        cause: String,
    },
}

/// One message as received: parsed, and the raw line it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct Received {
    /// The message.
    pub message: Message,
    /// Its JSON line, without the newline.
    pub raw: String,
}

/// A connection to the daemon whose greeting has been checked.
#[derive(Debug)]
pub struct ControlClient {
    path: PathBuf,
    reader: BufReader<OwnedReadHalf>,
    writer: OwnedWriteHalf,
    hello: Received,
}

impl ControlClient {
    /// Connects to `path` and reads the greeting; refuses an incompatible protocol version.
    pub async fn connect(path: &Path) -> Result<ControlClient, ClientError> {
        let stream =
            UnixStream::connect(path)
                .await
                .map_err(|source| ClientError::Unreachable {
                    path: path.to_owned(),
                    source,
                })?;
        let (reader, writer) = stream.into_split();
        let mut client = ControlClient {
            path: path.to_owned(),
            reader: BufReader::new(reader),
            writer,
            hello: Received {
                message: Message::Error {
                    message: String::new(),
                },
                raw: String::new(),
            },
        };
        let hello = match tokio::time::timeout(GREETING_TIMEOUT, client.next()).await {
            Ok(Ok(Some(m))) => m,
            Ok(Ok(None)) => return Err(client.io("the daemon closed the connection before greeting")),
            Ok(Err(e)) => return Err(e),
            Err(_) => {
                return Err(client.io(format!(
                    "no greeting within {} s; the process on this socket is not answering like a surfscan daemon",
                    GREETING_TIMEOUT.as_secs()
                )))
            }
        };
        match &hello.message {
            Message::Hello {
                protocol, software, ..
            } if *protocol != PROTOCOL_VERSION => Err(ClientError::Incompatible {
                path: path.to_owned(),
                daemon: *protocol,
                client: PROTOCOL_VERSION,
                software: software.clone(),
            }),
            Message::Hello { .. } => {
                client.hello = hello;
                Ok(client)
            }
            Message::Error { message } => Err(ClientError::Refused {
                path: path.to_owned(),
                message: message.clone(),
            }),
            _ => Err(client.io(format!(
                "expected a hello greeting first, got {}",
                hello.raw
            ))),
        }
    }

    /// The daemon's greeting.
    pub fn hello(&self) -> &Received {
        &self.hello
    }

    /// Sends one request line.
    pub async fn send(&mut self, request: &Request) -> Result<(), ClientError> {
        let mut line = serde_json::to_vec(request).map_err(|e| self.io(e.to_string()))?;
        line.push(b'\n');
        self.writer
            .write_all(&line)
            .await
            .map_err(|e| self.io(format!("sending the request: {e}")))
    }

    /// Sends `request` and returns the first message in reply.
    pub async fn request(&mut self, request: &Request) -> Result<Received, ClientError> {
        self.send(request).await?;
        match tokio::time::timeout(REPLY_TIMEOUT, self.next()).await {
            Ok(Ok(Some(m))) => Ok(m),
            Ok(Ok(None)) => Err(self.io("the daemon closed the connection without answering")),
            Ok(Err(e)) => Err(e),
            Err(_) => Err(self.io(format!(
                "no answer within {} s; see `journalctl -u surfscan`",
                REPLY_TIMEOUT.as_secs()
            ))),
        }
    }

    /// The next message, or `None` when the daemon closed the connection.
    pub async fn next(&mut self) -> Result<Option<Received>, ClientError> {
        let mut buf = Vec::new();
        let read = {
            let mut limited = (&mut self.reader).take(MAX_MESSAGE_BYTES + 1);
            limited.read_until(b'\n', &mut buf).await
        };
        let n = read.map_err(|e| self.io(format!("reading: {e}")))?;
        if n == 0 {
            return Ok(None);
        }
        if buf.last() != Some(&b'\n') {
            return Err(if n as u64 > MAX_MESSAGE_BYTES {
                self.io(format!(
                    "a message longer than {MAX_MESSAGE_BYTES} bytes arrived"
                ))
            } else {
                self.io("the daemon closed the connection in the middle of a message")
            });
        }
        buf.pop();
        if buf.last() == Some(&b'\r') {
            buf.pop();
        }
        let raw = String::from_utf8(buf).map_err(|_| self.io("a message is not UTF-8"))?;
        let message = serde_json::from_str(&raw)
            .map_err(|e| self.io(format!("unreadable message ({e}): {raw}")))?;
        Ok(Some(Received { message, raw }))
    }

    fn io(&self, cause: impl Into<String>) -> ClientError {
        ClientError::Io {
            path: self.path.clone(),
            cause: cause.into(),
        }
    }
}
