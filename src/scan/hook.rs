//! The notification hook's settings (`[notify]`): a command run when a scan completes,
//! fails or suspends.
//!
//! Layer 4 (process edge): serde only.

use serde::{Deserialize, Serialize};

fn d_timeout() -> u64 {
    30
}

/// `[notify]`: the command (argv, no shell) and its time bound.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct HookSettings {
    /// Program and arguments.
    pub command: Vec<String>,
    /// Seconds the command may run before it is killed (default 30).
    #[serde(default = "d_timeout")]
    pub timeout_s: u64,
}
