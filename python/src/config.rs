//! Configurations: the keys, and a configuration resolved from the paper's preset and Python's values (as JSON).

use crate::errors::value_error;
use arld_core::train::{ConfigInput, TrainConfig};
use pyo3::prelude::*;

/// Every configuration key (the CLI's `--set` keys), in order.
#[pyfunction]
pub(crate) fn config_keys() -> Vec<String> {
    TrainConfig::valid_keys()
}

/// Resolves a configuration (the paper's preset, then `values` as JSON texts) and returns it as JSON text.
/// `preset_of`: the built-in task whose preset a wrapped or re-limited copy of it (`env`) takes; the values are
/// resolved as for that task, then the run is named `env`. `person`: the options of an `arld.WebExpert` as its spec
/// (`.spec`): in real time a question's segment lasts its seconds of play unless `segment_len` is given
/// ([`ConfigInput::real_time_segment`]).
#[pyfunction]
#[pyo3(signature = (env, method, net, seed, values, preset_of=None, person=None))]
pub(crate) fn resolve_config(
    env: &str,
    method: &str,
    net: &str,
    seed: u64,
    values: Vec<(String, String)>,
    preset_of: Option<&str>,
    person: Option<&str>,
) -> PyResult<String> {
    let cfg = resolve(env, method, net, seed, &values, preset_of, person)
        .map_err(|e| value_error(format!("{e:#}")))?;
    Ok(cfg.to_json())
}

pub(crate) fn resolve(
    env: &str,
    method: &str,
    net: &str,
    seed: u64,
    values: &[(String, String)],
    preset_of: Option<&str>,
    person: Option<&str>,
) -> anyhow::Result<TrainConfig> {
    let mut input = ConfigInput::new(
        preset_of.unwrap_or(env),
        method.parse()?,
        net.parse()?,
        seed,
    );
    for (key, json) in values {
        let value: serde_json::Value = serde_json::from_str(json)?;
        input.set(key, toml_value(key, value)?)?;
    }
    if let Some(steps) = person.and_then(|spec| input.real_time_segment(spec)) {
        input.set("segment_len", steps as i64)?;
    }
    let mut cfg = input.resolve()?;
    if preset_of.is_some() {
        cfg.env = env.to_string();
        cfg.validate()?;
    }
    Ok(cfg)
}

/// A Python value (as JSON) as the configuration's TOML value: a number, boolean, string, or a list of them.
pub(crate) fn toml_value(key: &str, value: serde_json::Value) -> anyhow::Result<toml::Value> {
    Ok(match value {
        serde_json::Value::Bool(b) => toml::Value::Boolean(b),
        serde_json::Value::String(s) => toml::Value::String(s),
        serde_json::Value::Number(n) if n.is_i64() => {
            toml::Value::Integer(n.as_i64().expect("checked"))
        }
        serde_json::Value::Number(n) => toml::Value::Float(n.as_f64().unwrap_or(f64::NAN)),
        serde_json::Value::Array(items) => toml::Value::Array(
            items
                .into_iter()
                .map(|v| toml_value(key, v))
                .collect::<anyhow::Result<_>>()?,
        ),
        other => {
            anyhow::bail!("`{key}`: a number, boolean, string or list is needed, got {other}")
        }
    })
}
