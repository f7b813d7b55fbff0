//! Stop requests: SIGTERM and SIGINT set a flag that long-running work polls at points where it can stop
//! cleanly (the training loop snapshots its run there and returns [`Interrupted`]). A second SIGINT while the
//! first is being handled ends the process at once, as Ctrl-C twice does in most tools.
//!
//! The handlers are installed by the program (`arld train`, `arld sweep`), never by the library on its own: a
//! library user keeps control of their process's signals and may call [`request`] instead.

use std::sync::Arc;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

fn flag() -> &'static Arc<AtomicBool> {
    static FLAG: OnceLock<Arc<AtomicBool>> = OnceLock::new();
    FLAG.get_or_init(|| Arc::new(AtomicBool::new(false)))
}

/// The number of the last stop signal received (0: none).
fn last_signal() -> &'static Arc<AtomicUsize> {
    static SIGNAL: OnceLock<Arc<AtomicUsize>> = OnceLock::new();
    SIGNAL.get_or_init(|| Arc::new(AtomicUsize::new(0)))
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
    for signal in [SIGINT, SIGTERM] {
        signal_hook::flag::register_usize(signal, Arc::clone(last_signal()), signal as usize)?;
        signal_hook::flag::register(signal, Arc::clone(flag()))?;
    }
    let _ = INSTALLED.set(());
    Ok(())
}

/// Whether a stop was requested.
pub fn requested() -> bool {
    flag().load(Ordering::Relaxed)
}

/// The stop signal received, if a signal (not [`request`]) asked for the stop: its number and name.
pub fn signal() -> Option<(i32, &'static str)> {
    use signal_hook::consts::{SIGINT, SIGTERM};
    match last_signal().load(Ordering::Relaxed) as i32 {
        SIGINT => Some((SIGINT, "SIGINT")),
        SIGTERM => Some((SIGTERM, "SIGTERM")),
        _ => None,
    }
}

/// The exit status of a program stopped by a stop request, as shells report a process a signal ended:
/// 128 + the signal's number (130 for SIGINT, 143 for SIGTERM; 130 when no signal was involved).
pub fn exit_status() -> u8 {
    128 + signal().map_or(2, |(n, _)| n as u8)
}

/// Requests a stop, as a signal would.
pub fn request() {
    flag().store(true, Ordering::Relaxed);
}

/// The error of work that stopped because a stop was requested (after saving what it needs to continue).
#[derive(Debug, Clone, thiserror::Error)]
#[error("interrupted: {0}")]
pub struct Interrupted(pub String);

/// Whether `err` is a stop request (an expert that was waiting for an answer when the stop came returns one).
pub fn is_stop(err: &anyhow::Error) -> bool {
    err.chain().any(|cause| cause.is::<Interrupted>())
}
