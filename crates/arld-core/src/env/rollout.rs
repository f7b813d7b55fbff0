//! Playing whole episodes with a policy: the one loop behind the training run's test evaluations and the
//! expert statistics. A policy is any function from an observation to an action; one that may fail (an
//! expert) returns its error, which ends the rollout.

use super::{Action, Env, EnvError};

/// One finished episode.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Episode {
    /// Sum of the rewards.
    pub ret: f64,
    /// Steps taken.
    pub length: usize,
    /// The task ended (rather than the time limit).
    pub terminated: bool,
}

/// Plays `episodes` episodes of `policy` on `env` (of either kind of action); episode `i` starts with
/// `reset(seed(i))`.
pub fn rollouts<A: Action, E: From<EnvError>>(
    env: &mut dyn Env<A>,
    episodes: usize,
    seed: impl Fn(usize) -> Option<u64>,
    mut policy: impl FnMut(&[f32]) -> Result<A, E>,
) -> Result<Vec<Episode>, E> {
    // Capacity is only a hint: a huge `episodes` must not abort on allocation before the first episode.
    let mut out = Vec::with_capacity(episodes.min(1 << 16));
    let mut obs = vec![0.0; env.obs_dim()];
    for i in 0..episodes {
        env.reset_into(seed(i), &mut obs);
        let mut episode = Episode {
            ret: 0.0,
            length: 0,
            terminated: false,
        };
        loop {
            let action = policy(&obs)?;
            let s = env.step_into(action.borrow(), &mut obs)?;
            episode.ret += s.reward;
            episode.length += 1;
            if s.terminated || s.truncated {
                episode.terminated = s.terminated;
                break;
            }
        }
        out.push(episode);
    }
    Ok(out)
}

/// Mean, standard deviation (population), minimum and maximum of the episodes' returns; NaN for none.
pub fn return_stats(episodes: &[Episode]) -> (f64, f64, f64, f64) {
    let returns: Vec<f64> = episodes.iter().map(|e| e.ret).collect();
    mean_std_min_max(&returns)
}

/// Mean, standard deviation (population), minimum and maximum; NaN mean and std for no values.
pub fn mean_std_min_max(values: &[f64]) -> (f64, f64, f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let std = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
    let min = values.iter().cloned().fold(f64::INFINITY, f64::min);
    let max = values.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    (mean, std, min, max)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// CartPole pushed always left falls within a few steps; the episode's return is its length (reward 1 per
    /// step), and the statistics match a direct computation.
    #[test]
    fn rollouts_play_whole_episodes_from_the_given_seeds() {
        let mut env = crate::env::make("CartPole-v0").unwrap();
        let episodes = rollouts(
            env.as_mut(),
            3,
            |i| Some(i as u64),
            |_| Ok::<_, EnvError>(0),
        )
        .unwrap();
        for e in &episodes {
            assert!(
                e.terminated && e.length < 20 && e.ret == e.length as f64,
                "{e:?}"
            );
        }
        let again = rollouts(
            env.as_mut(),
            3,
            |i| Some(i as u64),
            |_| Ok::<_, EnvError>(0),
        )
        .unwrap();
        assert_eq!(episodes, again, "same seeds, same episodes");
        let r: Vec<f64> = episodes.iter().map(|e| e.ret).collect();
        let mean = (r[0] + r[1] + r[2]) / 3.0;
        let std = (r.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / 3.0).sqrt();
        let (m, s, lo, hi) = return_stats(&episodes);
        assert_eq!((m, s), (mean, std));
        assert_eq!(
            (lo, hi),
            (
                r.iter().cloned().fold(f64::MAX, f64::min),
                r.iter().cloned().fold(f64::MIN, f64::max)
            )
        );
        // A failing policy ends the rollout with its error.
        let err = rollouts(
            env.as_mut(),
            1,
            |_| None,
            |_| Err(EnvError::UnknownId { id: "x".into() }),
        );
        assert!(err.is_err());
    }
}
