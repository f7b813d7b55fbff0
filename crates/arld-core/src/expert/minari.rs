//! Minari datasets as demonstrations: `demo_file` may name a dataset that the `minari` package wrote in its Arrow
//! format (a person's answers exported with `python -m arld.answers export`, or any other dataset with the run's
//! spaces), read here without Python.
//!
//! Where: [`dataset_dir`] takes the dataset's directory, its `data/` directory, or its id (`namespace/name-vN`),
//! which is looked up as `minari` does: under `MINARI_DATASETS_PATH`, else `~/.minari/datasets`.
//!
//! What is read (minari 0.5's layout): `data/metadata.json` gives the format (`data_format`: `arrow`; `hdf5` and
//! `parquet` datasets are refused, saying how to convert them), the number of episodes and steps, and the
//! observation and action spaces (a JSON string each). Episode `i` is the Arrow IPC file(s) in `data/i/`: one row
//! per observation (`observations`, a fixed-size list of floats), and the columns `actions`, `rewards`,
//! `terminations` and `truncations`, whose last row is padding. Other columns (`infos`) are not read.
//!
//! Checks: the observation space must be a box of the run's observation size, and the action space the run's
//! (`Discrete(n)` starting at 0 with the run's n, or a box of the run's dimension and bounds); the error names
//! what differs. Each action is read as an answer of an expert process is ([`WireAction::from_wire`]) and the
//! transitions are checked by [`Demonstrations::from_columns`], like demonstrations given from Python. The files
//! are bounded before they are read (sizes, episodes and steps, see [`MAX_DATASET_BYTES`] and
//! [`MAX_TRANSITIONS`]), and a damaged file is an error naming it.
//!
//! An episode's transitions keep its ends; its last transition is marked truncated when it neither terminated nor
//! was truncated, so that episodes stay apart (as Python's `demos=` reads a dataset). Without the cargo feature
//! `minari` (the Python wheel), a dataset given here is refused with the ways round.

use super::demos::{DemoAction, Demonstrations};
#[cfg(feature = "minari")]
use super::demos::{DemoColumns, MAX_TRANSITIONS};
use anyhow::Result;
use std::path::{Path, PathBuf};

/// The file in a dataset's `data/` directory that says what it holds.
pub const METADATA_FILE: &str = "metadata.json";

/// Where `minari` keeps datasets by id: `MINARI_DATASETS_PATH`, else `~/.minari/datasets`.
pub fn datasets_root() -> Option<PathBuf> {
    match std::env::var_os("MINARI_DATASETS_PATH") {
        Some(root) => Some(PathBuf::from(root)),
        None => {
            std::env::var_os("HOME").map(|home| Path::new(&home).join(".minari").join("datasets"))
        }
    }
}

/// Whether `id` has the form of a dataset id, `namespace/name-vN` (the namespace optional, possibly nested).
fn is_dataset_id(id: &str) -> bool {
    let Some((rest, version)) = id.rsplit_once("-v") else {
        return false;
    };
    let word = |s: &str| {
        !s.is_empty()
            && s.chars()
                .all(|c| c.is_alphanumeric() || c == '-' || c == '_')
    };
    !version.is_empty() && version.chars().all(|c| c.is_ascii_digit()) && rest.split('/').all(word)
}

/// The `data/` directory of the Minari dataset that `demo_file` names, or `None` when it names none (then it is
/// an arld demonstration file): a directory holding `data/metadata.json` or itself holding `metadata.json`, or,
/// when no such file or directory exists, a dataset id found under [`datasets_root`]. An id found nowhere is an
/// error that says where it was looked for.
pub fn dataset_dir(demo_file: &Path) -> Result<Option<PathBuf>> {
    if demo_file.join("data").join(METADATA_FILE).is_file() {
        return Ok(Some(demo_file.join("data")));
    }
    if demo_file.is_dir() && demo_file.join(METADATA_FILE).is_file() {
        return Ok(Some(demo_file.to_path_buf()));
    }
    let Some(id) = demo_file.to_str() else {
        return Ok(None);
    };
    if demo_file.exists() || demo_file.is_absolute() || !is_dataset_id(id) {
        return Ok(None);
    }
    let Some(root) = datasets_root() else {
        anyhow::bail!(
            "no demonstration file {id}, and no Minari dataset {id}: neither MINARI_DATASETS_PATH nor HOME is set"
        );
    };
    let data = root.join(id).join("data");
    anyhow::ensure!(
        data.join(METADATA_FILE).is_file(),
        "no demonstration file {id}, and no Minari dataset {id} in {} (MINARI_DATASETS_PATH, else \
         ~/.minari/datasets)",
        root.display()
    );
    Ok(Some(data))
}

/// Reads the Minari dataset whose `data/` directory is `data` as demonstrations for a run on `env_id`.
#[cfg(not(feature = "minari"))]
pub fn load<A: DemoAction>(data: &Path, env_id: &str) -> Result<Demonstrations<A>> {
    anyhow::bail!(
        "{} is a Minari dataset, which this build of arld does not read (the command line does; the Python \
         package reads it as `demos=`): give it as `demos=` from Python, run on {env_id} from the command line, or \
         convert it with `python -m arld.answers to-demos DATASET OUT.jsonl` and give OUT.jsonl",
        data.display()
    )
}

/// Reads the Minari dataset whose `data/` directory is `data` as demonstrations for a run on `env_id` (see the
/// module's documentation).
#[cfg(feature = "minari")]
pub fn load<A: DemoAction>(data: &Path, env_id: &str) -> Result<Demonstrations<A>> {
    use anyhow::Context;
    let meta = Metadata::read(data)?;
    let spec = A::task(env_id)?;
    meta.check_spaces::<A>(spec, env_id)
        .map_err(|why| anyhow::anyhow!("Minari dataset {}: {why}", data.display()))?;
    let mut columns = DemoColumns::<A> {
        obs: Vec::new(),
        actions: Vec::new(),
        rewards: Vec::new(),
        next_obs: Vec::new(),
        terminated: Vec::new(),
        truncated: Vec::new(),
    };
    let mut budget = Budget::default();
    for episode in 0..meta.total_episodes {
        read_episode(&data.join(episode.to_string()), &mut columns, &mut budget)
            .with_context(|| format!("Minari dataset {}, episode {episode}", data.display()))?;
    }
    anyhow::ensure!(
        columns.actions.len() == meta.total_steps,
        "Minari dataset {}: {} says {} steps, but its episodes hold {}: the dataset is damaged",
        data.display(),
        METADATA_FILE,
        meta.total_steps,
        columns.actions.len()
    );
    let mut demos = Demonstrations::from_columns(env_id, columns)
        .with_context(|| format!("Minari dataset {}", data.display()))?;
    demos.expert = format!("minari:{}", meta.dataset_id);
    Ok(demos)
}

/// The largest `metadata.json` read.
#[cfg(feature = "minari")]
const MAX_METADATA_BYTES: u64 = 16 << 20;
/// The most bytes of a dataset's data files read (each is read whole into memory): above what
/// [`MAX_TRANSITIONS`] transitions of the largest task take.
pub const MAX_DATASET_BYTES: u64 = 2 << 30;

/// What a dataset's `metadata.json` says that the reader needs.
#[cfg(feature = "minari")]
struct Metadata {
    dataset_id: String,
    total_episodes: usize,
    total_steps: usize,
    observation_space: serde_json::Value,
    action_space: serde_json::Value,
}

#[cfg(feature = "minari")]
impl Metadata {
    /// Reads `data/metadata.json` and checks the format and counts.
    fn read(data: &Path) -> Result<Self> {
        use anyhow::{Context, bail, ensure};
        let path = data.join(METADATA_FILE);
        let text = read_bounded(&path, MAX_METADATA_BYTES)?;
        let text = String::from_utf8(text)
            .with_context(|| format!("{}: not UTF-8 text", path.display()))?;
        // Python writes infinite bounds as `Infinity`, which is not JSON: read as null (no bound arld accepts).
        let json = |text: &str| -> Result<serde_json::Value> {
            let text = text
                .replace("-Infinity", "null")
                .replace("Infinity", "null")
                .replace("NaN", "null");
            Ok(serde_json::from_str(&text)?)
        };
        let meta = json(&text)
            .with_context(|| format!("{}: not a Minari metadata file", path.display()))?;
        let field = |key: &str| {
            meta.get(key).with_context(|| {
                format!("{}: no `{key}`; is this a Minari dataset?", path.display())
            })
        };
        let format = field("data_format")?.as_str().unwrap_or_default();
        match format {
            "arrow" => {}
            "hdf5" => bail!(
                "{}: a Minari dataset in the HDF5 format, which arld reads only in the Arrow format: write it again \
                 with minari's `data_format=\"arrow\"` (minari.create_dataset_from_buffers over its episodes), or \
                 give it from Python as `demos=`",
                data.display()
            ),
            other => bail!(
                "{}: a Minari dataset in the format `{other}`; arld reads the Arrow format: write it again with \
                 minari's `data_format=\"arrow\"`, or give it from Python as `demos=`",
                data.display()
            ),
        }
        let count = |key: &str| -> Result<usize> {
            let n = field(key)?
                .as_u64()
                .with_context(|| format!("{}: `{key}` is not a count", path.display()))?;
            ensure!(
                n <= MAX_TRANSITIONS as u64,
                "{}: `{key}` is {n}; more than {MAX_TRANSITIONS} are refused",
                path.display()
            );
            Ok(n as usize)
        };
        let (total_episodes, total_steps) = (count("total_episodes")?, count("total_steps")?);
        ensure!(
            total_episodes > 0 && total_steps > 0,
            "{}: the dataset holds no transitions; DQfD and ADQNP pre-train on demonstrations",
            path.display()
        );
        let space = |key: &str| -> Result<serde_json::Value> {
            let text = field(key)?.as_str().with_context(|| {
                format!("{}: `{key}` is not a space description", path.display())
            })?;
            json(text)
                .with_context(|| format!("{}: `{key}` is not a space description", path.display()))
        };
        Ok(Self {
            dataset_id: field("dataset_id")?
                .as_str()
                .unwrap_or_default()
                .to_string(),
            total_episodes,
            total_steps,
            observation_space: space("observation_space")?,
            action_space: space("action_space")?,
        })
    }

    /// Checks the dataset's spaces against the task `spec` of the run on `env_id`; the error says what differs.
    fn check_spaces<A: DemoAction>(
        &self,
        spec: &A::Spec,
        env_id: &str,
    ) -> std::result::Result<(), String> {
        use crate::task::TaskSpec;
        let obs = &self.observation_space;
        let obs_size = box_size(obs);
        if obs_size != Some(spec.obs_dim()) {
            return Err(format!(
                "its observations are {}, but {env_id} observes {} numbers",
                describe(obs),
                spec.obs_dim()
            ));
        }
        let theirs = &self.action_space;
        let ours = A::action_space(spec);
        let as_ours = match theirs.get("type").and_then(|t| t.as_str()) {
            Some("Discrete") if theirs.get("start").and_then(|s| s.as_i64()).unwrap_or(0) == 0 => {
                serde_json::json!({"type": "discrete", "n": theirs.get("n")})
            }
            Some("Box") => serde_json::json!({
                "type": "box",
                "shape": [box_size(theirs)],
                "low": f32_list(theirs.get("low")),
                "high": f32_list(theirs.get("high")),
            }),
            _ => serde_json::Value::Null,
        };
        if as_ours != ours {
            return Err(format!(
                "its actions are {}, but {env_id}'s are {}",
                describe(theirs),
                describe_ours(&ours)
            ));
        }
        Ok(())
    }
}

/// The number of values in an observation or action of the Minari box space `space`; `None` for another space.
#[cfg(feature = "minari")]
fn box_size(space: &serde_json::Value) -> Option<usize> {
    if space.get("type")?.as_str()? != "Box" {
        return None;
    }
    space
        .get("shape")?
        .as_array()?
        .iter()
        .try_fold(1usize, |n, d| {
            n.checked_mul(usize::try_from(d.as_u64()?).ok()?)
        })
}

/// A Minari space's bounds as arld's (f32), or `null` when one is not a finite number.
#[cfg(feature = "minari")]
fn f32_list(bounds: Option<&serde_json::Value>) -> serde_json::Value {
    let list: Option<Vec<f32>> = bounds.and_then(|b| b.as_array()).and_then(|b| {
        b.iter()
            .map(|x| x.as_f64().map(|x| x as f32).filter(|x| x.is_finite()))
            .collect()
    });
    serde_json::json!(list)
}

/// A Minari space for an error message: `Discrete(3)`, `Box([-2.0] to [2.0], shape [1])`, else its description.
#[cfg(feature = "minari")]
fn describe(space: &serde_json::Value) -> String {
    let get = |key: &str| space.get(key).map(|v| v.to_string()).unwrap_or_default();
    match space.get("type").and_then(|t| t.as_str()) {
        Some("Discrete") if get("start") == "0" || get("start").is_empty() => {
            format!("Discrete({})", get("n"))
        }
        Some("Discrete") => format!("Discrete({}, start={})", get("n"), get("start")),
        Some("Box") => format!(
            "Box({} to {}, shape {})",
            // (An infinite bound is read as null: below, the lower bounds' -inf, the upper bounds' inf.)
            get("low").replace("null", "-inf"),
            get("high").replace("null", "inf"),
            get("shape")
        ),
        _ => space.to_string(),
    }
}

/// arld's action space ([`WireAction::action_space`]) in Minari's words.
#[cfg(feature = "minari")]
fn describe_ours(space: &serde_json::Value) -> String {
    let get = |key: &str| space.get(key).map(|v| v.to_string()).unwrap_or_default();
    match space.get("type").and_then(|t| t.as_str()) {
        Some("discrete") => format!("Discrete({})", get("n")),
        Some("box") => format!(
            "Box({} to {}, shape {})",
            get("low"),
            get("high"),
            get("shape")
        ),
        _ => space.to_string(),
    }
}

/// The bytes of a dataset's files read so far (at most [`MAX_DATASET_BYTES`] in all).
#[cfg(feature = "minari")]
#[derive(Default)]
struct Budget {
    bytes: u64,
}

/// Reads a file of at most `max` bytes whole.
#[cfg(feature = "minari")]
fn read_bounded(path: &Path, max: u64) -> Result<Vec<u8>> {
    use anyhow::Context;
    crate::files::read_bounded(path, max).with_context(|| format!("cannot read {}", path.display()))
}

/// The Arrow files of an episode's directory, in the order `pyarrow` reads them (by name; names starting with
/// `.` or `_` are not data).
#[cfg(feature = "minari")]
fn episode_files(dir: &Path) -> Result<Vec<PathBuf>> {
    use anyhow::Context;
    let mut files = Vec::new();
    for entry in
        std::fs::read_dir(dir).with_context(|| format!("no episode directory {}", dir.display()))?
    {
        let entry = entry?;
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if name.ends_with(".arrow") && !name.starts_with('.') && !name.starts_with('_') {
            files.push(entry.path());
        }
    }
    files.sort();
    anyhow::ensure!(!files.is_empty(), "{}: no Arrow file", dir.display());
    Ok(files)
}

/// One episode's rows, column by column (the padding row included).
#[cfg(feature = "minari")]
#[derive(Default)]
struct EpisodeRows {
    obs: Vec<Vec<f32>>,
    actions: Vec<serde_json::Value>,
    rewards: Vec<f32>,
    terminated: Vec<bool>,
    truncated: Vec<bool>,
}

/// Appends the transitions of the episode in `dir` to `columns`.
#[cfg(feature = "minari")]
fn read_episode<A: DemoAction>(
    dir: &Path,
    columns: &mut DemoColumns<A>,
    budget: &mut Budget,
) -> Result<()> {
    use anyhow::{Context, ensure};
    let mut rows = EpisodeRows::default();
    for file in episode_files(dir)? {
        let bytes = read_bounded(&file, MAX_DATASET_BYTES - budget.bytes)
            .context("the dataset is larger than arld reads")?;
        budget.bytes += bytes.len() as u64;
        let projection = check_layout(&bytes).map_err(|why| {
            anyhow::anyhow!("{}: not a readable Arrow IPC file: {why}", file.display())
        })?;
        let reader =
            arrow_ipc::reader::FileReader::try_new(std::io::Cursor::new(bytes), Some(projection))
                .with_context(|| format!("{}: not an Arrow IPC file", file.display()))?;
        for batch in reader {
            let batch = batch.with_context(|| format!("{}: damaged Arrow data", file.display()))?;
            ensure!(
                columns.actions.len() + rows.obs.len() + batch.num_rows() <= MAX_TRANSITIONS + 1,
                "the dataset holds more than {MAX_TRANSITIONS} transitions, which are refused"
            );
            rows.append(&batch)
                .map_err(|why| anyhow::anyhow!("{}: {why}", file.display()))?;
        }
    }
    let n = rows
        .obs
        .len()
        .checked_sub(1)
        .context("an episode with no observation")?;
    ensure!(n > 0, "an episode with no step");
    for (i, action) in rows.actions.iter().take(n).enumerate() {
        let action = A::from_wire(action).with_context(|| {
            format!("step {i}: the action {action} is not an action of the run's kind")
        })?;
        columns.actions.push(action);
    }
    let mut truncated = rows.truncated[..n].to_vec();
    if !rows.terminated[n - 1] {
        truncated[n - 1] = true; // the episode's end: learning bootstraps there unless it terminated
    }
    columns.next_obs.extend(rows.obs[1..].iter().cloned());
    rows.obs.truncate(n);
    columns.obs.extend(rows.obs);
    columns.rewards.extend_from_slice(&rows.rewards[..n]);
    columns.terminated.extend_from_slice(&rows.terminated[..n]);
    columns.truncated.extend(truncated);
    Ok(())
}

#[cfg(feature = "minari")]
impl EpisodeRows {
    /// Appends the rows of `batch`; the error names a column that is missing or of another type.
    fn append(&mut self, batch: &arrow_array::RecordBatch) -> std::result::Result<(), String> {
        use arrow_array::cast::AsArray;
        use arrow_array::types::{Float32Type, Float64Type};
        let column = |name: &str| {
            let c = batch
                .column_by_name(name)
                .ok_or_else(|| format!("no column `{name}`"))?;
            if c.null_count() > 0 {
                return Err(format!("column `{name}` has missing values"));
            }
            Ok(c)
        };
        let rows = batch.num_rows();
        self.obs.extend(
            float_lists(column("observations")?, rows)
                .map_err(|t| format!("`observations` {t}"))?,
        );
        let actions = column("actions")?;
        if actions.as_fixed_size_list_opt().is_some() {
            let values = float_lists(actions, rows).map_err(|t| format!("`actions` {t}"))?;
            self.actions
                .extend(values.into_iter().map(|a| serde_json::json!(a)));
        } else {
            self.actions
                .extend(integers(actions.as_ref()).map_err(|t| format!("`actions` {t}"))?);
        }
        let rewards = column("rewards")?;
        if let Some(r) = rewards.as_primitive_opt::<Float64Type>() {
            self.rewards.extend(r.values().iter().map(|&r| r as f32));
        } else if let Some(r) = rewards.as_primitive_opt::<Float32Type>() {
            self.rewards.extend(r.values().iter().copied());
        } else {
            return Err(format!("`rewards` are {}, not floats", rewards.data_type()));
        }
        for (name, out) in [
            ("terminations", &mut self.terminated),
            ("truncations", &mut self.truncated),
        ] {
            let c = column(name)?;
            let flags = c
                .as_boolean_opt()
                .ok_or_else(|| format!("`{name}` are {}, not booleans", c.data_type()))?;
            out.extend(flags.values().iter());
        }
        let lens = [
            self.actions.len(),
            self.rewards.len(),
            self.terminated.len(),
            self.truncated.len(),
        ];
        if lens.iter().any(|&l| l != self.obs.len()) {
            return Err("columns of different lengths".to_string());
        }
        Ok(())
    }
}

/// The rows of a fixed-size list column of floats (f32 or f64, read as f32).
#[cfg(feature = "minari")]
fn float_lists(
    column: &arrow_array::ArrayRef,
    rows: usize,
) -> std::result::Result<Vec<Vec<f32>>, String> {
    use arrow_array::Array;
    use arrow_array::cast::AsArray;
    use arrow_array::types::{Float32Type, Float64Type};
    let list = column
        .as_fixed_size_list_opt()
        .ok_or_else(|| format!("are {}, not lists of floats", column.data_type()))?;
    let width =
        usize::try_from(list.value_length()).map_err(|_| "have a negative width".to_string())?;
    let values = list.values();
    if values.null_count() > 0 {
        return Err("have missing values".to_string());
    }
    let floats: Vec<f32> = if let Some(v) = values.as_primitive_opt::<Float32Type>() {
        v.values().to_vec()
    } else if let Some(v) = values.as_primitive_opt::<Float64Type>() {
        v.values().iter().map(|&x| x as f32).collect()
    } else {
        return Err(format!(
            "are lists of {}, not of floats",
            values.data_type()
        ));
    };
    let needed = rows.checked_mul(width).ok_or("are too large")?;
    if list.len() != rows || floats.len() < needed {
        return Err("are shorter than the batch".to_string());
    }
    if width == 0 {
        return Ok(vec![Vec::new(); rows]);
    }
    Ok(floats[..needed]
        .chunks(width)
        .map(<[f32]>::to_vec)
        .collect())
}

/// The values of an integer column, as JSON numbers (what an answer's action is).
#[cfg(feature = "minari")]
fn integers(
    column: &dyn arrow_array::Array,
) -> std::result::Result<Vec<serde_json::Value>, String> {
    use arrow_array::cast::AsArray;
    use arrow_array::types::{
        ArrowPrimitiveType, Int8Type, Int16Type, Int32Type, Int64Type, UInt8Type, UInt16Type,
        UInt32Type, UInt64Type,
    };
    use arrow_buffer::ArrowNativeType;
    fn of<T: ArrowPrimitiveType>(
        column: &dyn arrow_array::Array,
    ) -> Option<Vec<serde_json::Value>> {
        let array = column.as_primitive_opt::<T>()?;
        Some(
            array
                .values()
                .iter()
                .map(|v| {
                    v.to_i64()
                        .map_or(serde_json::Value::Null, serde_json::Value::from)
                })
                .collect(),
        )
    }
    of::<Int64Type>(column)
        .or_else(|| of::<Int32Type>(column))
        .or_else(|| of::<Int16Type>(column))
        .or_else(|| of::<Int8Type>(column))
        .or_else(|| of::<UInt64Type>(column))
        .or_else(|| of::<UInt32Type>(column))
        .or_else(|| of::<UInt16Type>(column))
        .or_else(|| of::<UInt8Type>(column))
        .ok_or_else(|| {
            format!(
                "are {}, neither integers nor lists of floats",
                column.data_type()
            )
        })
}

/// The columns a dataset's episode file must have, all that is read of it.
#[cfg(feature = "minari")]
const COLUMNS: [&str; 5] = [
    "observations",
    "actions",
    "rewards",
    "terminations",
    "truncations",
];

/// The longest fixed-size list read (an observation or action of 16M values).
#[cfg(feature = "minari")]
const MAX_LIST: i32 = 1 << 24;

/// Checks the layout of the Arrow IPC file `bytes` before the `arrow-ipc` reader takes it, and returns the
/// positions of [`COLUMNS`]. The reader trusts the lengths and offsets a file states (a damaged one can make it
/// allocate what the file says, overflow or slice out of range, which panic), so every block, message, buffer,
/// column length and list size is checked here to lie within the file; only the columns read are decoded, and
/// files with dictionaries, unions or compression are refused (minari writes none).
#[cfg(feature = "minari")]
fn check_layout(bytes: &[u8]) -> std::result::Result<Vec<usize>, String> {
    const MAGIC: &[u8] = b"ARROW1";
    let len = bytes.len();
    if len < 8 + 10 || &bytes[..6] != MAGIC || &bytes[len - 6..] != MAGIC {
        return Err("no ARROW1 at its start and end".into());
    }
    let footer_len = i32::from_le_bytes([
        bytes[len - 10],
        bytes[len - 9],
        bytes[len - 8],
        bytes[len - 7],
    ]);
    let footer_start = usize::try_from(footer_len)
        .ok()
        .and_then(|n| (len - 10).checked_sub(n))
        .filter(|&start| start >= 8)
        .ok_or("its footer's length is not within the file")?;
    let footer = arrow_ipc::root_as_footer(&bytes[footer_start..len - 10])
        .map_err(|e| format!("a damaged footer ({e})"))?;
    if footer.dictionaries().is_some_and(|d| !d.is_empty()) {
        return Err("dictionary-encoded columns, which arld does not read".into());
    }
    fn check_field(field: arrow_ipc::Field<'_>) -> std::result::Result<(), String> {
        if field.type_type() == arrow_ipc::Type::Union || field.dictionary().is_some() {
            return Err("a union or dictionary-encoded column, which arld does not read".into());
        }
        if let Some(list) = field.type_as_fixed_size_list()
            && !(0..=MAX_LIST).contains(&list.listSize())
        {
            return Err(format!("a list of {} values", list.listSize()));
        }
        field.children().iter().flatten().try_for_each(check_field)
    }
    let fields: Vec<_> = footer
        .schema()
        .ok_or("no schema")?
        .fields()
        .iter()
        .flatten()
        .collect();
    fields.iter().copied().try_for_each(check_field)?;
    let projection = COLUMNS
        .iter()
        .map(|&name| {
            fields
                .iter()
                .position(|f| f.name() == Some(name))
                .ok_or_else(|| format!("no column `{name}`"))
        })
        .collect::<std::result::Result<Vec<usize>, String>>()?;
    let range = |what: &str, start: i64, n: i64, end: usize| {
        let start = usize::try_from(start).map_err(|_| format!("a negative {what} offset"))?;
        let n = usize::try_from(n).map_err(|_| format!("a negative {what} length"))?;
        start
            .checked_add(n)
            .filter(|&stop| stop <= end)
            .map(|stop| start..stop)
            .ok_or_else(|| format!("a {what} past its end"))
    };
    for block in footer.recordBatches().iter().flatten() {
        let meta = range(
            "record batch",
            block.offset(),
            i64::from(block.metaDataLength()),
            footer_start,
        )?;
        let body = range(
            "record batch",
            meta.end as i64,
            block.bodyLength(),
            footer_start,
        )?;
        let meta = &bytes[meta];
        let (prefix, n) = match meta {
            [0xff, 0xff, 0xff, 0xff, a, b, c, d, ..] => (8, i32::from_le_bytes([*a, *b, *c, *d])),
            [a, b, c, d, ..] => (4, i32::from_le_bytes([*a, *b, *c, *d])),
            _ => return Err("a record batch without its message".into()),
        };
        let message = range("message", prefix, i64::from(n), meta.len())?;
        let message = arrow_ipc::root_as_message(&meta[message])
            .map_err(|e| format!("a damaged message ({e})"))?;
        let batch = message
            .header_as_record_batch()
            .ok_or("a block that is not a record batch")?;
        if batch.compression().is_some() {
            return Err("compressed buffers, which arld does not read: write the dataset again uncompressed".into());
        }
        // A column of n values takes at least n bits of the body.
        let most = 8 * body.len() as i64 + 64;
        if !(0..=most).contains(&batch.length()) {
            return Err(format!("{} rows in {} bytes", batch.length(), body.len()));
        }
        for node in batch.nodes().iter().flatten() {
            if !(0..=most).contains(&node.length())
                || !(0..=node.length()).contains(&node.null_count())
            {
                return Err(format!(
                    "a column of {} values in {} bytes",
                    node.length(),
                    body.len()
                ));
            }
        }
        for buffer in batch.buffers().iter().flatten() {
            range("buffer", buffer.offset(), buffer.length(), body.len())?;
        }
    }
    Ok(projection)
}
