//! The shipped experts (`shipped:weak`, `shipped:perfect`), compiled into the library.
//!
//! The repository's `experts/<env>/{weak,perfect}.safetensors` (about 20 kB each, 14 files) are included in the
//! library's bytes when it is built, so an installed `arld` (or the Python package) finds them wherever it is
//! and whatever the working directory: nothing is looked up on disk at run time, and nothing a user writes into
//! a folder named `experts/` changes what `shipped:weak` means. [`model`] gives a shipped expert's bytes;
//! [`holds_shipped`] tells whether a folder is (or holds) the shipped experts, which `arld expert train` refuses
//! to write over.

use std::path::{Path, PathBuf};

/// The two shipped experts of a task: the paper's kind of expert (`weak`) and the best checkpoint (`perfect`).
pub const QUALITIES: [&str; 2] = ["weak", "perfect"];

/// One task's shipped experts.
struct TaskExperts {
    task: &'static str,
    weak: &'static [u8],
    perfect: &'static [u8],
}

/// Includes `experts/<task>/{weak,perfect}.safetensors` of the repository the library is built from.
macro_rules! task_experts {
    ($($task:literal),* $(,)?) => {
        [$(TaskExperts {
            task: $task,
            weak: include_bytes!(concat!(env!("CARGO_MANIFEST_DIR"), "/../../experts/", $task, "/weak.safetensors")),
            perfect: include_bytes!(concat!(
                env!("CARGO_MANIFEST_DIR"), "/../../experts/", $task, "/perfect.safetensors"
            )),
        }),*]
    };
}

static EXPERTS: [TaskExperts; 7] = task_experts!(
    "CartPole-v0",
    "Acrobot-v1",
    "MountainCar-v0",
    "LunarLander-v2",
    "Pendulum-v1",
    "MountainCarContinuous-v0",
    "LunarLanderContinuous-v3",
);

/// The task whose experts `env_id` uses: CartPole-v1 and LunarLander-v3 share those of CartPole-v0 and
/// LunarLander-v2 (the same dynamics, another time limit or version).
pub fn task_of(env_id: &str) -> &str {
    match env_id {
        "CartPole-v1" => "CartPole-v0",
        "LunarLander-v3" => "LunarLander-v2",
        e => e,
    }
}

/// The tasks that have shipped experts, as named in `experts/`.
pub fn tasks() -> impl Iterator<Item = &'static str> {
    EXPERTS.iter().map(|e| e.task)
}

/// The bytes of the shipped expert `quality` (`weak` or `perfect`) for `env_id`; `None` when there is none.
pub fn model(env_id: &str, quality: &str) -> Option<&'static [u8]> {
    let task = task_of(env_id);
    let experts = EXPERTS.iter().find(|e| e.task == task)?;
    match quality {
        "weak" => Some(experts.weak),
        "perfect" => Some(experts.perfect),
        _ => None,
    }
}

/// The repository folder the shipped experts were compiled from (`experts/` of the checkout that built this
/// library); it may no longer exist where the binary runs.
pub fn source_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .unwrap_or(Path::new(env!("CARGO_MANIFEST_DIR")))
        .join("experts")
}

/// Whether writing experts into `dir` would replace shipped ones: `dir` is a task's folder under
/// [`source_dir`], or it holds a file whose bytes are a shipped expert's (a copy of the checkout, wherever it
/// is).
pub fn holds_shipped(dir: &Path) -> bool {
    let same_place = |a: &Path, b: &Path| match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    };
    if tasks().any(|task| same_place(dir, &source_dir().join(task))) {
        return true;
    }
    QUALITIES.iter().any(|quality| {
        let bytes = std::fs::read(dir.join(format!("{quality}.safetensors"))).ok();
        bytes.is_some_and(|bytes| {
            EXPERTS
                .iter()
                .any(|e| e.weak == bytes.as_slice() || e.perfect == bytes.as_slice())
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every task folder of the repository's `experts/` is compiled in, byte for byte.
    #[test]
    fn every_expert_of_the_repository_is_compiled_in() {
        let mut on_disk: Vec<String> = std::fs::read_dir(source_dir())
            .unwrap()
            .map(|entry| entry.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        on_disk.sort();
        let mut compiled: Vec<String> = tasks().map(String::from).collect();
        compiled.sort();
        assert_eq!(on_disk, compiled);
        for task in tasks() {
            for quality in QUALITIES {
                let file = std::fs::read(
                    source_dir()
                        .join(task)
                        .join(format!("{quality}.safetensors")),
                );
                assert_eq!(
                    file.unwrap(),
                    model(task, quality).unwrap(),
                    "{task} {quality}"
                );
            }
            assert!(holds_shipped(&source_dir().join(task)));
        }
        assert!(model("CartPole-v1", "weak").is_some() && model("CartPole-v0", "best").is_none());
        assert!(!holds_shipped(Path::new("/nonexistent")));
    }
}
