//! Stop requests: SIGTERM and SIGINT set a flag that long-running work polls at points where it can stop
//! cleanly (the training loop snapshots its run there and returns [`Interrupted`]). A second SIGINT while the
//! first is being handled ends the process at once, as Ctrl-C twice does in most tools.
//!
//! The handlers are installed by the program (`arld train`, `arld sweep`), never by the library on its own: a
//! library user keeps control of their process's signals and may call [`request`] instead.

use std::sync::Arc;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, Ordering};

fn flag() -> &'static Arc<AtomicBool> {
    static FLAG: OnceLock<Arc<AtomicBool>> = OnceLock::new();
    FLAG.get_or_init(|| Arc::new(AtomicBool::new(false)))
}

/// Installs the SIGTERM/SIGINT handlers (idempotent).
pub fn install() -> std::io::Result<()> {
    static INSTALLED: OnceLock<()> = OnceLock::new();
    if INSTALLED.get().is_some() {
        return Ok(());
    }
    use signal_hook::consts::{SIGINT, SIGTERM};
    // Order matters: the conditional shutdown sees the flag before this signal sets it.
    signal_hook::flag::register_conditional_shutdown(SIGINT, 130, Arc::clone(flag()))?;
    signal_hook::flag::register(SIGINT, Arc::clone(flag()))?;
    signal_hook::flag::register(SIGTERM, Arc::clone(flag()))?;
    let _ = INSTALLED.set(());
    Ok(())
}

/// Whether a stop was requested.
pub fn requested() -> bool {
    flag().load(Ordering::Relaxed)
}

/// Requests a stop, as a signal would.
pub fn request() {
    flag().store(true, Ordering::Relaxed);
}

/// The error of work that stopped because a stop was requested (after saving what it needs to continue).
#[derive(Debug, Clone, thiserror::Error)]
#[error("interrupted: {0}")]
pub struct Interrupted(pub String);
