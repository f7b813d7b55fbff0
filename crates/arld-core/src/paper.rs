//! The paper's published numbers, in one place (Chen et al., "Active Deep Q-learning with Demonstration",
//! arXiv 1812.02632; docs/algorithm.md sections 1, 9, 10 and 11): its four tasks, the task-specific parameters
//! (its Table 4), the expert statistics (Table 3) and the median steps to solve (Table 5). Training takes its
//! presets from here, expert selection its targets, reports the numbers to print beside ours. Pure data: this
//! module uses nothing else of the crate. Every table is indexed in the order of [`PAPER_TASKS`].

/// One of the paper's four tasks: its display name, the Gym id the paper used, and the ids that count as it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperTask {
    /// Name as printed in the paper's tables.
    pub name: &'static str,
    /// Gym id of the version the paper used (docs/algorithm.md section 1).
    pub gym_id: &'static str,
    /// Ids that count as the same task (Gymnasium 1.x renamed LunarLander-v2 to -v3 without changing it;
    /// CartPole-v1 is another task: longer episodes, a higher threshold).
    pub aliases: &'static [&'static str],
}

/// The paper's tasks in the column order of its tables. (Their target scores are Gym's reward thresholds,
/// which the environments' specs hold.)
pub const PAPER_TASKS: [PaperTask; 4] = [
    PaperTask {
        name: "Cart-Pole",
        gym_id: "CartPole-v0",
        aliases: &["CartPole-v0"],
    },
    PaperTask {
        name: "Acrobot",
        gym_id: "Acrobot-v1",
        aliases: &["Acrobot-v1"],
    },
    PaperTask {
        name: "Mountain Car",
        gym_id: "MountainCar-v0",
        aliases: &["MountainCar-v0"],
    },
    PaperTask {
        name: "Lunar Lander",
        gym_id: "LunarLander-v2",
        aliases: &["LunarLander-v2", "LunarLander-v3"],
    },
];

/// Position of an environment id among [`PAPER_TASKS`] (its table column), if it is one of the paper's tasks.
pub fn task_index(env_id: &str) -> Option<usize> {
    PAPER_TASKS
        .iter()
        .position(|task| task.aliases.contains(&env_id))
}

/// The paper's task-specific parameters (its Table 4, "Task specific parameters").
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct TaskParameters {
    pub gamma: f64,
    pub lr: f64,
    pub train_steps: usize,
    /// Demonstrations (DQfD) and query budget (ADQN): "# of demo/budget".
    pub n_demo: usize,
    /// "Memory size": the agent part of replay.
    pub replay_size: usize,
    pub pretrain_steps: usize,
    /// DQfD's margin-loss weight λ.
    pub lambda: f64,
    pub t_query_bootstrap: f64,
    pub t_query_noisy: f64,
}

/// Table 4, in the order of [`PAPER_TASKS`].
pub(crate) const TASK_PARAMETERS: [TaskParameters; 4] = [
    TaskParameters {
        gamma: 0.9,
        lr: 1e-4,
        train_steps: 20_000,
        n_demo: 200,
        replay_size: 10_000,
        pretrain_steps: 10_000,
        lambda: 1e-5,
        t_query_bootstrap: 0.05,
        t_query_noisy: 0.5,
    },
    TaskParameters {
        gamma: 0.99,
        lr: 1e-4,
        train_steps: 200_000,
        n_demo: 100,
        replay_size: 100_000,
        pretrain_steps: 10_000,
        lambda: 1.0,
        t_query_bootstrap: 0.3,
        t_query_noisy: 0.3,
    },
    TaskParameters {
        gamma: 0.99,
        lr: 1e-3,
        train_steps: 500_000,
        n_demo: 500,
        replay_size: 100_000,
        pretrain_steps: 10_000,
        lambda: 1.0,
        t_query_bootstrap: 0.1,
        t_query_noisy: 0.3,
    },
    TaskParameters {
        gamma: 0.99,
        lr: 1e-3,
        train_steps: 500_000,
        n_demo: 3_000,
        replay_size: 100_000,
        pretrain_steps: 30_000,
        lambda: 1.0,
        t_query_bootstrap: 0.3,
        t_query_noisy: 0.1,
    },
];

/// The paper's parameters for an environment id, if it is one of the paper's tasks.
pub(crate) fn task_parameters(env_id: &str) -> Option<&'static TaskParameters> {
    task_index(env_id).map(|i| &TASK_PARAMETERS[i])
}

/// One row of the paper's expert statistics (its Table 3: 100 evaluation episodes of the snapshot expert).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperExpert {
    pub mean_return: f64,
    pub std_return: f64,
    pub min_return: f64,
    pub mean_episode_length: f64,
}

/// Table 3, in the order of [`PAPER_TASKS`], with the paper's own digits.
pub const EXPERT_STATS: [PaperExpert; 4] = [
    PaperExpert {
        mean_return: 166.77,
        std_return: 39.14,
        min_return: 93.0,
        mean_episode_length: 166.77,
    },
    PaperExpert {
        mean_return: -128.25,
        std_return: 66.86,
        min_return: -489.0,
        mean_episode_length: 128.25,
    },
    PaperExpert {
        mean_return: -134.0,
        std_return: 27.52,
        min_return: -158.0,
        mean_episode_length: 134.0,
    },
    PaperExpert {
        mean_return: 155.18,
        std_return: 55.58,
        min_return: -16.63,
        mean_episode_length: 784.92,
    },
];

/// The paper's expert statistics for an environment id, if it is one of the paper's tasks.
pub fn expert_stats(env_id: &str) -> Option<&'static PaperExpert> {
    task_index(env_id).map(|i| &EXPERT_STATS[i])
}

/// How the paper prints a method given by its config name (`dqfd` -> DQfD, `adqn` -> ADQN).
pub fn method_display_name(method: &str) -> String {
    match method {
        "dqfd" => "DQfD".to_string(),
        other => other.to_uppercase(),
    }
}

/// The six methods in the row order of Table 5 within each network group (lower-case, as in configs).
pub const TABLE5_METHODS: [&str; 6] = ["dqn", "gdqn", "bdqn", "adqn", "dqfd", "adqnp"];

/// The two network groups of Table 5: the config name and the suffix the paper prints (DQN-B, DQN-N).
pub const TABLE5_NETS: [(&str, &str); 2] = [("bootstrap", "B"), ("noisy", "N")];

/// Table 5: median environment steps to solve over 20 seeds, indexed `[method][net group][task]` in the orders
/// of [`TABLE5_METHODS`], [`TABLE5_NETS`] and [`PAPER_TASKS`] (a row holds a method's `-B` and `-N` lines of the
/// table). 500000 on Lunar Lander means no solve within the training budget for at least half of the seeds.
pub(crate) const TABLE5_MEDIAN_STEPS: [[[u64; 4]; 2]; 6] = [
    [
        [8000, 57000, 210000, 260000],
        [13000, 114000, 190000, 355000],
    ], // DQN
    [
        [8000, 45000, 170000, 310000],
        [10000, 73000, 295000, 500000],
    ], // GDQN
    [
        [7500, 31000, 100000, 217500],
        [10000, 55000, 170000, 160000],
    ], // BDQN
    [[7000, 25000, 85000, 205000], [9500, 8000, 230000, 47500]], // ADQN
    [[7500, 38000, 140000, 500000], [8000, 95000, 300000, 402500]], // DQfD
    [[6000, 49000, 135000, 267500], [8000, 75000, 255000, 212500]], // ADQNP
];

/// The paper's Table 5 entry for an environment id, method and network names, if the paper reports one.
pub fn median_steps(env_id: &str, method: &str, net: &str) -> Option<u64> {
    let task = task_index(env_id)?;
    let net_index = TABLE5_NETS.iter().position(|(name, _)| *name == net)?;
    let method_index = TABLE5_METHODS.iter().position(|m| *m == method)?;
    Some(TABLE5_MEDIAN_STEPS[method_index][net_index][task])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lookups_follow_the_paper_layout() {
        // Spot checks against the LaTeX tables: ADQN-N on Acrobot and DQfD-B on Lunar Lander (Table 5), the
        // Lunar Lander expert (Table 3), Mountain Car's parameters (Table 4).
        assert_eq!(median_steps("Acrobot-v1", "adqn", "noisy"), Some(8000));
        assert_eq!(
            median_steps("LunarLander-v3", "dqfd", "bootstrap"),
            Some(500000)
        );
        assert_eq!(median_steps("CartPole-v1", "dqn", "bootstrap"), None);
        assert_eq!(median_steps("CartPole-v0", "dqn", "plain"), None);
        let lander = expert_stats("LunarLander-v3").unwrap();
        assert_eq!(
            (
                lander.std_return,
                lander.min_return,
                lander.mean_episode_length
            ),
            (55.58, -16.63, 784.92)
        );
        let car = task_parameters("MountainCar-v0").unwrap();
        assert_eq!(
            (car.lr, car.n_demo, car.t_query_bootstrap, car.t_query_noisy),
            (1e-3, 500, 0.1, 0.3)
        );
        assert_eq!(task_parameters("CartPole-v1"), None);
        assert_eq!(task_index("Pendulum-v1"), None);
    }
}
