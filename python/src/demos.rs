//! Demonstrations given in Python as rows, turned into the library's.

use crate::actions::{DemoActions, PyAction};
use arld_core::expert::demos::{DemoColumns, Demonstrations};
use arld_core::train::TrainConfig;
use pyo3::prelude::*;

/// Demonstrations given as rows: (obs, action, reward, next_obs, terminated) per transition, in episode order.
#[derive(FromPyObject)]
pub(crate) struct DemoArrays {
    pub(crate) obs: Vec<Vec<f32>>,
    pub(crate) actions: DemoActions,
    pub(crate) rewards: Vec<f32>,
    pub(crate) next_obs: Vec<Vec<f32>>,
    pub(crate) terminated: Vec<bool>,
    pub(crate) truncated: Vec<bool>,
}

impl DemoArrays {
    /// The library's [`DemoColumns`] of actions of the kind `A`, checked and read into demonstrations there.
    pub(crate) fn into_demonstrations<A: PyAction>(
        self,
        cfg: &TrainConfig,
    ) -> anyhow::Result<Demonstrations<A>> {
        let columns = DemoColumns {
            obs: self.obs,
            actions: A::demo_actions(self.actions)?,
            rewards: self.rewards,
            next_obs: self.next_obs,
            terminated: self.terminated,
            truncated: self.truncated,
        };
        Demonstrations::from_columns(&cfg.env, columns)
    }
}
