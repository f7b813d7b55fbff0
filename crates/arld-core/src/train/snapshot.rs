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
//!
//! Format 2 adds a CRC-32C of the whole file under the metadata key `crc32c` (computed over the arrays' bytes,
//! then the header with the checksum's eight hex digits as `00000000`), checked before anything in the file is
//! used: a snapshot changed by a bad disk, a copy cut short or an edit is refused, never half-used. Format 1
//! snapshots (no checksum) are still read. The snapshot is the run's own file: a link, a directory or a device
//! in its place is an error that leaves it alone, never "no snapshot yet".

use super::{ConfigInput, TrainConfig};
use crate::state::{Array, StateDict};
use anyhow::{Context, Result, bail};
use safetensors::{Dtype, SafeTensors};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The snapshot's file in a run directory.
pub const SNAPSHOT_FILE: &str = "snapshot.safetensors";
/// The small description written next to it.
pub(crate) const SNAPSHOT_INFO_FILE: &str = "snapshot.json";
/// Version of the snapshot format; a snapshot of another format is refused (format 1, before the checksum,
/// is still read).
pub(crate) const FORMAT_VERSION: u32 = 2;

/// The largest snapshot read (the replay memory a configuration may ask for is at most 16 GiB).
const MAX_SNAPSHOT_BYTES: u64 = 64 << 30;

/// The metadata key of the checksum (format 2).
const CHECKSUM_KEY: &str = "crc32c";
/// The checksum's value while it is computed.
const CHECKSUM_PLACEHOLDER: &str = "00000000";

/// Writes and reads the snapshots of one run directory.
pub struct Checkpointer {
    dir: PathBuf,
    /// Snapshot every this many units of work (environment steps; pre-training updates); 0: only on request.
    every: usize,
    config: TrainConfig,
    config_toml: String,
    /// The thread making the last snapshot durable (see [`Checkpointer::save`]).
    pending: Option<std::thread::JoinHandle<Result<()>>>,
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
            config: cfg.clone(),
            config_toml: cfg.to_toml(),
            pending: None,
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
    ///
    /// The arrays go straight from the components into the file (no copy of them is made), and the file is
    /// made durable in the background: `save` returns once every byte is in the operating system's cache
    /// under a temporary name; a thread then syncs it to the disk and renames it over the previous snapshot
    /// (then writes `snapshot.json`). The rename comes only after the sync, so at every moment the snapshot
    /// file is a whole snapshot, the new one or the one before, even if the machine loses power; a process
    /// killed before the rename leaves the previous snapshot, from which the run resumes to the same results
    /// (it redoes more steps). The next `save`, [`Checkpointer::wait`], [`Checkpointer::remove`] and dropping
    /// the checkpointer wait for that thread.
    pub fn save(&mut self, state: &StateDict<'_>, position: serde_json::Value) -> Result<()> {
        let started = Instant::now();
        self.wait()?;
        let values = serde_json::to_string(&state.values)?;
        let metadata = [
            ("format", FORMAT_VERSION.to_string()),
            ("arld", env!("CARGO_PKG_VERSION").to_string()),
            ("numerics", crate::math::NUMERICS.to_string()),
            ("config", self.config_toml.clone()),
            ("values", values),
        ];
        let mut file = crate::files::AtomicFile::create(&self.path())?;
        let bytes = encode(&mut file, state, &metadata).map_err(|e| file.error(e))?;
        file.flush_buffer()?;
        let info = serde_json::json!({
            "format": FORMAT_VERSION,
            "arld": env!("CARGO_PKG_VERSION"),
            "config_hash": format!("{:016x}", fnv1a(self.config_toml.as_bytes())),
            "position": position,
            "bytes": bytes,
        });
        let info = serde_json::to_string_pretty(&info)?;
        let info_path = self.dir.join(SNAPSHOT_INFO_FILE);
        let commit = move || -> Result<()> {
            file.commit()?;
            crate::files::write_atomic(&info_path, info.as_bytes())?;
            Ok(())
        };
        let thread = std::thread::Builder::new()
            .name("snapshot".into())
            .spawn(commit)
            .context("cannot start the thread that writes the snapshot")?;
        self.pending = Some(thread);
        self.spent_s += started.elapsed().as_secs_f64();
        self.written += 1;
        self.last_bytes = bytes as usize;
        Ok(())
    }

    /// Waits until the last snapshot [`Checkpointer::save`] wrote is synced and in place; its error if
    /// that failed.
    pub fn wait(&mut self) -> Result<()> {
        match self.pending.take() {
            None => Ok(()),
            Some(thread) => thread
                .join()
                .map_err(|_| anyhow::anyhow!("the thread writing the snapshot panicked"))?
                .context("cannot write the snapshot"),
        }
    }

    /// The run directory's snapshot, if there is one; an error if it is damaged or belongs to another
    /// configuration or version.
    pub fn load(&mut self) -> Result<Option<StateDict<'static>>> {
        self.wait()?;
        let path = self.path();
        // A process killed while it wrote a snapshot leaves its temporary file; the snapshot itself is whole.
        for file in [SNAPSHOT_FILE, SNAPSHOT_INFO_FILE] {
            crate::files::remove_leftovers(&self.dir.join(file))
                .with_context(|| format!("cannot tidy {}", self.dir.display()))?;
        }
        // Only a missing snapshot means "none yet"; anything else in its place is kept and refused.
        if !crate::files::own_file_exists(&path).context("cannot resume the run")? {
            return Ok(None);
        }
        let bytes = crate::files::read_bounded(&path, MAX_SNAPSHOT_BYTES)
            .with_context(|| format!("cannot read {} to resume the run", path.display()))?;
        let state = decode(&bytes, &self.config)
            .with_context(|| format!("cannot resume from {}", path.display()))?;
        Ok(Some(state))
    }

    /// Removes the snapshot (the run finished: its results are the state worth keeping).
    pub fn remove(&mut self) -> Result<()> {
        self.wait()?;
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

impl Drop for Checkpointer {
    /// A run that ends with an error still leaves its last snapshot whole and in place.
    fn drop(&mut self) {
        let _ = self.wait();
    }
}

/// Whether the run directory `dir` holds a snapshot computed with other elementary functions than this arld's
/// (an older arld's): it cannot be resumed, and a sweep starts its run again.
pub fn is_stale(dir: &Path) -> bool {
    let Ok(bytes) = crate::files::read_bounded(&dir.join(SNAPSHOT_FILE), MAX_SNAPSHOT_BYTES) else {
        return false;
    };
    SafeTensors::read_metadata(&bytes).is_ok_and(|(_, header)| {
        header
            .metadata()
            .as_ref()
            .and_then(|m| m.get("numerics"))
            .map(String::as_str)
            != Some(crate::math::NUMERICS)
    })
}

/// The configuration (TOML text) the snapshot file `path` recorded, or an error saying the file is no snapshot.
pub fn recorded_config(path: &Path) -> Result<String> {
    let bytes = crate::files::read_bounded(path, MAX_SNAPSHOT_BYTES)
        .with_context(|| format!("cannot read {}", path.display()))?;
    let (_, header) = SafeTensors::read_metadata(&bytes)
        .with_context(|| format!("{} is not a readable safetensors file", path.display()))?;
    header
        .metadata()
        .as_ref()
        .and_then(|m| m.get("config").cloned())
        .with_context(|| {
            format!(
                "{} is not an arld snapshot (no `config` in its header)",
                path.display()
            )
        })
}

/// How the configuration a snapshot recorded differs from `config` (see [`TrainConfig::differences`]). The
/// recorded text is read as a config file is: a key an older arld did not have takes its default, so adding a
/// key does not orphan the snapshots written before it.
fn config_differences(recorded: &str, config: &TrainConfig) -> Result<Vec<String>> {
    if recorded == config.to_toml() {
        return Ok(Vec::new());
    }
    let mut input = ConfigInput::new(&config.env, config.method, config.net, config.seed);
    input
        .apply_text(recorded, Path::new("(the snapshot's configuration)"))
        .and_then(|()| input.resolve())
        .map(|then| then.differences(config))
        .context("the snapshot's configuration cannot be read by this arld")
}

/// Writes `state` as a safetensors file: the header (every array's type, length and place; `metadata` under
/// `__metadata__`), padded with spaces to a multiple of 8 bytes, then every array's little-endian bytes in
/// the order of their names. Returns the bytes written.
fn encode(
    out: &mut impl Write,
    state: &StateDict<'_>,
    metadata: &[(&str, String)],
) -> std::io::Result<u64> {
    // The arrays' checksum first (a pass that writes nothing), then the header's with the placeholder.
    let mut data_crc = CrcSink(0);
    write_arrays(&mut data_crc, state)?;
    let mut header = serde_json::Map::new();
    header.insert(
        "__metadata__".to_string(),
        metadata
            .iter()
            .map(|(k, v)| (k.to_string(), serde_json::Value::from(v.as_str())))
            .chain([(CHECKSUM_KEY.to_string(), CHECKSUM_PLACEHOLDER.into())])
            .collect::<serde_json::Map<_, _>>()
            .into(),
    );
    let mut offset = 0;
    for (name, array) in &state.arrays {
        let end = offset + array.len() * array.element_bytes();
        let dtype = match array {
            Array::F32(_) => "F32",
            Array::F64(_) => "F64",
            Array::U64(_) => "U64",
            Array::U8(_) => "U8",
        };
        header.insert(
            name.clone(),
            serde_json::json!({"dtype": dtype, "shape": [array.len()], "data_offsets": [offset, end]}),
        );
        offset = end;
    }
    let mut header = serde_json::to_vec(&header).map_err(std::io::Error::other)?;
    header.resize(header.len().next_multiple_of(8), b' ');
    let at = checksum_field(&header).map_err(std::io::Error::other)?;
    let crc = crc32c::crc32c_append(data_crc.0, &header);
    header[at..at + 8].copy_from_slice(format!("{crc:08x}").as_bytes());
    out.write_all(&(header.len() as u64).to_le_bytes())?;
    out.write_all(&header)?;
    write_arrays(out, state)?;
    Ok(8 + header.len() as u64 + offset as u64)
}

/// Writes every array's numbers as little-endian bytes, in the order of their names, through one small buffer.
fn write_arrays(out: &mut impl Write, state: &StateDict<'_>) -> std::io::Result<()> {
    let mut buffer = vec![0u8; 1 << 16];
    for array in state.arrays.values() {
        match array {
            Array::F32(v) => write_le(out, v, f32::to_le_bytes, &mut buffer)?,
            Array::F64(v) => write_le(out, v, f64::to_le_bytes, &mut buffer)?,
            Array::U64(v) => write_le(out, v, u64::to_le_bytes, &mut buffer)?,
            Array::U8(v) => out.write_all(v)?,
        }
    }
    Ok(())
}

/// A writer that only computes the CRC-32C of what goes through it.
struct CrcSink(u32);

impl Write for CrcSink {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0 = crc32c::crc32c_append(self.0, buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// Where the checksum's eight hex digits stand in a snapshot's header (JSON text): after the one
/// `"crc32c":"`. A JSON string escapes its quotes, so no value can hold that text; a header holding it
/// twice, or not followed by eight characters and a quote, is damaged.
fn checksum_field(header: &[u8]) -> Result<usize, String> {
    let key = format!("\"{CHECKSUM_KEY}\":\"");
    let found: Vec<usize> = header
        .windows(key.len())
        .enumerate()
        .filter(|(_, w)| *w == key.as_bytes())
        .map(|(i, _)| i + key.len())
        .collect();
    match found[..] {
        [at] if header.get(at + 8) == Some(&b'"') => Ok(at),
        [] => Err("the snapshot has no checksum".into()),
        _ => Err("the snapshot's checksum field is damaged".into()),
    }
}

/// Checks a format-2 snapshot's checksum (see the module's documentation) before anything else is read.
fn verify_checksum(bytes: &[u8]) -> Result<()> {
    let damaged = "the snapshot is damaged (changed or cut short since it was written)";
    let header_len = bytes
        .get(..8)
        .map(|b| u64::from_le_bytes(b.try_into().expect("eight bytes")))
        .with_context(|| format!("{damaged}: it is shorter than a header"))?;
    let header_end = usize::try_from(header_len)
        .ok()
        .and_then(|n| n.checked_add(8))
        .filter(|&end| end <= bytes.len())
        .with_context(|| format!("{damaged}: its header runs past its end"))?;
    let mut header = bytes[8..header_end].to_vec();
    let at = checksum_field(&header).map_err(|e| anyhow::anyhow!("{damaged}: {e}"))?;
    // Eight lowercase hex digits, as written: one number has one spelling.
    let digits = &header[at..at + 8];
    let recorded = std::str::from_utf8(digits)
        .ok()
        .filter(|_| {
            digits
                .iter()
                .all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'))
        })
        .and_then(|hex| u32::from_str_radix(hex, 16).ok())
        .with_context(|| format!("{damaged}: its checksum is not eight lowercase hex digits"))?;
    header[at..at + 8].copy_from_slice(CHECKSUM_PLACEHOLDER.as_bytes());
    let actual = crc32c::crc32c_append(crc32c::crc32c(&bytes[header_end..]), &header);
    if actual != recorded {
        bail!(
            "{damaged}: its CRC-32C is {actual:08x}, it recorded {recorded:08x}; nothing of it was used (start \
             the run again with --restart, or restore the snapshot from a copy)"
        );
    }
    Ok(())
}

/// Writes `data`'s numbers as little-endian bytes, `buffer.len()` bytes at a time.
fn write_le<T: Copy, const N: usize>(
    out: &mut impl Write,
    data: &[T],
    to_le: fn(T) -> [u8; N],
    buffer: &mut [u8],
) -> std::io::Result<()> {
    for part in data.chunks(buffer.len() / N) {
        let bytes = &mut buffer[..part.len() * N];
        for (slot, &x) in bytes.chunks_exact_mut(N).zip(part) {
            slot.copy_from_slice(&to_le(x));
        }
        out.write_all(bytes)?;
    }
    Ok(())
}

/// FNV-1a, 64 bits: the configuration's fingerprint shown in `snapshot.json`.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// Reads the bytes of a snapshot file of the run of `config`: its checksum, format, version and configuration
/// are checked, then every array and value is read, and every action in it range-checked. Any damage is an
/// error, never a panic (what `arld train --resume` reads, and the fuzz target `snapshot` exercises).
pub fn read_snapshot(bytes: &[u8], config: &TrainConfig) -> Result<StateDict<'static>> {
    decode(bytes, config)
}

/// Reads a snapshot file's bytes, checking format, version and configuration.
fn decode(bytes: &[u8], config: &TrainConfig) -> Result<StateDict<'static>> {
    let (_, header) =
        SafeTensors::read_metadata(bytes).context("the file is not a readable safetensors file")?;
    let meta = header.metadata().clone().unwrap_or_default();
    let get = |key: &str| {
        meta.get(key)
            .with_context(|| format!("the file is not an arld snapshot (no `{key}` in its header)"))
    };
    let format = get("format")?;
    if format == &FORMAT_VERSION.to_string() {
        verify_checksum(bytes)?;
    } else if format != "1" {
        bail!(
            "the snapshot has format version {format}, this arld reads versions 1 and {FORMAT_VERSION}; \
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
    if meta.get("numerics").map(String::as_str) != Some(crate::math::NUMERICS) {
        bail!(
            "the snapshot was computed with {} elementary functions, this arld uses {} ones; results would not \
             match an uninterrupted run: start the run again",
            meta.get("numerics")
                .map_or("the C library's", String::as_str),
            crate::math::NUMERICS
        );
    }
    let differences = config_differences(get("config")?, config)?;
    if !differences.is_empty() {
        bail!(
            "the snapshot belongs to another configuration (snapshot's value first: {}); start the run again in \
             a new directory, or give the configuration it was started with",
            differences.join("; ")
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
            Dtype::F32 => Array::F32(read_le(data, f32::from_le_bytes).into()),
            Dtype::F64 => Array::F64(read_le(data, f64::from_le_bytes).into()),
            Dtype::U64 => Array::U64(read_le(data, u64::from_le_bytes).into()),
            Dtype::U8 => Array::U8(data.to_vec().into()),
            other => {
                bail!("the snapshot's array `{name}` has type {other:?}, which arld never writes")
            }
        };
        state.arrays.insert(name, array);
    }
    if let Ok(spec) = crate::env::spec(&config.env) {
        check_actions(&state, spec.n_actions)?;
    }
    Ok(state)
}

/// Checks that every action the snapshot holds (the replay memory's, the n-step queue's, the episode in
/// progress's, the open question's) is one of the environment's `n_actions`: an action out of range would be
/// an index past the end of the Q-values later, where it can only panic.
fn check_actions(state: &StateDict<'_>, n_actions: usize) -> Result<()> {
    let in_range = |what: &str, actions: &mut dyn Iterator<Item = Option<u64>>| -> Result<()> {
        for (i, action) in actions.enumerate() {
            match action {
                Some(a) if a < n_actions as u64 => {}
                Some(a) => bail!(
                    "the snapshot's {what} holds action {a} (entry {i}), but the environment has {n_actions} \
                     actions; the snapshot is not this run's"
                ),
                None => bail!("the snapshot's {what} holds a malformed action (entry {i})"),
            }
        }
        Ok(())
    };
    if let Ok(actions) = state.u64s("replay.actions") {
        in_range("replay memory", &mut actions.iter().map(|&a| Some(a)))?;
    }
    let json_actions =
        |value: Option<&serde_json::Value>, field: Option<&str>| -> Vec<Option<u64>> {
            let list = value.and_then(serde_json::Value::as_array);
            list.into_iter()
                .flatten()
                .map(|v| match field {
                    Some(field) => v.get(field).and_then(serde_json::Value::as_u64),
                    None => v.as_u64(),
                })
                .collect()
        };
    let queue = json_actions(state.values.get("replay.nstep_queue"), Some("action"));
    in_range("n-step queue", &mut queue.into_iter())?;
    let position = state.values.get("loop");
    let episode = json_actions(position.and_then(|p| p.get("ep_actions")), None);
    in_range("episode in progress", &mut episode.into_iter())?;
    let open = position
        .and_then(|p| p.get("pending"))
        .filter(|p| !p.is_null())
        .map(|p| p.get("agent_action").and_then(serde_json::Value::as_u64));
    in_range("open question", &mut open.into_iter())?;
    Ok(())
}

/// The numbers of little-endian `bytes` (whose length safetensors checked against the array's type).
fn read_le<T, const N: usize>(bytes: &[u8], from_le: fn([u8; N]) -> T) -> Vec<T> {
    bytes
        .chunks_exact(N)
        .map(|c| from_le(c.try_into().expect("chunks of N bytes")))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::{Method, NetKind};

    fn config(seed: u64) -> TrainConfig {
        ConfigInput::new("CartPole-v0", Method::Dqn, NetKind::Bootstrap, seed)
            .resolve()
            .unwrap()
    }

    #[test]
    fn a_snapshot_round_trips_and_another_configuration_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mut state = StateDict::default();
        state.put_f32("a", &[1.5, -0.0, f32::MIN_POSITIVE][..]);
        state.put_f64("b", &[][..]);
        state.put_u64("c", vec![u64::MAX]);
        state.put_u8("d", &[0, 1][..]);
        state.put_value("e", &(3usize, "x"));
        // Longer than the writer's 64 KiB buffer, so it goes out in several pieces.
        let long: Vec<f64> = (0..20_000).map(|i| f64::from(i) * 0.37 - 11.0).collect();
        state.put_f64("f", &long);
        let mut ck = Checkpointer::new(dir.path(), &config(0));
        ck.save(&state, serde_json::json!({"step": 10})).unwrap();
        ck.wait().unwrap();
        // The file is a safetensors file as the safetensors crate reads it, each array's bytes little-endian.
        let bytes = std::fs::read(ck.path()).unwrap();
        assert_eq!(ck.last_bytes, bytes.len());
        let header_len = u64::from_le_bytes(bytes[..8].try_into().unwrap());
        assert_eq!(header_len % 8, 0);
        let file = SafeTensors::deserialize(&bytes).unwrap();
        let f = file.tensor("f").unwrap();
        assert_eq!((f.dtype(), f.shape()), (Dtype::F64, &[20_000][..]));
        let expected: Vec<u8> = long.iter().flat_map(|x| x.to_le_bytes()).collect();
        assert_eq!(f.data(), &expected[..]);
        assert_eq!(file.tensor("c").unwrap().data(), &[0xff; 8]);
        // A temporary file a killed writer left is removed when the snapshot is read.
        let leftover = dir.path().join(".snapshot.safetensors.tmp999-0");
        std::fs::write(&leftover, b"half a snapshot").unwrap();
        assert_eq!(ck.load().unwrap().unwrap(), state);
        assert!(!leftover.exists());
        let mut other = Checkpointer::new(dir.path(), &config(1));
        let err = format!("{:#}", other.load().unwrap_err());
        assert!(
            err.contains("another configuration") && err.contains("seed = 0 (1)"),
            "{err}"
        );
        // A snapshot written before a key existed resumes when the key's default is the run's value; one
        // whose elementary functions were the C library's (no `numerics` recorded) is refused.
        let path = ck.path();
        let write_with = |metadata: &[(&str, String)]| {
            let mut bytes = Vec::new();
            encode(&mut bytes, &state, metadata).unwrap();
            std::fs::write(&path, bytes).unwrap();
        };
        let without_key: String = config(0)
            .to_toml()
            .lines()
            .filter(|l| !l.starts_with("double_q"))
            .map(|l| format!("{l}\n"))
            .collect();
        assert_ne!(without_key, config(0).to_toml());
        let metadata = |numerics: Option<&str>, config: &str| {
            let mut m = vec![
                ("format", FORMAT_VERSION.to_string()),
                ("arld", env!("CARGO_PKG_VERSION").to_string()),
                ("config", config.to_string()),
                ("values", serde_json::to_string(&state.values).unwrap()),
            ];
            m.extend(numerics.map(|n| ("numerics", n.to_string())));
            m
        };
        write_with(&metadata(Some(crate::math::NUMERICS), &without_key));
        assert_eq!(ck.load().unwrap().unwrap(), state);
        let with_other_value = without_key.replace("lr = ", "double_q = false\nlr = ");
        write_with(&metadata(Some(crate::math::NUMERICS), &with_other_value));
        let err = format!("{:#}", ck.load().unwrap_err());
        assert!(err.contains("double_q = false (true)"), "{err}");
        write_with(&metadata(None, &config(0).to_toml()));
        let err = format!("{:#}", ck.load().unwrap_err());
        assert!(
            err.contains("the C library's elementary functions"),
            "{err}"
        );
        // Format 1 (no checksum) is still read; in format 2 one changed byte anywhere is refused as damage.
        let mut format_1 = metadata(Some(crate::math::NUMERICS), &config(0).to_toml());
        format_1[0].1 = "1".to_string();
        write_with(&format_1);
        let written = std::fs::read(&path).unwrap();
        let n = u64::from_le_bytes(written[..8].try_into().unwrap()) as usize;
        let mut header: serde_json::Value = serde_json::from_slice(&written[8..8 + n]).unwrap();
        header["__metadata__"]
            .as_object_mut()
            .unwrap()
            .remove(CHECKSUM_KEY);
        let mut text = serde_json::to_vec(&header).unwrap();
        text.resize(text.len().next_multiple_of(8), b' ');
        let mut old = (text.len() as u64).to_le_bytes().to_vec();
        old.extend(&text);
        old.extend(&written[8 + n..]);
        std::fs::write(&path, &old).unwrap();
        assert_eq!(ck.load().unwrap().unwrap(), state);
        write_with(&metadata(Some(crate::math::NUMERICS), &config(0).to_toml()));
        let mut changed = std::fs::read(&path).unwrap();
        let last = changed.len() - 1;
        changed[last] ^= 1;
        std::fs::write(&path, &changed).unwrap();
        let err = format!("{:#}", ck.load().unwrap_err());
        assert!(err.contains("damaged") && err.contains("CRC-32C"), "{err}");
        std::fs::write(ck.path(), b"not a snapshot").unwrap();
        assert!(format!("{:#}", ck.load().unwrap_err()).contains("not a readable safetensors"));
        ck.remove().unwrap();
        assert!(ck.load().unwrap().is_none());
    }
}
