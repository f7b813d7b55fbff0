//! The paper's published numbers, kept as data so a report can put ours next to theirs, and the grids of the
//! paper's experiments so one command can reproduce them.
//!
//! Sources: Table 5 (median steps to solve over 20 seeds) and the expert statistics table of Chen et al.,
//! "Active Deep Q-learning with Demonstration" (arXiv 1812.02632), as transcribed in docs/algorithm.md
//! sections 1, 9, 10 and 11. [`paper_grids`] turns the paper's Section 4 (the method comparison, the t_query
//! study and the expert-quality study) into [`SweepGrid`]s for [`super::sweep::run_sweep`].

use super::sweep::SweepGrid;
use crate::train::{Method, NetKind};

/// One of the paper's four tasks: its display name, the Gym id the paper used, and the score that marks it solved.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperTask {
    /// Name as printed in the paper's tables.
    pub name: &'static str,
    /// Gym id of the version the paper used (docs/algorithm.md section 1).
    pub gym_id: &'static str,
    /// Ids that count as the same task (Gymnasium 1.x renamed LunarLander-v2 to -v3 without changing it).
    pub aliases: &'static [&'static str],
    /// Target score (Gym `reward_threshold`).
    pub solve_threshold: f64,
}

/// The paper's tasks in the column order of its tables.
pub const PAPER_TASKS: [PaperTask; 4] = [
    PaperTask {
        name: "Cart-Pole",
        gym_id: "CartPole-v0",
        aliases: &["CartPole-v0"],
        solve_threshold: 195.0,
    },
    PaperTask {
        name: "Acrobot",
        gym_id: "Acrobot-v1",
        aliases: &["Acrobot-v1"],
        solve_threshold: -100.0,
    },
    PaperTask {
        name: "Mountain Car",
        gym_id: "MountainCar-v0",
        aliases: &["MountainCar-v0"],
        solve_threshold: -110.0,
    },
    PaperTask {
        name: "Lunar Lander",
        gym_id: "LunarLander-v2",
        aliases: &["LunarLander-v2", "LunarLander-v3"],
        solve_threshold: 200.0,
    },
];

/// Position of an environment id among [`PAPER_TASKS`] (its table column), if it is one of the paper's tasks.
pub fn paper_task_index(env_id: &str) -> Option<usize> {
    PAPER_TASKS
        .iter()
        .position(|task| task.aliases.contains(&env_id))
}

/// The six methods in the row order of Table 5 within each network group (lower-case, as in configs).
pub const TABLE5_METHODS: [&str; 6] = ["dqn", "gdqn", "bdqn", "adqn", "dqfd", "adqnp"];

/// The two network groups of Table 5: the config name and the suffix the paper prints (DQN-B, DQN-N).
pub const TABLE5_NETS: [(&str, &str); 2] = [("bootstrap", "B"), ("noisy", "N")];

/// Table 5: median environment steps to solve over 20 seeds, indexed `[net group][method][task]` in the orders
/// of [`TABLE5_NETS`], [`TABLE5_METHODS`] and [`PAPER_TASKS`]. 500000 on Lunar Lander means no solve within
/// the training budget for at least half of the seeds.
pub const TABLE5_MEDIAN_STEPS: [[[u64; 4]; 6]; 2] = [
    [
        [8000, 57000, 210000, 260000], // DQN-B
        [8000, 45000, 170000, 310000], // GDQN-B
        [7500, 31000, 100000, 217500], // BDQN-B
        [7000, 25000, 85000, 205000],  // ADQN-B
        [7500, 38000, 140000, 500000], // DQfD-B
        [6000, 49000, 135000, 267500], // ADQNP-B
    ],
    [
        [13000, 114000, 190000, 355000], // DQN-N
        [10000, 73000, 295000, 500000],  // GDQN-N
        [10000, 55000, 170000, 160000],  // BDQN-N
        [9500, 8000, 230000, 47500],     // ADQN-N
        [8000, 95000, 300000, 402500],   // DQfD-N
        [8000, 75000, 255000, 212500],   // ADQNP-N
    ],
];

/// The paper's Table 5 entry for an environment id, method and network, if the paper reports one.
pub fn paper_median_steps(env_id: &str, method: &str, net: &str) -> Option<u64> {
    let task = paper_task_index(env_id)?;
    let net_index = TABLE5_NETS.iter().position(|(name, _)| *name == net)?;
    let method_index = TABLE5_METHODS.iter().position(|m| *m == method)?;
    Some(TABLE5_MEDIAN_STEPS[net_index][method_index][task])
}

/// How the paper prints a method name (DQfD keeps its lower-case f).
pub fn method_display_name(method: &str) -> String {
    match method {
        "dqfd" => "DQfD".to_string(),
        other => other.to_uppercase(),
    }
}

/// One row of the paper's expert statistics table (100 evaluation episodes of the snapshot "weak" expert).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExpertStats {
    pub gym_id: &'static str,
    pub mean_return: f64,
    pub std_return: f64,
    pub min_return: f64,
    pub mean_episode_length: f64,
    pub target_score: f64,
}

/// The expert statistics table, in the order of [`PAPER_TASKS`].
pub const EXPERT_STATS: [ExpertStats; 4] = [
    ExpertStats {
        gym_id: "CartPole-v0",
        mean_return: 166.77,
        std_return: 39.14,
        min_return: 93.0,
        mean_episode_length: 166.77,
        target_score: 195.0,
    },
    ExpertStats {
        gym_id: "Acrobot-v1",
        mean_return: -128.25,
        std_return: 66.86,
        min_return: -489.0,
        mean_episode_length: 128.25,
        target_score: -100.0,
    },
    ExpertStats {
        gym_id: "MountainCar-v0",
        mean_return: -134.0,
        std_return: 27.52,
        min_return: -158.0,
        mean_episode_length: 134.0,
        target_score: -110.0,
    },
    ExpertStats {
        gym_id: "LunarLander-v2",
        mean_return: 155.18,
        std_return: 55.58,
        min_return: -16.63,
        mean_episode_length: 784.92,
        target_score: 200.0,
    },
];

/// The paper's expert statistics for an environment id, if it is one of the paper's tasks.
pub fn expert_stats(env_id: &str) -> Option<&'static ExpertStats> {
    paper_task_index(env_id).map(|i| &EXPERT_STATS[i])
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
    let all_tasks: Vec<String> = PAPER_TASKS.iter().map(|t| t.gym_id.to_string()).collect();
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
        envs: vec![PAPER_TASKS[3].gym_id.to_string()],
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
    fn table5_lookup_follows_the_paper_layout() {
        // Spot checks against the LaTeX table (t:step_solve): ADQN-N on Acrobot and DQfD-B on Lunar Lander.
        assert_eq!(
            paper_median_steps("Acrobot-v1", "adqn", "noisy"),
            Some(8000)
        );
        assert_eq!(
            paper_median_steps("LunarLander-v3", "dqfd", "bootstrap"),
            Some(500000)
        );
        assert_eq!(paper_median_steps("CartPole-v1", "dqn", "bootstrap"), None);
        assert_eq!(paper_median_steps("CartPole-v0", "dqn", "plain"), None);
    }

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
