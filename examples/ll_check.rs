use arld::env::{
    Env,
    lunar_lander::{LunarLander, heuristic_action},
};
use std::io::BufRead;
fn main() {
    let f = std::fs::File::open("/work/shared/conformance/lunar_lander.jsonl").unwrap();
    let mut env = LunarLander::new("LunarLander-v3");
    let mut case = String::new();
    let mut seed = 0;
    let mut maxdev: f64 = 0.0;
    let mut first_bad: Option<usize> = None;
    let mut heur_mismatch = 0;
    let report = |case: &str, seed: u64, maxdev: f64, first_bad: Option<usize>, hm: usize| {
        println!(
            "{case} seed {seed}: maxdev {maxdev:.3e} first_bad {first_bad:?} heuristic_action_mismatch {hm}"
        );
    };
    let mut last_obs: Vec<f32> = vec![];
    for line in std::io::BufReader::new(f).lines() {
        let v: serde_json::Value = serde_json::from_str(&line.unwrap()).unwrap();
        let kind = v["kind"].as_str().unwrap();
        if kind == "meta" {
            continue;
        }
        let obs: Vec<f64> = v["obs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        if kind == "start" {
            if !case.is_empty() {
                report(&case, seed, maxdev, first_bad, heur_mismatch);
            }
            case = v["case"].as_str().unwrap().to_string();
            seed = v["seed"].as_u64().unwrap();
            maxdev = 0.0;
            first_bad = None;
            heur_mismatch = 0;
            let o = env.reset(Some(seed));
            for (a, b) in o.iter().zip(&obs) {
                maxdev = maxdev.max((*a as f64 - b).abs());
            }
            last_obs = o;
        } else {
            let t = v["t"].as_u64().unwrap() as usize;
            let action = v["action"].as_u64().unwrap() as usize;
            if case == "heuristic" && heuristic_action(&last_obs) != action {
                heur_mismatch += 1;
            }
            let st = env.step(action).unwrap();
            let mut d: f64 = 0.0;
            for (a, b) in st.obs.iter().zip(&obs) {
                d = d.max((*a as f64 - b).abs());
            }
            d = d.max((st.reward - v["reward"].as_f64().unwrap()).abs());
            if st.terminated != v["terminated"].as_bool().unwrap()
                || st.truncated != v["truncated"].as_bool().unwrap()
            {
                d = f64::INFINITY;
            }
            if d > 1e-9 && d > maxdev {
                let comps: Vec<f64> = st
                    .obs
                    .iter()
                    .zip(&obs)
                    .map(|(a, b)| *a as f64 - b)
                    .collect();
                println!(
                    "  t={t} dev {d:.3e} comps {comps:?} rdev {:.3e} term {}",
                    st.reward - v["reward"].as_f64().unwrap(),
                    st.terminated
                );
            }
            if d > 1e-4 && first_bad.is_none() {
                first_bad = Some(t);
                println!(
                    "  t={t} ours {:?} r {} term {} | ref {:?} r {}",
                    st.obs, st.reward, st.terminated, obs, v["reward"]
                );
            }
            maxdev = maxdev.max(d);
            last_obs = st.obs;
        }
    }
    report(&case, seed, maxdev, first_bad, heur_mismatch);
}
