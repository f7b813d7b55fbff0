//! Experts of actions in a box (the continuous tasks): built from the same specs as the discrete experts, where
//! the kind makes sense for a box.
//!
//! - `scripted`: the task's controller ([`super::scripted::ScriptedBoxExpert`]).
//! - `shipped:weak`, `shipped:perfect`: the actors the expert pipeline selected for the task (`arld expert train`,
//!   in `experts/<env>/`, compiled into the library: [`super::shipped`]).
//! - `checkpoint:PATH`: a trained actor, as a run saves it (`weights.safetensors` or a checkpoint of a TD3 or SAC
//!   run: [`crate::agent::box_agent::BoxAgent`]'s weights file), acting without exploration.
//! - `noisy:S:SPEC`: the expert `SPEC` with Gaussian noise of standard deviation `S` half-widths of the box on
//!   every action, clipped to the box (for a discrete task `noisy:P:SPEC` is a random action with probability
//!   `P`; a box has no single "random action" a weaker expert would take, so the weakening is noise).
//!
//! - `cmd:COMMAND`: a program answering with lists of numbers ([`super::process`]).
//!
//! - `web[:OPTIONS]`: a person on the page, where the program has the web expert ([`from_spec_with`], given
//!   its start: the `arld-web` crate); elsewhere refused with a reason.

use super::scripted::ScriptedBoxExpert;
use super::{Expert, ExpertSpec};
use crate::agent::actor_critic::ActionBox;
use crate::agent::actor_file::TrainedActor;
use crate::env::BoxSpec;
use anyhow::{Context, Result, bail, ensure};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64;
use std::path::Path;

/// The expert `spec` for the box task `spec`, its random draws (noise) from `seed`; an expert process may take
/// `timeout_s` seconds per answer.
pub fn from_spec(
    expert: &str,
    spec: &'static BoxSpec,
    seed: u64,
    timeout_s: f64,
) -> Result<Box<dyn Expert<Vec<f32>>>> {
    let no_web: BoxWebStart = |_, _| {
        bail!("this program was built without the web expert (the arld-web crate builds it)")
    };
    from_spec_with(expert, spec, seed, timeout_s, no_web)
}

/// Starts the web expert with its options for the box task `env_id` (`arld_web::start_box`): the crate above
/// this one builds it.
pub type BoxWebStart =
    fn(&super::web_options::WebOptions, &str) -> Result<Box<dyn Expert<Vec<f32>>>>;

/// [`from_spec`], every kind including the web expert, which `web` starts.
pub fn from_spec_with(
    expert: &str,
    spec: &'static BoxSpec,
    seed: u64,
    timeout_s: f64,
    web: BoxWebStart,
) -> Result<Box<dyn Expert<Vec<f32>>>> {
    build(&expert.parse()?, spec, seed, timeout_s, web)
}

fn build(
    parsed: &ExpertSpec,
    spec: &'static BoxSpec,
    seed: u64,
    timeout_s: f64,
    web: BoxWebStart,
) -> Result<Box<dyn Expert<Vec<f32>>>> {
    Ok(match parsed {
        ExpertSpec::Web(options) => web(options, spec.id)?,
        ExpertSpec::Scripted => Box::new(ScriptedBoxExpert::new(spec.id)?),
        ExpertSpec::Checkpoint(path) => Box::new(ActorExpert::load(path, spec)?),
        ExpertSpec::Shipped(quality) => Box::new(ActorExpert::shipped(quality, spec)?),
        ExpertSpec::Command(command) => Box::new(super::process::ProcessExpert::<Vec<f32>>::spawn(
            command, spec, timeout_s,
        )?),
        ExpertSpec::Noisy { p, inner } => {
            let inner = build(inner, spec, seed, timeout_s, web)?;
            Box::new(GaussianNoise::new(inner, *p as f32, spec, seed)?)
        }
        ExpertSpec::Python(_) => bail!(super::PYTHON_ONLY),
    })
}

/// A trained actor acting without exploration ([`TrainedActor`]).
pub struct ActorExpert {
    /// What the expert is called in records: `checkpoint:PATH`, or `shipped:QUALITY`.
    name: String,
    actor: TrainedActor,
}

impl ActorExpert {
    /// Reads the actor saved at `path` for the task `spec`: the file must be an actor's weights file
    /// ([`crate::agent::actor_file`]) of a run of the same task (observation size, box).
    pub fn load(path: &Path, spec: &BoxSpec) -> Result<Self> {
        let (actor, _) = TrainedActor::load(path).context("cannot load the expert")?;
        Self::new(actor, format!("checkpoint:{}", path.display()), spec)
    }

    /// The shipped actor `quality` of the task `spec` ([`super::shipped::model`]), named `shipped:QUALITY`.
    pub fn shipped(quality: &str, spec: &BoxSpec) -> Result<Self> {
        let bytes = super::shipped::model(spec.id, quality)
            .with_context(|| super::no_shipped(quality, spec.id))?;
        let name = format!("shipped:{quality}");
        let (actor, _) =
            TrainedActor::from_bytes(bytes, &name).context("cannot load the expert")?;
        Self::new(actor, name, spec)
    }

    fn new(actor: TrainedActor, name: String, spec: &BoxSpec) -> Result<Self> {
        let (low, high) = actor.bounds();
        let file = name.trim_start_matches("checkpoint:");
        ensure!(
            low == spec.action_low && high == spec.action_high,
            "the expert's actor {file} acts in the box {low:?} to {high:?}, but {} has {:?} to {:?}",
            spec.id,
            spec.action_low,
            spec.action_high
        );
        ensure!(
            actor.obs_dim() == spec.obs_dim,
            "the expert's actor {file} takes {} inputs, but {} has {} observation values",
            actor.obs_dim(),
            spec.id,
            spec.obs_dim
        );
        Ok(ActorExpert { name, actor })
    }
}

impl Expert<Vec<f32>> for ActorExpert {
    fn act(&mut self, obs: &[f32]) -> Result<Vec<f32>> {
        Ok(self.actor.act(obs))
    }

    fn describe(&self) -> String {
        self.name.clone()
    }
}

/// An expert whose every action gets Gaussian noise of standard deviation `sigma` half-widths of the box,
/// clipped to the box.
pub struct GaussianNoise {
    inner: Box<dyn Expert<Vec<f32>>>,
    sigma: f32,
    action_box: ActionBox,
    rng: Pcg64,
}

impl GaussianNoise {
    /// `inner` with noise `sigma` (in half-widths, at least 0 and finite), drawn from `seed`.
    pub fn new(
        inner: Box<dyn Expert<Vec<f32>>>,
        sigma: f32,
        spec: &BoxSpec,
        seed: u64,
    ) -> Result<Self> {
        ensure!(
            sigma.is_finite() && sigma >= 0.0,
            "the noise of a noisy expert must be a finite number of half-widths, at least 0, got {sigma}"
        );
        Ok(GaussianNoise {
            inner,
            sigma,
            action_box: ActionBox::new(spec.action_low, spec.action_high),
            rng: Pcg64::seed_from_u64(seed),
        })
    }
}

impl Expert<Vec<f32>> for GaussianNoise {
    fn act(&mut self, obs: &[f32]) -> Result<Vec<f32>> {
        let mut action = self.inner.act(obs)?;
        let unit = Normal::new(0.0f32, 1.0).expect("a unit normal");
        for (d, a) in action.iter_mut().enumerate() {
            let noisy = *a + self.sigma * self.action_box.half[d] * unit.sample(&mut self.rng);
            *a = noisy.clamp(self.action_box.low[d], self.action_box.high[d]);
        }
        Ok(action)
    }

    fn describe(&self) -> String {
        format!("noisy({}, {})", self.sigma, self.inner.describe())
    }

    fn state(&self) -> Option<String> {
        Some(serde_json::to_string(&self.rng).expect("the generator serialises"))
    }

    fn restore(&mut self, state: &str) -> Result<()> {
        self.rng =
            serde_json::from_str(state).context("the noisy expert's state in the snapshot")?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::agent::Learner;
    use crate::agent::algo::BoxLearnerConfig;
    use crate::agent::box_agent::BoxAgent;
    use crate::agent::sac::SacConfig;
    use crate::agent::td3::Td3Config;
    use crate::env::box_spec;
    use crate::task::{ActionColumn, BoxColumn};

    /// An actor saved by a run answers as the run's own test-time policy, bit for bit, for TD3 and SAC.
    #[test]
    fn a_saved_actor_answers_as_the_agent_that_saved_it() {
        let spec = box_spec("LunarLanderContinuous-v3").unwrap();
        let (low, high) = (spec.action_low, spec.action_high);
        let hidden = vec![16, 8];
        let (mut td3, mut sac) = (Td3Config::default(), SacConfig::default());
        td3.common.hidden = hidden.clone();
        sac.common.hidden = hidden;
        let configs = [BoxLearnerConfig::Td3(td3), BoxLearnerConfig::Sac(sac)];
        let dir = tempfile::tempdir().unwrap();
        for (i, config) in configs.into_iter().enumerate() {
            let mut agent = BoxAgent::new(config, 8, low, high, 0.99, 1 + i as u64);
            let path = dir.path().join(format!("actor{i}.safetensors"));
            agent.save_weights(&path, &Default::default()).unwrap();
            let mut expert =
                from_spec(&format!("checkpoint:{}", path.display()), spec, 0, 30.0).unwrap();
            let obs: Vec<f32> = (0..8).map(|k| (k as f32 * 0.37 + i as f32).sin()).collect();
            let mut column = BoxColumn::default();
            agent.test_actions(&obs, &mut column);
            assert_eq!(
                expert.act(&obs).unwrap(),
                column.get(0).to_vec(),
                "agent {i}"
            );
        }
        // Another task's box or a file that is no actor is refused, naming the problem.
        let path = dir.path().join("actor0.safetensors");
        let err = ActorExpert::load(&path, box_spec("Pendulum-v1").unwrap())
            .err()
            .unwrap();
        assert!(format!("{err:#}").contains("box"), "{err:#}");
        std::fs::write(&path, b"not a file of weights").unwrap();
        let err = ActorExpert::load(&path, spec).err().unwrap();
        assert!(format!("{err:#}").contains("safetensors"), "{err:#}");
    }

    /// The noise's spread is the asked number of half-widths (measured over many draws), and it stays in the
    /// box.
    #[test]
    fn noisy_box_experts_spread_as_asked_and_stay_in_the_box() {
        let spec = box_spec("Pendulum-v1").unwrap();
        let mut expert = from_spec("noisy:0.1:scripted", spec, 5, 30.0).unwrap();
        let obs = [1.0f32, 0.0, 0.0];
        let clean = crate::env::pendulum::swing_up(&obs)[0];
        let draws: Vec<f32> = (0..20_000).map(|_| expert.act(&obs).unwrap()[0]).collect();
        assert!(draws.iter().all(|a| (-2.0..=2.0).contains(a)));
        let n = draws.len() as f32;
        let mean = draws.iter().sum::<f32>() / n;
        let sd = (draws.iter().map(|a| (a - mean).powi(2)).sum::<f32>() / n).sqrt();
        assert!((mean - clean).abs() < 0.01, "mean {mean}, clean {clean}");
        assert!((sd - 0.2).abs() < 0.01, "sd {sd} for 0.1 half-widths of 2");
    }

    /// The shipped actors of every box task load as experts and act in their task's box.
    #[test]
    fn shipped_box_experts_act_in_the_box() {
        for id in [
            "Pendulum-v1",
            "MountainCarContinuous-v0",
            "LunarLanderContinuous-v3",
        ] {
            let spec = box_spec(id).unwrap();
            for quality in ["shipped:weak", "shipped:perfect"] {
                let mut expert = from_spec(quality, spec, 0, 30.0).unwrap();
                let action = expert.act(&vec![0.1; spec.obs_dim]).unwrap();
                assert_eq!(action.len(), spec.action_dim());
                for (a, (lo, hi)) in action
                    .iter()
                    .zip(spec.action_low.iter().zip(spec.action_high))
                {
                    assert!((*lo..=*hi).contains(a), "{id} {quality}: {action:?}");
                }
            }
        }
    }
}
