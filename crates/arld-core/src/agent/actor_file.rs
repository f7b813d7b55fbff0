//! The weights file of an actor-critic run's actor (`weights.safetensors` and the checkpoints of a TD3 or SAC
//! run, the shipped experts of the box tasks, Python's `BoxPolicy.save`): its one writer ([`write`]) and its one
//! reader ([`TrainedActor::load`]), and the actor acting with its test policy.
//!
//! Format: safetensors with one tensor `actor.params` (float32, the actor's [`Mlp`] parameters in their flat
//! layout: layer by layer, weight `[in][out]` then bias) and the header fields `kind` (`td3-actor` or
//! `sac-actor`), `sizes` (the layer widths, input first, comma-separated) and `action_low`/`action_high` (the box,
//! comma-separated), beside the caller's own metadata (a run's id and step).

use super::actor_critic::ActionBox;
use super::algo::Algo;
use crate::nn::{Mlp, MlpWorkspace};
use anyhow::{Context, Result, bail, ensure};
use rand::SeedableRng;
use rand_pcg::Pcg64;
use safetensors::{Dtype, tensor::TensorView};
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// The largest actor file read (an actor of 4096-wide layers is far below it).
const MAX_ACTOR_FILE_BYTES: u64 = 1 << 30;

/// The header fields the format owns; the rest is the caller's metadata.
const OWN_FIELDS: [&str; 4] = ["kind", "sizes", "action_low", "action_high"];

/// The header's `kind` of an actor of `algo`: `td3-actor`, `sac-actor`.
fn kind_field(algo: Algo) -> String {
    format!("{}-actor", algo.name())
}

/// The learner whose actor a header's `kind` names, if any.
fn algo_of_kind(kind: &str) -> Option<Algo> {
    Algo::ALL.into_iter().find(|&algo| kind_field(algo) == kind)
}

/// Outputs of `algo`'s actor for `action_dim` dimensions.
fn outputs(algo: Algo, action_dim: usize) -> usize {
    algo.actor().0 * action_dim
}

/// Writes `actor` (of the learner `algo`, acting in `[low, high]`) to `path` atomically, with `metadata`; the same
/// actor and metadata give the same bytes.
pub fn write(
    path: &Path,
    algo: Algo,
    actor: &Mlp,
    low: &[f32],
    high: &[f32],
    metadata: &BTreeMap<String, String>,
) -> Result<()> {
    let bytes: Vec<u8> = actor
        .parameters()
        .iter()
        .flat_map(|p| p.to_le_bytes())
        .collect();
    let view = TensorView::new(Dtype::F32, vec![actor.parameters().len()], &bytes)?;
    let mut header: HashMap<String, String> = metadata
        .iter()
        .filter(|(key, _)| !OWN_FIELDS.contains(&key.as_str()))
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect();
    let list = |v: &[f32]| v.iter().map(f32::to_string).collect::<Vec<_>>().join(",");
    let sizes = actor
        .sizes()
        .iter()
        .map(usize::to_string)
        .collect::<Vec<_>>();
    header.insert("kind".into(), kind_field(algo));
    header.insert("sizes".into(), sizes.join(","));
    header.insert("action_low".into(), list(low));
    header.insert("action_high".into(), list(high));
    // Sorted header keys: the same actor gives the same bytes in every process.
    let file = crate::nn::with_sorted_metadata(safetensors::serialize(
        [("actor.params", view)],
        Some(header),
    )?)?;
    crate::files::write_atomic(path, &file)?;
    Ok(())
}

/// Whether the safetensors file at `path` is an actor's weights file (its header's `kind` is `td3-actor` or
/// `sac-actor`), read without its tensors; an error when it is not a safetensors file.
pub fn holds_an_actor(path: &Path) -> Result<bool> {
    use std::io::Read;
    let (mut file, _) = crate::files::open_bounded(path, MAX_ACTOR_FILE_BYTES)?;
    let mut length = [0u8; 8];
    file.read_exact(&mut length)
        .context("it is too short for a safetensors file")?;
    let length = u64::from_le_bytes(length);
    ensure!(
        length <= 100_000_000,
        "its header claims {length} bytes: not a safetensors file"
    );
    let mut header = vec![0u8; length as usize];
    file.read_exact(&mut header)
        .context("its header is cut short: not a whole safetensors file")?;
    let header: serde_json::Value = serde_json::from_slice(&header)
        .context("its header is not JSON: not a safetensors file")?;
    let kind = header["__metadata__"]["kind"].as_str().unwrap_or("");
    Ok(algo_of_kind(kind).is_some())
}

/// A trained actor acting with its test policy (no exploration): TD3's action, or SAC's `tanh` of its means,
/// mapped into the box, as the run's test episodes act.
#[derive(Clone, Debug)]
pub struct TrainedActor {
    algo: Algo,
    net: Mlp,
    ws: MlpWorkspace,
    action_box: ActionBox,
}

impl TrainedActor {
    /// The actor `net` of the learner `algo`, acting in `[low, high]`.
    ///
    /// # Panics
    /// If the box is empty or inverted, or the network's widths do not fit it (the callers hold a learner's own
    /// actor or a file [`Self::load`] checked).
    pub fn new(algo: Algo, net: Mlp, low: &[f32], high: &[f32]) -> Self {
        assert_eq!(net.output_dim(), outputs(algo, low.len()));
        TrainedActor {
            algo,
            ws: MlpWorkspace::new(&net, 1),
            net,
            action_box: ActionBox::new(low, high),
        }
    }

    /// Reads the actor at `path` (whole, finite, within the format) and the caller's metadata it was saved with.
    pub fn load(path: &Path) -> Result<(Self, BTreeMap<String, String>)> {
        let bytes = crate::files::read_bounded(path, MAX_ACTOR_FILE_BYTES)
            .with_context(|| format!("cannot read the actor {}", path.display()))?;
        Self::from_bytes(&bytes, &path.display().to_string())
    }

    /// Reads an actor from the bytes of its file, checked as [`TrainedActor::load`] checks a file (`name` names
    /// it in errors).
    pub(crate) fn from_bytes(bytes: &[u8], name: &str) -> Result<(Self, BTreeMap<String, String>)> {
        let what = || format!("the actor {name}");
        let (_, header) = safetensors::SafeTensors::read_metadata(bytes)
            .with_context(|| format!("{} is not a safetensors file", what()))?;
        let meta = header.metadata().clone().unwrap_or_default();
        let field = |key: &str| {
            meta.get(key).with_context(|| {
                format!(
                    "{} has no `{key}` in its header: it is not an actor's weights file",
                    what()
                )
            })
        };
        let kind = field("kind")?;
        let Some(algo) = algo_of_kind(kind) else {
            bail!("{} holds a `{kind}`, not a TD3 or SAC actor", what());
        };
        let sizes = field("sizes")?
            .split(',')
            .map(|w| {
                w.trim()
                    .parse::<usize>()
                    .ok()
                    .filter(|&w| (1..=1 << 16).contains(&w))
            })
            .collect::<Option<Vec<usize>>>()
            .filter(|s| s.len() >= 2)
            .with_context(|| format!("{}: bad layer sizes `{}`", what(), meta["sizes"]))?;
        let floats = |key: &str| -> Result<Vec<f32>> {
            field(key)?
                .split(',')
                .map(|v| {
                    v.trim()
                        .parse::<f32>()
                        .with_context(|| format!("{}: bad `{key}`", what()))
                })
                .collect()
        };
        let (low, high) = (floats("action_low")?, floats("action_high")?);
        ensure!(
            !low.is_empty()
                && low.len() == high.len()
                && low
                    .iter()
                    .zip(&high)
                    .all(|(l, h)| l.is_finite() && h.is_finite() && l < h),
            "{}: the box {low:?} to {high:?} is not a box (finite bounds, low below high in every dimension)",
            what()
        );
        let outputs = outputs(algo, low.len());
        ensure!(
            sizes[sizes.len() - 1] == outputs,
            "{} has {} outputs, but a {} actor in a box of {} dimensions has {outputs}",
            what(),
            sizes[sizes.len() - 1],
            algo.name(),
            low.len()
        );
        let tensors = safetensors::SafeTensors::deserialize(bytes)
            .with_context(|| format!("{} is not a whole safetensors file", what()))?;
        let params = tensors
            .tensor("actor.params")
            .with_context(|| format!("{} has no tensor `actor.params`", what()))?;
        let mut net = Mlp::new(&sizes, algo.actor().1, &mut Pcg64::seed_from_u64(0));
        ensure!(
            params.dtype() == Dtype::F32 && params.data().len() == 4 * net.parameters().len(),
            "{}: `actor.params` holds {} bytes, but layers {sizes:?} need {} float32 numbers",
            what(),
            params.data().len(),
            net.parameters().len()
        );
        for (p, b) in net
            .parameters_mut()
            .iter_mut()
            .zip(params.data().chunks_exact(4))
        {
            *p = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        }
        ensure!(
            net.parameters().iter().all(|p| p.is_finite()),
            "{} holds a weight that is not a finite number",
            what()
        );
        let metadata = meta
            .into_iter()
            .filter(|(key, _)| !OWN_FIELDS.contains(&key.as_str()))
            .collect();
        Ok((TrainedActor::new(algo, net, &low, &high), metadata))
    }

    /// Writes the actor to `path` ([`write`]) with `metadata`.
    pub fn save(&self, path: &Path, metadata: &BTreeMap<String, String>) -> Result<()> {
        let b = &self.action_box;
        write(path, self.algo, &self.net, &b.low, &b.high, metadata)
    }

    /// The test policy's action at `obs` (which has [`Self::obs_dim`] numbers).
    ///
    /// # Panics
    /// If `obs` has another length.
    pub fn act(&mut self, obs: &[f32]) -> Vec<f32> {
        let a = self.action_box.dim();
        let out = self.net.forward(obs, 1, &mut self.ws);
        let mut action = vec![0.0; a];
        self.algo.test_units(out, a, &mut action);
        self.action_box.to_box(&mut action);
        action
    }

    /// The learner whose actor this is.
    pub fn algo(&self) -> Algo {
        self.algo
    }

    pub fn obs_dim(&self) -> usize {
        self.net.input_dim()
    }

    pub fn action_dim(&self) -> usize {
        self.action_box.dim()
    }

    /// The box, `(low, high)`.
    pub fn bounds(&self) -> (&[f32], &[f32]) {
        (&self.action_box.low, &self.action_box.high)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::OutputActivation;

    /// A file written by [`write`] reads back as the same actor: the same actions at random observations, the
    /// caller's metadata without the format's own fields, the same bytes when written again (the header's keys
    /// reach safetensors in a hash map's order, which differs from map to map).
    #[test]
    fn an_actor_file_reads_back_as_the_same_actor() {
        let dir = tempfile::tempdir().unwrap();
        let mut rng = Pcg64::seed_from_u64(3);
        for (kind, output, dim) in [
            (Algo::Td3, OutputActivation::Tanh, 2),
            (Algo::Sac, OutputActivation::Linear, 1),
        ] {
            let net = Mlp::new(&[3, 7, 5, outputs(kind, dim)], output, &mut rng);
            let (low, high) = (vec![-2.0; dim], vec![1.5; dim]);
            let meta = BTreeMap::from([
                ("run".to_string(), "x".to_string()),
                ("kind".to_string(), "ignored".to_string()),
            ]);
            let path = dir.path().join(format!("{kind:?}.safetensors"));
            write(&path, kind, &net, &low, &high, &meta).unwrap();
            let (mut read, read_meta) = TrainedActor::load(&path).unwrap();
            let mut original = TrainedActor::new(kind, net, &low, &high);
            assert_eq!(read_meta, BTreeMap::from([("run".into(), "x".into())]));
            assert_eq!(read.algo(), kind);
            for i in 0..20 {
                let obs = [i as f32 * 0.3 - 3.0, 1.0 / (i as f32 + 1.0), -0.5];
                let (a, b) = (read.act(&obs), original.act(&obs));
                assert_eq!(a, b);
                assert!(a.iter().all(|v| (-2.0..=1.5).contains(v)), "{a:?}");
            }
            let again = dir.path().join("again.safetensors");
            read.save(&again, &read_meta).unwrap();
            assert_eq!(
                std::fs::read(&again).unwrap(),
                std::fs::read(&path).unwrap()
            );
        }
    }

    /// Damaged files are refused with what is wrong: not safetensors, no kind, a box that is not one, too few
    /// numbers, a weight that is not finite.
    #[test]
    fn damaged_actor_files_are_refused_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.safetensors");
        let net = Mlp::new(
            &[2, 4, 1],
            OutputActivation::Tanh,
            &mut Pcg64::seed_from_u64(0),
        );
        let refused = |bytes: &[u8], says: &str| {
            std::fs::write(&path, bytes).unwrap();
            let err = format!("{:#}", TrainedActor::load(&path).unwrap_err());
            assert!(err.contains(says), "{err}");
        };
        refused(b"not weights", "not a safetensors file");
        let file = |params: &[f32], header: &[(&str, &str)]| {
            let bytes: Vec<u8> = params.iter().flat_map(|p| p.to_le_bytes()).collect();
            let view = TensorView::new(Dtype::F32, vec![params.len()], &bytes).unwrap();
            let header: HashMap<String, String> = header
                .iter()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect();
            safetensors::serialize([("actor.params", view)], Some(header)).unwrap()
        };
        let good = [
            ("kind", "td3-actor"),
            ("sizes", "2,4,1"),
            ("action_low", "-1"),
            ("action_high", "1"),
        ];
        let params = net.parameters().to_vec();
        refused(&file(&params, &good[1..]), "no `kind`");
        let mut flat = good;
        flat[3] = ("action_high", "-1");
        refused(&file(&params, &flat), "not a box");
        refused(&file(&params[1..], &good), "need 17 float32 numbers");
        let mut bad = params.clone();
        bad[4] = f32::NAN;
        refused(&file(&bad, &good), "not a finite number");
        std::fs::write(&path, file(&params, &good)).unwrap();
        assert!(TrainedActor::load(&path).is_ok());
        assert!(holds_an_actor(&path).unwrap());
        let q = dir.path().join("q.safetensors");
        crate::nn::QNet::new(
            2,
            3,
            crate::nn::OutputKind::Plain,
            &mut Pcg64::seed_from_u64(0),
        )
        .save(&q, &BTreeMap::new())
        .unwrap();
        assert!(!holds_an_actor(&q).unwrap());
        std::fs::write(&path, b"short").unwrap();
        assert!(holds_an_actor(&path).is_err());
    }
}
