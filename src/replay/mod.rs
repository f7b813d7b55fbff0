//! Prioritized replay.
