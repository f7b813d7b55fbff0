//! The paper's experimental protocol (Section 4: the method comparison, the t_query study and the
//! expert-quality study) as sweep grids, so one command can reproduce it ([`paper_grids`]); and the order in
//! which reports list environments. The paper's numbers themselves are in [`crate::paper`].

use super::sweep::SweepGrid;
use crate::paper::{TABLE5_METHODS, TABLE5_NETS, task_index};
use crate::train::{Method, NetKind};

/// Environments in table order: the paper's tasks first in its column order, then any others alphabetically.
pub fn env_order<'a>(envs: impl IntoIterator<Item = &'a str>) -> Vec<String> {
    let mut list: Vec<&str> = envs.into_iter().collect();
    list.sort_by_key(|env| (task_index(env).unwrap_or(usize::MAX), env.to_string()));
    list.dedup();
    list.into_iter().map(str::to_string).collect()
}

/// The t_query values of the paper's threshold study (Section 4, "Effect of Query Proportion Threshold").
pub const T_QUERY_VALUES: [f64; 4] = [0.05, 0.1, 0.3, 0.5];

/// The experts of the paper's expert-quality study on Lunar Lander, as expert specs: the converged expert,
/// the converged expert taking a random action with probability 0.4, and the snapshot ("weak") expert.
pub const EXPERT_QUALITY_SPECS: [&str; 3] = [
    "shipped:perfect",
    "noisy:0.4:shipped:perfect",
    "shipped:weak",
];

/// Methods of the expert-quality study.
pub const EXPERT_QUALITY_METHODS: [&str; 2] = ["adqn", "dqfd"];

/// Number of seeds the paper used per configuration.
pub const PAPER_SEEDS: u64 = 20;

/// The paper's experiments as sweeps, each with the name of the sub-directory it should run in:
/// - `methods`: the four tasks x six methods x bootstrapped and noisy nets (Table 5; Figures 1 and 2);
/// - `t_query`: ADQN on the four tasks x both nets x t_query in {0.05, 0.1, 0.3, 0.5} (Figure 3);
/// - `experts`: ADQN and DQfD on Lunar Lander x both nets x three experts (Figure 4).
///
/// Every other setting is left to the per-task presets of the training code.
pub fn paper_grids(seeds: u64) -> Vec<(&'static str, SweepGrid)> {
    let all_tasks: Vec<String> = crate::paper::PAPER_TASKS
        .iter()
        .map(|t| t.gym_id.to_string())
        .collect();
    // The tables name methods and networks as configs do; every name parses (a test builds the grids).
    let method = |m: &str| m.parse::<Method>().expect("a method name");
    let nets: Vec<NetKind> = TABLE5_NETS
        .iter()
        .map(|(n, _)| n.parse().expect("a network name"))
        .collect();
    let seed_list: Vec<u64> = (0..seeds).collect();
    let methods = SweepGrid {
        envs: all_tasks.clone(),
        methods: TABLE5_METHODS.iter().map(|m| method(m)).collect(),
        nets: nets.clone(),
        seeds: seed_list.clone(),
        ..SweepGrid::default()
    };
    let t_query = SweepGrid {
        envs: all_tasks,
        methods: vec![Method::Adqn],
        nets: nets.clone(),
        seeds: seed_list.clone(),
        t_query: T_QUERY_VALUES.to_vec(),
        ..SweepGrid::default()
    };
    let experts = SweepGrid {
        envs: vec![crate::paper::PAPER_TASKS[3].gym_id.to_string()],
        methods: EXPERT_QUALITY_METHODS.iter().map(|m| method(m)).collect(),
        nets,
        seeds: seed_list,
        experts: EXPERT_QUALITY_SPECS.iter().map(|e| e.to_string()).collect(),
        ..SweepGrid::default()
    };
    vec![
        ("methods", methods),
        ("t_query", t_query),
        ("experts", experts),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_grids_are_valid_and_sized_as_in_the_paper() {
        let grids = paper_grids(PAPER_SEEDS);
        let sizes: Vec<usize> = grids
            .iter()
            .map(|(_, g)| g.specs().unwrap().len())
            .collect();
        assert_eq!(sizes, vec![4 * 6 * 2 * 20, 4 * 2 * 4 * 20, 2 * 2 * 3 * 20]);
    }
}
