//! The page's listener: accepts connections up to a bound, gives each its TLS handshake (when
//! configured) and its HTTP/1.1 conversation under deadlines, and hands requests to the
//! router ([`super::api`]).
//!
//! No client can hold the daemon: at most `[web] max-connections` connections are served
//! (one more is answered `503` and closed at once); a TLS handshake must finish within
//! [`HANDSHAKE_TIMEOUT`], a request's headers arrive within [`HEADER_TIMEOUT`] of the
//! connection's start or of the last answer (so a connection that sends nothing, or drips
//! its headers, is closed), and a connection on which nothing moves either way for
//! [`STALL_TIMEOUT`] is closed (a client that stops reading its stream). Streams send a
//! comment every [`super::api::KEEP_ALIVE`], well inside it.
//!
//! Written by hand around hyper's connection API rather than axum's `serve`, which has no
//! bound on connections, no TLS and no stall deadline.
//!
//! Layer 4 (process edge): depends on hyper, hyper-util, tokio-rustls and tokio; knows nothing
//! of the station beyond the router it is given.

use axum::Router;
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{watch, Semaphore};
use tokio::time::Instant;
use tokio_rustls::TlsAcceptor;
use tower_service::Service;

/// How long a TLS handshake may take.
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);

/// How long a request's headers may take to arrive, from the connection's start or the
/// previous answer.
pub const HEADER_TIMEOUT: Duration = Duration::from_secs(10);

/// How long a connection may go with nothing read or written.
pub const STALL_TIMEOUT: Duration = Duration::from_secs(45);

/// How long open connections get to finish when the daemon stops.
pub const SHUTDOWN_GRACE: Duration = Duration::from_secs(2);

/// The client's address, as a request extension.
#[derive(Debug, Clone, Copy)]
pub struct ClientAddr(pub SocketAddr);

/// Binds `addr` (address reuse on, so a restarted daemon gets its port back at once).
pub fn bind(addr: SocketAddr) -> std::io::Result<TcpListener> {
    let socket = match addr {
        SocketAddr::V4(_) => tokio::net::TcpSocket::new_v4()?,
        SocketAddr::V6(_) => tokio::net::TcpSocket::new_v6()?,
    };
    socket.set_reuseaddr(true)?;
    socket.bind(addr)?;
    socket.listen(1024)
}

/// Serves `router` on `listener` until `shutdown` turns true.
pub async fn serve(
    listener: TcpListener,
    tls: Option<TlsAcceptor>,
    router: Router,
    max_connections: usize,
    mut shutdown: watch::Receiver<bool>,
) {
    let slots = Arc::new(Semaphore::new(max_connections));
    loop {
        // The select's output is left before anything else is awaited, so that the loop can
        // run in a spawned task (a shutdown borrow held across an await would not be Send).
        let accepted = tokio::select! {
            _ = shutdown.wait_for(|s| *s) => break,
            accepted = listener.accept() => accepted,
        };
        let (stream, addr) = match accepted {
            Ok(a) => a,
            Err(e) => {
                // Out of file descriptors and the like: wait rather than spin.
                tracing::warn!("web: accept failed: {e}");
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        let Ok(permit) = slots.clone().try_acquire_owned() else {
            refuse_busy(&stream, max_connections);
            continue;
        };
        let _ = stream.set_nodelay(true);
        let (router, tls, shutdown) = (router.clone(), tls.clone(), shutdown.clone());
        tokio::spawn(async move {
            match tls {
                None => connection(stream, addr, router, shutdown).await,
                Some(acceptor) => {
                    match tokio::time::timeout(HANDSHAKE_TIMEOUT, acceptor.accept(stream)).await {
                        Ok(Ok(s)) => connection(s, addr, router, shutdown).await,
                        Ok(Err(e)) => tracing::debug!("web: TLS handshake with {addr} failed: {e}"),
                        Err(_) => tracing::debug!("web: TLS handshake with {addr} timed out"),
                    }
                }
            }
            drop(permit);
        });
    }
}

/// Tells a client beyond the bound so (when its socket takes the few bytes at once) and
/// closes.
fn refuse_busy(stream: &TcpStream, max: usize) {
    tracing::warn!("web: {max} connections are open, the most [web] max-connections allows; a new one was refused");
    let body = format!("{{\"class\":\"error\",\"message\":\"the station's page serves at most {max} connections at once; close unused pages and retry\"}}");
    let reply = format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\ncontent-length: {}\r\nretry-after: 5\r\nconnection: close\r\n\r\n{body}",
        body.len()
    );
    let _ = stream.try_write(reply.as_bytes());
}

/// One connection's conversation, under the header and stall deadlines.
async fn connection<S>(io: S, addr: SocketAddr, router: Router, mut shutdown: watch::Receiver<bool>)
where
    S: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    let epoch = Instant::now();
    let progress = Arc::new(AtomicU64::new(0));
    let io = Watched {
        inner: io,
        epoch,
        progress: progress.clone(),
    };
    let service = hyper::service::service_fn(move |mut req: hyper::Request<Incoming>| {
        req.extensions_mut().insert(ClientAddr(addr));
        let mut router = router.clone();
        router.call(req)
    });
    let mut builder = hyper::server::conn::http1::Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(HEADER_TIMEOUT)
        .max_buf_size(64 * 1024)
        .keep_alive(true);
    let conn = builder.serve_connection(TokioIo::new(io), service);
    tokio::pin!(conn);
    tokio::select! {
        r = conn.as_mut() => {
            if let Err(e) = r {
                tracing::debug!("web: connection with {addr} ended: {e}");
            }
            return;
        }
        () = stalled(&progress, epoch) => {
            tracing::debug!("web: connection with {addr} closed: nothing moved for {} s", STALL_TIMEOUT.as_secs());
            return;
        }
        _ = shutdown.wait_for(|s| *s) => conn.as_mut().graceful_shutdown(),
    }
    let _ = tokio::time::timeout(SHUTDOWN_GRACE, conn).await;
}

/// Resolves once nothing has been read or written for [`STALL_TIMEOUT`].
async fn stalled(progress: &AtomicU64, epoch: Instant) {
    loop {
        let last = epoch + Duration::from_millis(progress.load(Ordering::Relaxed));
        let deadline = last + STALL_TIMEOUT;
        if Instant::now() >= deadline {
            return;
        }
        tokio::time::sleep_until(deadline).await;
    }
}

/// A connection's byte stream that notes when bytes last moved.
struct Watched<S> {
    inner: S,
    epoch: Instant,
    progress: Arc<AtomicU64>,
}

impl<S> Watched<S> {
    fn moved(&self) {
        let ms = self.epoch.elapsed().as_millis() as u64;
        self.progress.store(ms, Ordering::Relaxed);
    }
}

impl<S: AsyncRead + Unpin> AsyncRead for Watched<S> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<std::io::Result<()>> {
        let before = buf.filled().len();
        let r = Pin::new(&mut self.inner).poll_read(cx, buf);
        if matches!(r, Poll::Ready(Ok(()))) && buf.filled().len() > before {
            self.moved();
        }
        r
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for Watched<S> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<std::io::Result<usize>> {
        let r = Pin::new(&mut self.inner).poll_write(cx, buf);
        if matches!(r, Poll::Ready(Ok(n)) if n > 0) {
            self.moved();
        }
        r
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[std::io::IoSlice<'_>],
    ) -> Poll<std::io::Result<usize>> {
        let r = Pin::new(&mut self.inner).poll_write_vectored(cx, bufs);
        if matches!(r, Poll::Ready(Ok(n)) if n > 0) {
            self.moved();
        }
        r
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}
