//! Full-state snapshots of a training run, so that a run stopped at any moment (killed, preempted, its node
//! lost) continues to exactly the results of an uninterrupted run.
//!
//! The run owns them, not the network: [`Checkpointer`] writes one [`StateDict`] that the training loop gathers
//! from every part of the run (agent: online and target weights, Adam; replay with its n-step queue; query
//! window, budget and segment; every generator; the loop's position and the episode in progress; the logs'
//! byte positions). On disk it is one safetensors file (`snapshot.safetensors`: raw little-endian arrays, the
//! small values as JSON in its metadata), written atomically, plus `snapshot.json` saying what it is for people
//! and scripts. A snapshot records the format version, the arld version and the run's whole configuration; a
//! snapshot of another configuration or version is refused with the difference named.

use super::TrainConfig;
use crate::state::{Array, StateDict};
use anyhow::{Context, Result, bail};
use safetensors::tensor::TensorView;
use safetensors::{Dtype, SafeTensors};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The snapshot's file in a run directory.
pub const SNAPSHOT_FILE: &str = "snapshot.safetensors";
/// The small description written next to it.
pub const SNAPSHOT_INFO_FILE: &str = "snapshot.json";
/// Version of the snapshot format; a snapshot of another format is refused.
pub const FORMAT_VERSION: u32 = 1;

/// Writes and reads the snapshots of one run directory.
pub struct Checkpointer {
    dir: PathBuf,
    /// Snapshot every this many units of work (environment steps; pre-training updates); 0: only on request.
    every: usize,
    config_toml: String,
    /// Time spent writing snapshots, and how many were written (for the benchmark and the summary's notes).
    pub spent_s: f64,
    pub written: usize,
    pub last_bytes: usize,
}

impl Checkpointer {
    /// A checkpointer for the run of `cfg` in `dir` (snapshots every `cfg.snapshot_every` steps).
    pub fn new(dir: &Path, cfg: &TrainConfig) -> Self {
        Self {
            dir: dir.to_path_buf(),
            every: cfg.snapshot_every,
            config_toml: cfg.to_toml(),
            spent_s: 0.0,
            written: 0,
            last_bytes: 0,
        }
    }

    /// Whether a periodic snapshot is due after `done` units of work.
    pub fn due(&self, done: usize) -> bool {
        self.every > 0 && done > 0 && done.is_multiple_of(self.every)
    }

    pub fn path(&self) -> PathBuf {
        self.dir.join(SNAPSHOT_FILE)
    }

    /// Writes `state` atomically (the previous snapshot stays whole until the new one replaces it).
    /// `position` says where the run is, for people and scripts (`snapshot.json`).
    pub fn save(&mut self, state: &StateDict, position: serde_json::Value) -> Result<()> {
        let started = Instant::now();
        let values = serde_json::to_string(&state.values)?;
        let mut meta = HashMap::new();
        meta.insert("format".to_string(), FORMAT_VERSION.to_string());
        meta.insert("arld".to_string(), env!("CARGO_PKG_VERSION").to_string());
        meta.insert("config".to_string(), self.config_toml.clone());
        meta.insert("values".to_string(), values);
        let buffers: Vec<(&String, Dtype, Vec<u8>, usize)> = state
            .arrays
            .iter()
            .map(|(name, array)| {
                let (dtype, bytes) = match array {
                    Array::F32(v) => (Dtype::F32, v.iter().flat_map(|x| x.to_le_bytes()).collect()),
                    Array::F64(v) => (Dtype::F64, v.iter().flat_map(|x| x.to_le_bytes()).collect()),
                    Array::U64(v) => (Dtype::U64, v.iter().flat_map(|x| x.to_le_bytes()).collect()),
                    Array::U8(v) => (Dtype::U8, v.clone()),
                };
                (name, dtype, bytes, array.len())
            })
            .collect();
        let views = buffers
            .iter()
            .map(|(name, dtype, bytes, len)| {
                Ok(((*name).clone(), TensorView::new(*dtype, vec![*len], bytes)?))
            })
            .collect::<Result<Vec<_>, safetensors::SafeTensorError>>()?;
        let bytes = safetensors::serialize(views, Some(meta))?;
        crate::files::write_atomic(&self.path(), &bytes)?;
        let info = serde_json::json!({
            "format": FORMAT_VERSION,
            "arld": env!("CARGO_PKG_VERSION"),
            "config_hash": format!("{:016x}", fnv1a(self.config_toml.as_bytes())),
            "position": position,
            "bytes": bytes.len(),
        });
        crate::files::write_atomic(
            &self.dir.join(SNAPSHOT_INFO_FILE),
            serde_json::to_string_pretty(&info)?.as_bytes(),
        )?;
        self.spent_s += started.elapsed().as_secs_f64();
        self.written += 1;
        self.last_bytes = bytes.len();
        Ok(())
    }

    /// The run directory's snapshot, if there is one; an error if it is damaged or belongs to another
    /// configuration or version.
    pub fn load(&self) -> Result<Option<StateDict>> {
        let path = self.path();
        if !path.is_file() {
            return Ok(None);
        }
        let bytes =
            std::fs::read(&path).with_context(|| format!("cannot read {}", path.display()))?;
        let state = decode(&bytes, &self.config_toml)
            .with_context(|| format!("cannot resume from {}", path.display()))?;
        Ok(Some(state))
    }

    /// Removes the snapshot (the run finished: its results are the state worth keeping).
    pub fn remove(&self) -> Result<()> {
        for name in [SNAPSHOT_FILE, SNAPSHOT_INFO_FILE] {
            match std::fs::remove_file(self.dir.join(name)) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    return Err(e).with_context(|| format!("cannot remove {name}"));
                }
                _ => {}
            }
        }
        Ok(())
    }
}

/// FNV-1a, 64 bits: the configuration's fingerprint shown in `snapshot.json`.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// Reads a snapshot file's bytes, checking format, version and configuration.
fn decode(bytes: &[u8], config_toml: &str) -> Result<StateDict> {
    let (_, header) =
        SafeTensors::read_metadata(bytes).context("the file is not a readable safetensors file")?;
    let meta = header.metadata().clone().unwrap_or_default();
    let get = |key: &str| {
        meta.get(key)
            .with_context(|| format!("the file is not an arld snapshot (no `{key}` in its header)"))
    };
    let format = get("format")?;
    if format != &FORMAT_VERSION.to_string() {
        bail!(
            "the snapshot has format version {format}, this arld reads version {FORMAT_VERSION}; \
             finish the run with the arld that started it, or start it again"
        );
    }
    let version = get("arld")?;
    if version != env!("CARGO_PKG_VERSION") {
        bail!(
            "the snapshot was written by arld {version}, this is arld {}; results would not match an \
             uninterrupted run: finish the run with arld {version}, or start it again",
            env!("CARGO_PKG_VERSION")
        );
    }
    let recorded = get("config")?;
    if recorded != config_toml {
        let differences: Vec<String> = recorded
            .lines()
            .zip(config_toml.lines())
            .filter(|(a, b)| a != b)
            .take(5)
            .map(|(a, b)| format!("snapshot `{a}`, now `{b}`"))
            .collect();
        bail!(
            "the snapshot belongs to another configuration ({}); start the run again in a new directory, or \
             give the configuration it was started with",
            if differences.is_empty() {
                "the key lists differ".to_string()
            } else {
                differences.join("; ")
            }
        );
    }
    let mut state = StateDict {
        values: serde_json::from_str(get("values")?)
            .context("the snapshot's values are damaged")?,
        ..StateDict::default()
    };
    let file = SafeTensors::deserialize(bytes).context("the snapshot's arrays are damaged")?;
    for (name, view) in file.tensors() {
        let data = view.data();
        let array = match view.dtype() {
            Dtype::F32 => Array::F32(
                data.chunks_exact(4)
                    .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
                    .collect(),
            ),
            Dtype::F64 => Array::F64(
                data.chunks_exact(8)
                    .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
                    .collect(),
            ),
            Dtype::U64 => Array::U64(
                data.chunks_exact(8)
                    .map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes")))
                    .collect(),
            ),
            Dtype::U8 => Array::U8(data.to_vec()),
            other => {
                bail!("the snapshot's array `{name}` has type {other:?}, which arld never writes")
            }
        };
        state.arrays.insert(name, array);
    }
    Ok(state)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::{ConfigInput, Method, NetKind};

    fn config(seed: u64) -> TrainConfig {
        ConfigInput::new("CartPole-v0", Method::Dqn, NetKind::Bootstrap, seed)
            .resolve()
            .unwrap()
    }

    #[test]
    fn a_snapshot_round_trips_and_another_configuration_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mut state = StateDict::default();
        state.put_f32("a", &[1.5, -0.0, f32::MIN_POSITIVE]);
        state.put_f64("b", &[]);
        state.put_u64("c", &[u64::MAX]);
        state.put_u8("d", &[0, 1]);
        state.put_value("e", &(3usize, "x"));
        let mut ck = Checkpointer::new(dir.path(), &config(0));
        ck.save(&state, serde_json::json!({"step": 10})).unwrap();
        assert_eq!(ck.load().unwrap().unwrap(), state);
        let other = Checkpointer::new(dir.path(), &config(1));
        let err = format!("{:#}", other.load().unwrap_err());
        assert!(
            err.contains("another configuration")
                && err.contains("seed = 0")
                && err.contains("seed = 1"),
            "{err}"
        );
        std::fs::write(ck.path(), b"not a snapshot").unwrap();
        assert!(format!("{:#}", ck.load().unwrap_err()).contains("not a readable safetensors"));
        ck.remove().unwrap();
        assert!(ck.load().unwrap().is_none());
    }
}
