//! The control socket: JSON lines over a Unix socket, versioned, closed command set.
//!
//! Layer 4 (process edge): talks to the scan runner only through channels.
