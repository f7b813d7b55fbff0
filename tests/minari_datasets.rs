//! Minari datasets as demonstrations, read without Python: the small datasets of tests/data/minari (written by
//! the `minari` package, see make.py there) read as `minari.load_dataset` reads them (expected.json, written by
//! minari from the same files), their spaces checked against the run's, HDF5 and damaged datasets refused with
//! clear errors, and `arld train --set demo_file=ID` pre-training on a dataset found by its id.

mod common;

use arld::expert::demos::{DemoAction, Demonstrations};
use arld::expert::minari;
use common::{ARLD, stderr};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

const CARTPOLE: &str = "arld-test/cartpole-v0";
const PENDULUM: &str = "arld-test/pendulum-v0";

/// The directory of the committed datasets (what `MINARI_DATASETS_PATH` names).
fn datasets() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/minari")
}

/// What minari read from dataset `id`: one object per episode.
fn expected(id: &str) -> Vec<Value> {
    let text = std::fs::read_to_string(datasets().join("expected.json")).unwrap();
    let all: Value = serde_json::from_str(&text).unwrap();
    all[id].as_array().unwrap().clone()
}

/// A copy of dataset `id` in a temporary directory, to damage.
fn copy_of(id: &str) -> (tempfile::TempDir, PathBuf) {
    fn copy(from: &Path, to: &Path) {
        std::fs::create_dir_all(to).unwrap();
        for entry in std::fs::read_dir(from).unwrap() {
            let entry = entry.unwrap();
            let target = to.join(entry.file_name());
            if entry.file_type().unwrap().is_dir() {
                copy(&entry.path(), &target);
            } else {
                std::fs::copy(entry.path(), target).unwrap();
            }
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let dataset = dir.path().join("dataset");
    copy(&datasets().join(id), &dataset);
    (dir, dataset)
}

fn load<A: DemoAction>(dataset: &Path, env: &str) -> Result<Demonstrations<A>, String> {
    let data = minari::dataset_dir(dataset)
        .unwrap()
        .expect("a Minari dataset");
    minari::load::<A>(&data, env).map_err(|e| format!("{e:#}"))
}

/// The transitions read equal minari's episodes: observations, actions, rewards and ends, in order, each episode's
/// last step marked truncated unless it terminated.
fn reads_as_minari<A: DemoAction>(id: &str, env: &str) {
    let demos = load::<A>(&datasets().join(id), env).unwrap();
    assert_eq!(demos.env, env);
    assert_eq!(demos.expert, format!("minari:{id}"));
    let episodes = expected(id);
    let mut t = demos.transitions.iter();
    for (e, episode) in episodes.iter().enumerate() {
        let obs: Vec<Vec<f32>> = serde_json::from_value(episode["observations"].clone()).unwrap();
        let actions = episode["actions"].as_array().unwrap();
        let n = actions.len();
        assert_eq!(obs.len(), n + 1);
        for i in 0..n {
            let step = t
                .next()
                .unwrap_or_else(|| panic!("{id}: episode {e} step {i} missing"));
            assert_eq!(step.episode, e);
            assert_eq!(step.obs, obs[i], "{id}: episode {e} step {i}");
            assert_eq!(step.next_obs, obs[i + 1], "{id}: episode {e} step {i}");
            assert_eq!(serde_json::to_value(&step.action).unwrap(), actions[i]);
            assert_eq!(step.reward, episode["rewards"][i].as_f64().unwrap() as f32);
            let terminated = episode["terminations"][i].as_bool().unwrap();
            let truncated = episode["truncations"][i].as_bool().unwrap();
            assert_eq!(step.terminated, terminated);
            assert_eq!(step.truncated, truncated || (i + 1 == n && !terminated));
        }
    }
    assert!(
        t.next().is_none(),
        "{id}: more transitions than minari reads"
    );
}

#[test]
fn discrete_and_box_datasets_read_as_minari_reads_them() {
    reads_as_minari::<usize>(CARTPOLE, "CartPole-v1");
    reads_as_minari::<Vec<f32>>(PENDULUM, "Pendulum-v1");
    // The dataset's directory, its `data/` and (with no such path) its id name the same dataset.
    let dir = datasets().join(CARTPOLE);
    let found = |path: &Path| minari::dataset_dir(path).unwrap();
    assert_eq!(found(&dir), Some(dir.join("data")));
    assert_eq!(found(&dir.join("data")), Some(dir.join("data")));
    assert_eq!(found(&datasets().join("no-such-v0")), None);
    assert_eq!(found(Path::new("demos.jsonl")), None);
}

#[test]
fn a_dataset_of_other_spaces_is_refused_naming_the_difference() {
    let cartpole = datasets().join(CARTPOLE);
    let e = load::<usize>(&cartpole, "MountainCar-v0").unwrap_err();
    assert!(
        e.contains("shape [4]") && e.contains("MountainCar-v0 observes 2 numbers"),
        "{e}"
    );
    let pendulum = datasets().join(PENDULUM);
    let e = load::<Vec<f32>>(&pendulum, "MountainCarContinuous-v0").unwrap_err();
    assert!(e.contains("observes 2 numbers"), "{e}");
    // Three actions where CartPole has two; a box of other bounds.
    let (_tmp, three) = copy_of(CARTPOLE);
    edit_metadata(&three, |m| {
        m["action_space"] = r#"{"type": "Discrete", "dtype": "int64", "start": 0, "n": 3}"#.into()
    });
    let e = load::<usize>(&three, "CartPole-v1").unwrap_err();
    assert!(
        e.contains("its actions are Discrete(3), but CartPole-v1's are Discrete(2)"),
        "{e}"
    );
    let (_tmp, narrow) = copy_of(PENDULUM);
    edit_metadata(&narrow, |m| {
        m["action_space"] =
            r#"{"type": "Box", "dtype": "float32", "shape": [1], "low": [-1.0], "high": [2.0]}"#
                .into()
    });
    let e = load::<Vec<f32>>(&narrow, "Pendulum-v1").unwrap_err();
    assert!(
        e.contains("Box([-1.0] to [2.0], shape [1])")
            && e.contains("Pendulum-v1's are Box([-2.0] to [2.0]"),
        "{e}"
    );
    // A discrete dataset for a task with actions in a box, and the reverse.
    let e = load::<Vec<f32>>(&cartpole, "Pendulum-v1").unwrap_err();
    assert!(e.contains("observes 3 numbers"), "{e}");
    let (_tmp, boxed) = copy_of(CARTPOLE);
    edit_metadata(&boxed, |m| {
        m["action_space"] =
            r#"{"type": "Box", "dtype": "float32", "shape": [1], "low": [-1.0], "high": [1.0]}"#
                .into()
    });
    let e = load::<usize>(&boxed, "CartPole-v1").unwrap_err();
    assert!(e.contains("Discrete(2)"), "{e}");
}

fn edit_metadata(dataset: &Path, edit: impl FnOnce(&mut Value)) {
    let path = dataset.join("data").join(minari::METADATA_FILE);
    let text = std::fs::read_to_string(&path)
        .unwrap()
        .replace("-Infinity", "-1e30")
        .replace("Infinity", "1e30");
    let mut meta: Value = serde_json::from_str(&text).unwrap();
    edit(&mut meta);
    std::fs::write(&path, meta.to_string()).unwrap();
}

#[test]
fn hdf5_and_damaged_datasets_are_clear_errors() {
    let (_tmp, hdf5) = copy_of(CARTPOLE);
    edit_metadata(&hdf5, |m| m["data_format"] = "hdf5".into());
    let e = load::<usize>(&hdf5, "CartPole-v1").unwrap_err();
    assert!(
        e.contains("HDF5") && e.contains("data_format=\"arrow\""),
        "{e}"
    );
    // Counts that disagree with the episodes.
    let (_tmp, counts) = copy_of(CARTPOLE);
    edit_metadata(&counts, |m| m["total_steps"] = 29.into());
    let e = load::<usize>(&counts, "CartPole-v1").unwrap_err();
    assert!(e.contains("says 29 steps, but its episodes hold 28"), "{e}");
    edit_metadata(&counts, |m| m["total_episodes"] = 4.into());
    let e = load::<usize>(&counts, "CartPole-v1").unwrap_err();
    assert!(
        e.contains("episode 3") && e.contains("no episode directory"),
        "{e}"
    );
    // Not JSON.
    let (_tmp, garbled) = copy_of(CARTPOLE);
    std::fs::write(
        garbled.join("data").join(minari::METADATA_FILE),
        "{\"total_",
    )
    .unwrap();
    let e = load::<usize>(&garbled, "CartPole-v1").unwrap_err();
    assert!(e.contains("not a Minari metadata file"), "{e}");
    // An episode file cut anywhere is refused; one with any byte changed is refused or read, never a panic.
    let (_tmp, damaged) = copy_of(CARTPOLE);
    let file = damaged.join("data").join("1").join("part-0.arrow");
    let bytes = std::fs::read(&file).unwrap();
    for len in 0..bytes.len() {
        std::fs::write(&file, &bytes[..len]).unwrap();
        let e = load::<usize>(&damaged, "CartPole-v1").unwrap_err();
        assert!(
            e.contains("episode 1") && e.contains("part-0.arrow"),
            "{len}: {e}"
        );
    }
    let mut read = 0;
    for at in 0..bytes.len() {
        let mut changed = bytes.clone();
        changed[at] ^= 0x5a;
        std::fs::write(&file, &changed).unwrap();
        if load::<usize>(&damaged, "CartPole-v1").is_ok() {
            read += 1;
        }
    }
    // The values' bytes may change and still read; the layout's may not.
    assert!(
        0 < read && read < bytes.len(),
        "{read} of {} read",
        bytes.len()
    );
}

/// Runs `arld` with `MINARI_DATASETS_PATH` set to the committed datasets.
fn arld_with_datasets(args: &[&str]) -> std::process::Output {
    Command::new(ARLD)
        .args(args)
        .env("MINARI_DATASETS_PATH", datasets())
        .output()
        .unwrap()
}

#[test]
fn the_command_line_pre_trains_on_a_dataset_given_by_id() {
    let dir = tempfile::tempdir().unwrap();
    for (env, id, method, steps) in [
        ("CartPole-v1", CARTPOLE, "dqfd", 28),
        ("Pendulum-v1", PENDULUM, "dqfd", 12),
    ] {
        let out = dir.path().join(env);
        let res = arld_with_datasets(&[
            "train",
            "--env",
            env,
            "--method",
            method,
            "--quiet",
            "--set",
            &format!("demo_file={id}"),
            "--set",
            "pretrain_steps=20",
            "--set",
            "train_steps=300",
            "--set",
            "learning_starts=100",
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(res.status.success(), "{env}: {}", stderr(&res));
        let summary: Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap())
                .unwrap();
        assert_eq!(summary["demos_pretrain"], steps, "{env}");
    }
    // Of other spaces: refused before training, naming the difference.
    let res = arld_with_datasets(&[
        "train",
        "--env",
        "Acrobot-v1",
        "--method",
        "dqfd",
        "--quiet",
        "--set",
        &format!("demo_file={CARTPOLE}"),
        "-o",
        dir.path().join("acrobot").to_str().unwrap(),
    ]);
    assert!(!res.status.success());
    assert!(
        stderr(&res).contains("Acrobot-v1 observes 6 numbers"),
        "{}",
        stderr(&res)
    );
    // An id that names no dataset, and no file: both said.
    let res = arld_with_datasets(&[
        "train",
        "--env",
        "CartPole-v1",
        "--method",
        "dqfd",
        "--quiet",
        "--set",
        "demo_file=arld-test/nothing-v0",
        "-o",
        dir.path().join("nothing").to_str().unwrap(),
    ]);
    assert!(!res.status.success());
    let e = stderr(&res);
    assert!(
        e.contains("no Minari dataset arld-test/nothing-v0") && e.contains("tests/data/minari"),
        "{e}"
    );
}
