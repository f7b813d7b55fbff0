//! Saving and loading a [`QNet`] as a safetensors file, readable from Python (`safetensors.torch.load_file`).
//!
//! Every tensor is written in PyTorch's `nn.Linear` layout (`weight [out][in]`, `bias [out]`) under a
//! readable name, whatever the in-memory layout:
//! - trunk: `fc1.weight [h1][obs_dim]`, `fc1.bias`, `fc2.weight [h2][h1]`, `fc2.bias`, ... up to `fc{L}` for L
//!   hidden layers (two of 64 in the paper; at most [`MAX_DEPTH`]);
//! - `Plain`: `out.weight [A][h_L]`, `out.bias [A]`;
//! - `Bootstrap`: `heads.{k}.weight [A][h_L]`, `heads.{k}.bias [A]` for k = 0..K;
//! - `Noisy`: `noisy.mu_w [A][h_L]`, `noisy.sigma_w [A][h_L]`, `noisy.mu_b [A]`, `noisy.sigma_b [A]`.
//!
//! The header metadata holds `kind` (`plain`/`bootstrap`/`noisy`), `heads`, `obs_dim` and `n_actions`, plus
//! the caller's own keys, which [`QNet::load`] hands back; the depth and the hidden widths are the trunk tensors'
//! names and shapes. Files are written atomically (temporary file in
//! the same directory, then rename), and loading validates everything before building a network.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use safetensors::tensor::TensorView;
use safetensors::{Dtype, SafeTensors};
use thiserror::Error;

use super::linear::MatView;
use super::{HIDDEN, HiddenLayers, Layout, MAX_DEPTH, MAX_HIDDEN, OutputKind, QNet};

/// Metadata keys the network itself writes; callers may not use them.
const RESERVED_KEYS: [&str; 4] = ["kind", "heads", "obs_dim", "n_actions"];

/// Errors reading or writing a model file.
#[derive(Debug, Error)]
pub enum ModelFileError {
    #[error("cannot read model file {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot write model file {path}: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path} is not a valid safetensors file (truncated or corrupt?): {source}")]
    Corrupt {
        path: PathBuf,
        source: safetensors::SafeTensorError,
    },
    #[error("{path}: metadata key '{key}' {problem}")]
    Metadata {
        path: PathBuf,
        key: String,
        problem: String,
    },
    #[error(
        "{path}: tensor '{name}' is missing (a {kind} network with {n_actions} actions needs it)"
    )]
    MissingTensor {
        path: PathBuf,
        name: String,
        kind: String,
        n_actions: usize,
    },
    #[error("{path}: unexpected tensor '{name}' for this network kind")]
    UnexpectedTensor { path: PathBuf, name: String },
    #[error("{path}: tensor '{name}' has shape {found:?}, expected {expected:?}")]
    Shape {
        path: PathBuf,
        name: String,
        expected: Vec<usize>,
        found: Vec<usize>,
    },
    #[error("{path}: tensor '{name}' has dtype {found}, expected F32")]
    Dtype {
        path: PathBuf,
        name: String,
        found: String,
    },
    #[error("{path}: tensor '{name}' contains a non-finite value")]
    NonFinite { path: PathBuf, name: String },
    #[error(
        "{path}: the network has {depth} hidden layers (fc1 to fc{depth}), more than the {max} supported",
        max = MAX_DEPTH
    )]
    TooDeep { path: PathBuf, depth: usize },
    #[error("metadata key '{key}' is reserved for the network description")]
    ReservedKey { key: String },
}

/// One tensor of the file: its name, PyTorch shape, and where its elements live in the flat parameters.
struct FileTensor {
    name: String,
    shape: Vec<usize>,
    /// Offset of element (0, 0) in the flat parameter vector.
    base: usize,
    /// Placement of the `[rows][cols]` file matrix (a bias is `[n][1]`) relative to `base`.
    view: MatView,
}

impl FileTensor {
    fn matrix(
        name: impl Into<String>,
        rows: usize,
        cols: usize,
        base: usize,
        view: MatView,
    ) -> Self {
        Self {
            name: name.into(),
            shape: vec![rows, cols],
            base,
            view,
        }
    }

    fn vector(name: impl Into<String>, len: usize, base: usize) -> Self {
        Self {
            name: name.into(),
            shape: vec![len],
            base,
            view: MatView::row_major(len, 1),
        }
    }

    fn len(&self) -> usize {
        self.view.rows * self.view.cols
    }

    /// Flat-parameter index of every file element, in file (row-major) order.
    fn indices(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.view.rows).flat_map(move |r| {
            (0..self.view.cols)
                .map(move |c| self.base + r * self.view.row_stride + c * self.view.col_stride)
        })
    }
}

/// The file's tensors for a network layout (see the module docs).
fn file_tensors(layout: &Layout) -> Vec<FileTensor> {
    let (a, width) = (layout.n_actions, layout.out_width);
    let n2 = layout.last_width();
    // Storage is [in][out]: the file's [out][in] element (o, i) sits at i*out + o.
    let transposed = |outputs: usize, inputs: usize| MatView::row_major(inputs, outputs).t();
    let mut tensors = Vec::new();
    for (i, &n) in layout.hidden.iter().enumerate() {
        let n_in = layout.input_width(i);
        let name = format!("fc{}", i + 1);
        tensors.push(FileTensor::matrix(
            format!("{name}.weight"),
            n,
            n_in,
            layout.fc_w[i].start,
            transposed(n, n_in),
        ));
        tensors.push(FileTensor::vector(
            format!("{name}.bias"),
            n,
            layout.fc_b[i].start,
        ));
    }
    match layout.kind {
        OutputKind::Plain => {
            tensors.push(FileTensor::matrix(
                "out.weight",
                a,
                n2,
                layout.out_w.start,
                transposed(a, n2),
            ));
            tensors.push(FileTensor::vector("out.bias", a, layout.out_b.start));
        }
        OutputKind::Bootstrap { heads } => {
            for head in 0..heads {
                // Head k: columns k*A..(k+1)*A of the fused [h2][K*A] storage.
                let view = MatView {
                    rows: a,
                    cols: n2,
                    row_stride: 1,
                    col_stride: width,
                };
                tensors.push(FileTensor::matrix(
                    format!("heads.{head}.weight"),
                    a,
                    n2,
                    layout.out_w.start + head * a,
                    view,
                ));
                tensors.push(FileTensor::vector(
                    format!("heads.{head}.bias"),
                    a,
                    layout.out_b.start + head * a,
                ));
            }
        }
        OutputKind::Noisy => {
            let row_major = MatView::row_major(a, n2);
            tensors.push(FileTensor::matrix(
                "noisy.mu_w",
                a,
                n2,
                layout.out_w.start,
                row_major,
            ));
            tensors.push(FileTensor::matrix(
                "noisy.sigma_w",
                a,
                n2,
                layout.sigma_w.start,
                row_major,
            ));
            tensors.push(FileTensor::vector("noisy.mu_b", a, layout.out_b.start));
            tensors.push(FileTensor::vector("noisy.sigma_b", a, layout.sigma_b.start));
        }
    }
    tensors
}

fn kind_name(kind: OutputKind) -> &'static str {
    match kind {
        OutputKind::Plain => "plain",
        OutputKind::Bootstrap { .. } => "bootstrap",
        OutputKind::Noisy => "noisy",
    }
}

/// Rewrites a safetensors file's header with its `__metadata__` keys in sorted order. `safetensors::serialize`
/// takes the metadata as a `HashMap`, whose order changes from process to process; sorting makes the same network
/// give the same bytes. The header is padded with spaces to keep the data 8-byte aligned, as the format requires.
pub(crate) fn with_sorted_metadata(bytes: Vec<u8>) -> anyhow::Result<Vec<u8>> {
    #[derive(serde::Serialize, serde::Deserialize)]
    #[serde(untagged)]
    enum Entry {
        Metadata(BTreeMap<String, String>),
        Tensor(serde_json::Value),
    }
    let length = u64::from_le_bytes(bytes[..8].try_into()?) as usize;
    let header: BTreeMap<String, Entry> = serde_json::from_slice(&bytes[8..8 + length])?;
    let mut text = serde_json::to_vec(&header)?;
    text.resize(text.len().next_multiple_of(8), b' ');
    let mut out = Vec::with_capacity(8 + text.len() + bytes.len() - 8 - length);
    out.extend_from_slice(&(text.len() as u64).to_le_bytes());
    out.extend_from_slice(&text);
    out.extend_from_slice(&bytes[8 + length..]);
    Ok(out)
}

impl QNet {
    /// Saves the network as safetensors at `path` (atomically), with `metadata` added to the header.
    ///
    /// Fails if `metadata` uses a reserved key (`kind`, `heads`, `obs_dim`, `n_actions`) or the file
    /// cannot be written.
    pub fn save(&self, path: &Path, metadata: &BTreeMap<String, String>) -> anyhow::Result<()> {
        let layout = self.layout();
        let mut header: HashMap<String, String> = HashMap::new();
        for (key, value) in metadata {
            if RESERVED_KEYS.contains(&key.as_str()) {
                return Err(ModelFileError::ReservedKey { key: key.clone() }.into());
            }
            header.insert(key.clone(), value.clone());
        }
        header.insert("kind".into(), kind_name(layout.kind).into());
        header.insert("heads".into(), layout.heads().to_string());
        header.insert("obs_dim".into(), layout.obs_dim.to_string());
        header.insert("n_actions".into(), layout.n_actions.to_string());

        let params = self.parameters();
        let tensors = file_tensors(layout);
        let buffers: Vec<Vec<u8>> = tensors
            .iter()
            .map(|t| t.indices().flat_map(|i| params[i].to_le_bytes()).collect())
            .collect();
        let views = tensors
            .iter()
            .zip(&buffers)
            .map(|(t, bytes)| {
                Ok((
                    t.name.clone(),
                    TensorView::new(Dtype::F32, t.shape.clone(), bytes)?,
                ))
            })
            .collect::<Result<Vec<_>, safetensors::SafeTensorError>>()?;
        let bytes = with_sorted_metadata(safetensors::serialize(views, Some(header))?)?;
        crate::files::write_atomic(path, &bytes).map_err(|e| ModelFileError::Write {
            path: e.path,
            source: e.source,
        })?;
        Ok(())
    }

    /// Loads a network saved by [`QNet::save`]; returns it with the caller's metadata (reserved keys removed).
    ///
    /// Validates the whole file: readable, a complete safetensors file, a known kind with positive sizes,
    /// every expected tensor present as F32 with the right shape and finite values, and no extra tensors.
    pub fn load(path: &Path) -> anyhow::Result<(QNet, BTreeMap<String, String>)> {
        Ok(load_file(path)?)
    }
}

/// The largest model file read: far above any network of this crate (a 10-head LunarLander network is ~25 kB).
pub const MAX_MODEL_FILE_BYTES: u64 = 256 << 20;
/// The largest observation size and action count a model file may declare.
const MAX_DIM: usize = 1 << 16;
/// The largest number of bootstrap heads a model file may declare.
const MAX_HEADS: usize = 1024;

fn load_file(path: &Path) -> Result<(QNet, BTreeMap<String, String>), ModelFileError> {
    let read_error = |source| ModelFileError::Read {
        path: path.to_path_buf(),
        source,
    };
    let bytes = crate::files::read_bounded(path, MAX_MODEL_FILE_BYTES).map_err(read_error)?;
    parse_model(path, &bytes)
}

/// Parses the bytes of a model file (`path` only names it in errors). Every size the header declares is
/// bounded and checked against the bytes actually present before anything is allocated.
pub fn parse_model(
    path: &Path,
    bytes: &[u8],
) -> Result<(QNet, BTreeMap<String, String>), ModelFileError> {
    let path_buf = || path.to_path_buf();
    let corrupt = |source| ModelFileError::Corrupt {
        path: path_buf(),
        source,
    };
    let (_, header) = SafeTensors::read_metadata(bytes).map_err(corrupt)?;
    let file = SafeTensors::deserialize(bytes).map_err(corrupt)?;
    let mut metadata: BTreeMap<String, String> = header
        .metadata()
        .clone()
        .unwrap_or_default()
        .into_iter()
        .collect();

    let metadata_error = |key: &str, problem: String| ModelFileError::Metadata {
        path: path_buf(),
        key: key.to_string(),
        problem,
    };
    let mut take = |key: &str| {
        metadata
            .remove(key)
            .ok_or_else(|| metadata_error(key, "is missing".into()))
    };
    let kind_text = take("kind")?;
    let heads_text = take("heads")?;
    let obs_dim_text = take("obs_dim")?;
    let n_actions_text = take("n_actions")?;
    let positive = |key: &str, text: &str| match text.parse::<usize>() {
        Ok(value) if value > 0 => Ok(value),
        _ => Err(metadata_error(
            key,
            format!("must be a positive integer, found '{text}'"),
        )),
    };
    let bounded = |key: &str, text: &str, max: usize| {
        let value = positive(key, text)?;
        if value > max {
            return Err(metadata_error(
                key,
                format!("is {value}, more than the largest supported ({max})"),
            ));
        }
        Ok(value)
    };
    let heads = bounded("heads", &heads_text, MAX_HEADS)?;
    let obs_dim = bounded("obs_dim", &obs_dim_text, MAX_DIM)?;
    let n_actions = bounded("n_actions", &n_actions_text, MAX_DIM)?;
    let kind = match kind_text.as_str() {
        "plain" => OutputKind::Plain,
        "bootstrap" => OutputKind::Bootstrap { heads },
        "noisy" => OutputKind::Noisy,
        other => {
            return Err(metadata_error(
                "kind",
                format!("must be plain, bootstrap or noisy, found '{other}'"),
            ));
        }
    };
    if kind.heads() != heads {
        return Err(metadata_error(
            "heads",
            format!("is {heads}, but a {kind_text} network has {}", kind.heads()),
        ));
    }

    // The depth: the trunk layers `fc1.weight`, `fc2.weight`, ... present in an unbroken run from `fc1` (at
    // least one: a file without `fc1.weight` is refused below for the missing tensor).
    let depth = (1..)
        .take_while(|i| file.tensor(&format!("fc{i}.weight")).is_ok())
        .count()
        .max(1);
    if depth > MAX_DEPTH {
        return Err(ModelFileError::TooDeep {
            path: path_buf(),
            depth,
        });
    }
    // The hidden widths: the trunk's output sizes, `fc{i}.weight [h_i][..]`. A tensor missing, or a width out
    // of range, leaves the paper's width, and the shape checks below name the tensor.
    let width = |i: usize| {
        file.tensor(&format!("fc{}.weight", i + 1))
            .ok()
            .and_then(|t| t.shape().first().copied())
            .filter(|w| (1..=MAX_HIDDEN).contains(w))
            .unwrap_or(HIDDEN)
    };
    let widths: Vec<usize> = (0..depth).map(width).collect();
    let hidden = HiddenLayers::new(&widths).expect("depth is 1..=MAX_DEPTH");
    let n2 = widths[depth - 1];
    // Parameters the declared sizes need, against the data the file really holds (before allocating them).
    let trunk: usize = (0..depth)
        .map(|i| (if i == 0 { obs_dim } else { widths[i - 1] } + 1) * widths[i])
        .sum();
    let needed =
        trunk + heads * n_actions * (n2 + 1) * if kind == OutputKind::Noisy { 2 } else { 1 };
    if needed.saturating_mul(4) > bytes.len() {
        return Err(metadata_error(
            "n_actions",
            format!(
                "with obs_dim {obs_dim} and {heads} head(s) the network has {needed} parameters, more than the \
                 file's {} bytes can hold",
                bytes.len()
            ),
        ));
    }
    let layout = Layout::new(obs_dim, n_actions, kind, hidden);
    let expected = file_tensors(&layout);
    for name in file.names() {
        if !expected.iter().any(|t| t.name == name) {
            return Err(ModelFileError::UnexpectedTensor {
                path: path_buf(),
                name: name.to_string(),
            });
        }
    }
    let mut params = vec![0.0f32; layout.len];
    for tensor in &expected {
        let view = file
            .tensor(&tensor.name)
            .map_err(|_| ModelFileError::MissingTensor {
                path: path_buf(),
                name: tensor.name.clone(),
                kind: kind_text.clone(),
                n_actions,
            })?;
        if view.dtype() != Dtype::F32 {
            return Err(ModelFileError::Dtype {
                path: path_buf(),
                name: tensor.name.clone(),
                found: view.dtype().to_string(),
            });
        }
        if view.shape() != tensor.shape.as_slice() {
            return Err(ModelFileError::Shape {
                path: path_buf(),
                name: tensor.name.clone(),
                expected: tensor.shape.clone(),
                found: view.shape().to_vec(),
            });
        }
        let data = view.data();
        debug_assert_eq!(data.len(), tensor.len() * 4);
        for (index, chunk) in tensor.indices().zip(data.chunks_exact(4)) {
            let value = f32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]);
            if !value.is_finite() {
                return Err(ModelFileError::NonFinite {
                    path: path_buf(),
                    name: tensor.name.clone(),
                });
            }
            params[index] = value;
        }
    }
    Ok((QNet::from_parts(layout, params), metadata))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use std::fs;

    #[test]
    fn same_network_same_bytes_with_metadata_in_sorted_order() {
        // The metadata reaches safetensors as a HashMap; saved twice (each HashMap with its own random order),
        // the files must be byte-identical and the header's metadata keys sorted.
        let dir = tempfile::tempdir().unwrap();
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        let net = QNet::new(4, 2, OutputKind::Bootstrap { heads: 3 }, &mut rng);
        let mut metadata = example_metadata();
        for i in 0..20 {
            metadata.insert(format!("key{i}"), i.to_string());
        }
        let files: Vec<Vec<u8>> = (0..2)
            .map(|i| {
                let path = dir.path().join(format!("n{i}.safetensors"));
                net.save(&path, &metadata).unwrap();
                std::fs::read(&path).unwrap()
            })
            .collect();
        assert!(files[0] == files[1], "two saves of one network differ");
        let text = String::from_utf8_lossy(&files[0][8..800]).to_string();
        let positions: Vec<usize> = [
            "env",
            "heads",
            "key0",
            "key1",
            "kind",
            "n_actions",
            "obs_dim",
            "seed",
        ]
        .iter()
        .map(|k| {
            text.find(&format!("\"{k}\""))
                .unwrap_or_else(|| panic!("{k} in {text}"))
        })
        .collect();
        assert!(positions.windows(2).all(|w| w[0] < w[1]), "{text}");
        let (loaded, back) = QNet::load(&dir.path().join("n0.safetensors")).unwrap();
        assert_eq!(back, metadata);
        assert_eq!(loaded.parameters(), net.parameters());
    }

    fn example_metadata() -> BTreeMap<String, String> {
        BTreeMap::from([
            ("env".to_string(), "CartPole-v0".to_string()),
            ("seed".to_string(), "7".to_string()),
        ])
    }

    #[test]
    fn save_then_load_round_trips_every_kind() {
        let dir = tempfile::tempdir().unwrap();
        let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
        let kinds = [
            OutputKind::Plain,
            OutputKind::Bootstrap { heads: 3 },
            OutputKind::Noisy,
        ];
        for (kind, hidden) in kinds
            .into_iter()
            .flat_map(|k| [&[HIDDEN, HIDDEN][..], &[256, 9], &[6], &[5, 7, 3]].map(move |h| (k, h)))
        {
            let mut net = QNet::with_hidden(5, 3, kind, hidden, &mut rng);
            // Make sigma distinct from its constant initial value so a mix-up would show.
            for (i, p) in net.parameters_mut().iter_mut().enumerate() {
                *p += i as f32 * 1e-4;
            }
            let path = dir.path().join(format!("{kind:?}{hidden:?}.safetensors"));
            net.save(&path, &example_metadata()).unwrap();
            // The file holds PyTorch's shapes for these widths, `fc{i}.weight [h_i][h_{i-1}]`, and no more layers.
            let bytes = fs::read(&path).unwrap();
            let file = SafeTensors::deserialize(&bytes).unwrap();
            let inputs = std::iter::once(5).chain(hidden.iter().copied());
            for (i, (&n, n_in)) in hidden.iter().zip(inputs).enumerate() {
                let name = format!("fc{}.weight", i + 1);
                assert_eq!(file.tensor(&name).unwrap().shape(), &[n, n_in], "{name}");
            }
            let beyond = format!("fc{}.weight", hidden.len() + 1);
            assert!(file.tensor(&beyond).is_err());
            let (loaded, metadata) = QNet::load(&path).unwrap();
            assert_eq!(loaded.hidden(), hidden);
            assert_eq!(loaded.kind(), kind);
            assert_eq!(loaded.obs_dim(), 5);
            assert_eq!(loaded.n_actions(), 3);
            assert_eq!(loaded.parameters(), net.parameters());
            assert_eq!(metadata, example_metadata());
            // No temporary file is left behind.
            let leftovers: Vec<_> = fs::read_dir(dir.path())
                .unwrap()
                .filter_map(|e| e.ok())
                .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
                .collect();
            assert!(leftovers.is_empty());
        }
    }

    /// A network (`obs_dim` inputs, 2 actions, `output`, parameters drawn from `seed`) saved without metadata as
    /// `net.safetensors` in a fresh directory: the directory, the network and the file's bytes.
    fn saved_net(
        obs_dim: usize,
        output: OutputKind,
        seed: u64,
    ) -> (tempfile::TempDir, QNet, Vec<u8>) {
        let dir = tempfile::tempdir().unwrap();
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let net = QNet::new(obs_dim, 2, output, &mut rng);
        let path = dir.path().join("net.safetensors");
        net.save(&path, &BTreeMap::new()).unwrap();
        let bytes = fs::read(&path).unwrap();
        (dir, net, bytes)
    }

    /// The file holds PyTorch-layout tensors: check `fc1.weight[o][i]` against the network's own
    /// single-state forward (an independent path through the in-memory layout).
    #[test]
    fn file_tensors_are_in_pytorch_layout() {
        let (_dir, net, bytes) = saved_net(3, OutputKind::Bootstrap { heads: 2 }, 12);
        let file = SafeTensors::deserialize(&bytes).unwrap();
        let read = |name: &str| -> Vec<f32> {
            let view = file.tensor(name).unwrap();
            view.data()
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect()
        };
        let (w1, b1, w2, b2) = (
            read("fc1.weight"),
            read("fc1.bias"),
            read("fc2.weight"),
            read("fc2.bias"),
        );
        assert_eq!(file.tensor("heads.1.weight").unwrap().shape(), &[2, HIDDEN]);
        let obs = [0.3f32, -0.7, 1.1];
        let mut expected = Vec::new();
        for head in 0..2 {
            let (wh, bh) = (
                read(&format!("heads.{head}.weight")),
                read(&format!("heads.{head}.bias")),
            );
            let h1: Vec<f32> = (0..HIDDEN)
                .map(|o| (b1[o] + (0..3).map(|i| w1[o * 3 + i] * obs[i]).sum::<f32>()).max(0.0))
                .collect();
            let h2: Vec<f32> = (0..HIDDEN)
                .map(|o| {
                    (b2[o] + (0..HIDDEN).map(|i| w2[o * HIDDEN + i] * h1[i]).sum::<f32>()).max(0.0)
                })
                .collect();
            for a in 0..2 {
                expected.push(bh[a] + (0..HIDDEN).map(|i| wh[a * HIDDEN + i] * h2[i]).sum::<f32>());
            }
        }
        let mut q = [0.0f32; 4];
        net.q_values_single(&obs, None, &mut q);
        for (x, y) in q.iter().zip(&expected) {
            assert!((x - y).abs() < 1e-5, "{q:?} vs {expected:?}");
        }
    }

    fn load_error(path: &Path) -> ModelFileError {
        QNet::load(path)
            .unwrap_err()
            .downcast::<ModelFileError>()
            .unwrap()
    }

    #[test]
    fn missing_truncated_and_foreign_files_give_clear_errors() {
        let (dir, _, bytes) = saved_net(4, OutputKind::Noisy, 13);

        let missing = dir.path().join("absent.safetensors");
        let error = load_error(&missing);
        assert!(matches!(error, ModelFileError::Read { .. }), "{error}");
        assert!(error.to_string().contains("absent.safetensors"));

        let truncated = dir.path().join("truncated.safetensors");
        fs::write(&truncated, &bytes[..bytes.len() - 10]).unwrap();
        let error = load_error(&truncated);
        assert!(matches!(error, ModelFileError::Corrupt { .. }), "{error}");
        assert!(
            error.to_string().contains("truncated or corrupt"),
            "{error}"
        );

        let text = dir.path().join("notes.txt");
        fs::write(&text, "this is not a model").unwrap();
        assert!(matches!(load_error(&text), ModelFileError::Corrupt { .. }));

        // A valid safetensors file that is not a Q-network: no metadata.
        let foreign = dir.path().join("foreign.safetensors");
        let data = [0u8; 8];
        let view = TensorView::new(Dtype::F32, vec![2], &data).unwrap();
        fs::write(
            &foreign,
            safetensors::serialize([("x", view)], None).unwrap(),
        )
        .unwrap();
        let error = load_error(&foreign);
        assert!(
            matches!(&error, ModelFileError::Metadata { key, .. } if key == "kind"),
            "{error}"
        );
    }

    /// Replaces one tensor's (shape, bytes), or drops it with `None`.
    type TensorChange = dyn Fn(&TensorView) -> Option<(Vec<usize>, Vec<u8>)>;

    /// Rewrites a saved file with one tensor changed (or dropped) and checks the matching error.
    #[test]
    fn inconsistent_tensors_are_rejected() {
        let (dir, _, bytes) = saved_net(4, OutputKind::Bootstrap { heads: 2 }, 14);
        let original = SafeTensors::deserialize(&bytes).unwrap();
        let header = SafeTensors::read_metadata(&bytes)
            .unwrap()
            .1
            .metadata()
            .clone();

        let rewrite = |name: &str, change: &TensorChange| -> ModelFileError {
            let mut owned: Vec<(String, Dtype, Vec<usize>, Vec<u8>)> = Vec::new();
            for (n, view) in original.tensors() {
                if n == name {
                    if let Some((shape, data)) = change(&view) {
                        owned.push((n, view.dtype(), shape, data));
                    }
                } else {
                    owned.push((n, view.dtype(), view.shape().to_vec(), view.data().to_vec()));
                }
            }
            let views: Vec<_> = owned
                .iter()
                .map(|(n, dtype, shape, data)| {
                    (
                        n.clone(),
                        TensorView::new(*dtype, shape.clone(), data).unwrap(),
                    )
                })
                .collect();
            let out = dir.path().join("changed.safetensors");
            fs::write(&out, safetensors::serialize(views, header.clone()).unwrap()).unwrap();
            load_error(&out)
        };

        let error = rewrite("heads.1.bias", &|_| None);
        assert!(
            matches!(&error, ModelFileError::MissingTensor { name, .. } if name == "heads.1.bias"),
            "{error}"
        );

        let error = rewrite("fc1.weight", &|view| {
            Some((vec![4, HIDDEN], view.data().to_vec()))
        });
        assert!(
            matches!(&error, ModelFileError::Shape { name, .. } if name == "fc1.weight"),
            "{error}"
        );

        let error = rewrite("fc2.bias", &|view| {
            let mut data = view.data().to_vec();
            data[..4].copy_from_slice(&f32::NAN.to_le_bytes());
            Some((view.shape().to_vec(), data))
        });
        assert!(
            matches!(&error, ModelFileError::NonFinite { .. }),
            "{error}"
        );
    }

    /// A file with more trunk layers than a network may have is refused by name, before any shape check.
    #[test]
    fn a_file_deeper_than_the_deepest_network_is_refused() {
        let (dir, _, bytes) = saved_net(2, OutputKind::Plain, 16);
        let original = SafeTensors::deserialize(&bytes).unwrap();
        let header = SafeTensors::read_metadata(&bytes)
            .unwrap()
            .1
            .metadata()
            .clone();
        let square = vec![0u8; HIDDEN * HIDDEN * 4];
        let mut views: Vec<(String, TensorView)> = original.tensors();
        for layer in 3..=MAX_DEPTH + 1 {
            let view = TensorView::new(Dtype::F32, vec![HIDDEN, HIDDEN], &square).unwrap();
            views.push((format!("fc{layer}.weight"), view));
        }
        let path = dir.path().join("deep.safetensors");
        fs::write(&path, safetensors::serialize(views, header).unwrap()).unwrap();
        let error = load_error(&path);
        assert!(
            matches!(error, ModelFileError::TooDeep { depth, .. } if depth == MAX_DEPTH + 1),
            "{error}"
        );
        assert!(
            error.to_string().contains("more than the 8 supported"),
            "{error}"
        );
    }

    #[test]
    fn reserved_metadata_keys_are_refused_on_save() {
        let dir = tempfile::tempdir().unwrap();
        let mut rng = rand_pcg::Pcg64::seed_from_u64(15);
        let net = QNet::new(2, 2, OutputKind::Plain, &mut rng);
        let metadata = BTreeMap::from([("kind".to_string(), "mine".to_string())]);
        let error = net
            .save(&dir.path().join("x.safetensors"), &metadata)
            .unwrap_err();
        assert!(matches!(
            error.downcast_ref::<ModelFileError>(),
            Some(ModelFileError::ReservedKey { .. })
        ));
    }

    #[test]
    fn declared_sizes_beyond_the_file_are_refused_before_allocating() {
        let dir = tempfile::tempdir().unwrap();
        let mut rng = rand_pcg::Pcg64::seed_from_u64(15);
        let path = dir.path().join("x.safetensors");
        QNet::new(2, 2, OutputKind::Plain, &mut rng)
            .save(&path, &BTreeMap::new())
            .unwrap();
        let bytes = fs::read(&path).unwrap();
        let header_len = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
        let text = std::str::from_utf8(&bytes[8..8 + header_len]).unwrap();
        for (from, to) in [
            ("\"n_actions\":\"2\"", "\"n_actions\":\"60000\""),
            ("\"obs_dim\":\"2\"", "\"obs_dim\":\"99999999999\""),
            ("\"heads\":\"1\"", "\"heads\":\"18446744073709551615\""),
        ] {
            assert!(text.contains(from), "{text}");
            let mut header = text.replace(from, to);
            let pad = (8 - header.len() % 8) % 8;
            header.push_str(&" ".repeat(pad));
            let mut out = (header.len() as u64).to_le_bytes().to_vec();
            out.extend_from_slice(header.as_bytes());
            out.extend_from_slice(&bytes[8 + header_len..]);
            let error = parse_model(&path, &out).unwrap_err();
            assert!(matches!(error, ModelFileError::Metadata { .. }), "{error}");
        }
        assert!(matches!(
            load_file(dir.path()).unwrap_err(),
            ModelFileError::Read { .. }
        ));
    }
}
