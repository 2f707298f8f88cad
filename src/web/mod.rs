//! The station's page: an optional HTTP(S) server in the daemon (`[web]`, off unless
//! configured, loopback by default) with the live view, the operator's controls, the history,
//! and an HTTP JSON API mirroring the control socket.
//!
//! - [`settings`]: the `[web]` table.
//! - [`auth`]: users and tokens, signed session cookies, CSRF checks (pure).
//! - [`live`]: the live view fed from the runner's status and the scan's files.
//! - [`history`]: the scans from the scan index, and a scan's files by checked name.
//! - [`api`]: the routes.
//! - [`page`]: the page's HTML, script and style, compiled in.
//! - [`tls`]: rustls from PEM files.
//! - [`server`]: the listener with its bounds and deadlines.
//!
//! The page is a consumer of the daemon's status, never on the scan's path: it runs on a
//! thread and runtime of its own, reads the status from the runner's `watch` channel (latest
//! value only), reads files the scan has already written, and sends commands through the same
//! channel, dispatcher and checks as the control socket ([`crate::control::dispatch`]).
//!
//! Layer 4 (process edge): depends on [`crate::control`], the scan's status, store and command
//! types, the scan index, [`crate::publish::sandbox_hint`], axum/hyper/rustls and tokio.

pub mod api;
pub mod auth;
pub mod history;
pub mod live;
pub mod page;
pub mod server;
pub mod settings;
pub mod tls;

use crate::control::protocol::ControlChannels;
use settings::WebSettings;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use tokio::sync::watch;

/// The page's name among the status's links, where a page that cannot listen is named.
pub const LINK: &str = "web";

/// Why the page could not be started.
#[derive(Debug, thiserror::Error)]
pub enum WebError {
    /// The token file or the certificate is not usable (the daemon exits 78).
    #[error("[web]: {0}")]
    Config(String),
    /// The address cannot be listened on (the daemon scans on without its page).
    #[error("[web] listen: {0}")]
    Listen(String),
    /// The page's thread or runtime could not be started.
    #[error("the station's page cannot start: {0}")]
    Start(String),
}

/// The running page; [`WebHandle::stop`] ends it.
pub struct WebHandle {
    addr: SocketAddr,
    tls: bool,
    shutdown: watch::Sender<bool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl WebHandle {
    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The page's address for people, `http://127.0.0.1:8210/`.
    pub fn url(&self) -> String {
        let scheme = if self.tls { "https" } else { "http" };
        format!("{scheme}://{}/", self.addr)
    }

    /// Stops listening and closes the connections (each gets
    /// [`server::SHUTDOWN_GRACE`] to finish what it is sending).
    pub fn stop(mut self) {
        let _ = self.shutdown.send(true);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Starts the page for `settings` on a thread of its own: reads the token file and the
/// certificate, binds the address (so every error is known before the daemon is ready), and
/// serves the runner's `channels` and the scans of `out`.
pub fn start(
    settings: &WebSettings,
    channels: ControlChannels,
    out: PathBuf,
) -> Result<WebHandle, WebError> {
    let addr = settings.address().map_err(WebError::Listen)?;
    let users = auth::Users::load(&settings.token_file).map_err(WebError::Config)?;
    let acceptor = match (&settings.tls_cert, &settings.tls_key) {
        (Some(c), Some(k)) => Some(tls::acceptor(c, k).map_err(WebError::Config)?),
        _ => None,
    };
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .max_blocking_threads(4)
        .build()
        .map_err(|e| WebError::Start(e.to_string()))?;
    // Entered, not blocked on: `start` may be called from within another runtime (and on
    // failure the runtime is let go in the background, which is allowed there too).
    let bound = {
        let _in_rt = rt.enter();
        server::bind(addr).and_then(|l| l.local_addr().map(|a| (l, a)))
    };
    let (listener, addr) = match bound {
        Ok(b) => b,
        Err(e) => {
            rt.shutdown_background();
            return Err(WebError::Listen(listen_error(addr, &e)));
        }
    };
    let (view_tx, view_rx) = watch::channel(Arc::new(live::View::default()));
    let (shutdown_tx, shutdown_rx) = watch::channel(false);
    let status = channels.status.clone();
    let app = Arc::new(api::App {
        users,
        sessions: auth::Sessions::default(),
        channels,
        view: view_rx,
        out: out.clone(),
        tls: acceptor.is_some(),
        session_hours: settings.session_hours,
        reply_timeout: crate::control::server::ServerOptions::default().reply_timeout,
        history: tokio::sync::Mutex::new(None),
    });
    let max = settings.max_connections;
    let tls = acceptor.is_some();
    let thread = std::thread::Builder::new()
        .name("surfscan-web".into())
        .spawn(move || {
            // A panic in one request ends that connection only; one in the accept loop or
            // the live feed would leave the daemon without its page: the process ends
            // ([`crate::panics`]) and systemd starts it again.
            let served = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                rt.block_on(async move {
                    let feed = live::run(status, out, view_tx);
                    let feed = crate::panics::spawn_vital("the station's page's feed", feed);
                    server::serve(listener, acceptor, api::router(app), max, shutdown_rx).await;
                    feed.abort();
                })
            }));
            if let Err(p) = served {
                crate::panics::exit_internal("the station's page", crate::panics::message(&*p));
            }
        })
        .map_err(|e| WebError::Start(e.to_string()))?;
    Ok(WebHandle {
        addr,
        tls,
        shutdown: shutdown_tx,
        thread: Some(thread),
    })
}

/// Why `addr` cannot be listened on, and what to do.
fn listen_error(addr: SocketAddr, e: &std::io::Error) -> String {
    let sandbox = crate::publish::sandbox_hint(e);
    let hint = if !sandbox.is_empty() {
        ""
    } else if e.raw_os_error() == Some(libc::EACCES) {
        "; ports below 1024 need privileges the daemon does not have: use a port above 1023 ([web] listen)"
    } else {
        "; another program may use the port, or the address is not one of this PC's ([web] listen)"
    };
    format!("cannot listen on {addr}: {e}{sandbox}{hint}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_listen_error_says_what_to_do_for_its_cause() {
        let addr: SocketAddr = "0.0.0.0:8210".parse().unwrap();
        let said = |errno| listen_error(addr, &std::io::Error::from_raw_os_error(errno));
        assert!(
            said(libc::EAFNOSUPPORT).contains("RestrictAddressFamilies=AF_UNIX AF_INET AF_INET6")
        );
        assert!(said(libc::EACCES).contains("above 1023"));
        let taken = said(libc::EADDRINUSE);
        assert!(
            taken.starts_with("cannot listen on 0.0.0.0:8210: ")
                && taken.contains("another program"),
            "{taken}"
        );
    }
}
