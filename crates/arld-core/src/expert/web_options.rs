//! The web expert's options, as its spec writes them (`web:listen=ADDR,fps=N,timeout=S,wait=no`): parsed with the
//! other expert specs ([`super::ExpertSpec`]), so that a configuration naming the web expert is checked before any
//! work. The expert itself (server and page) is the `arld-web` crate.

use anyhow::{Context, Result, bail, ensure};
use std::net::SocketAddr;

/// The default address: this machine only.
pub const DEFAULT_LISTEN: &str = "127.0.0.1:8765";
/// The slowest real-time pace (one step in 100 s): the step period 1/fps stays a time a clock can hold.
const MIN_FPS: f64 = 0.01;

/// How the web expert listens and how the person answers. Written as the spec
/// `web:listen=ADDR,fps=N,timeout=S,wait=no` (every part optional, e.g. `web` or `web:fps=10`).
#[derive(Clone, Debug, PartialEq)]
pub struct WebOptions {
    pub listen: SocketAddr,
    /// Real-time steps per second; `None`: turn-based.
    pub fps: Option<f64>,
    /// Seconds a question waits before it goes back to the agent; `None`: it waits for ever.
    pub timeout: Option<f64>,
    /// Whether the run waits for the page to be opened before it starts (so that the first question is not
    /// timed against opening a browser).
    pub wait: bool,
}

impl Default for WebOptions {
    fn default() -> Self {
        Self {
            listen: DEFAULT_LISTEN.parse().expect("valid default address"),
            fps: None,
            timeout: None,
            wait: true,
        }
    }
}

impl std::str::FromStr for WebOptions {
    type Err = anyhow::Error;
    /// Parses `listen=ADDR,fps=N,timeout=S` (any subset, any order; empty: the defaults).
    fn from_str(s: &str) -> Result<Self> {
        let mut o = WebOptions::default();
        for part in s.split(',').filter(|p| !p.is_empty()) {
            let (key, value) = part
                .split_once('=')
                .with_context(|| format!("web expert option '{part}' is not key=value"))?;
            // Bounded on both sides: a step period of 1/fps seconds must be a time a clock can hold.
            let within = |what: &str, min: f64, max: f64| -> Result<f64> {
                let v: f64 = value
                    .parse()
                    .with_context(|| format!("web expert {what} '{value}' is not a number"))?;
                ensure!(
                    v.is_finite() && v >= min && v <= max,
                    "web expert {what} must be in [{min}, {max}], got {value}"
                );
                Ok(v)
            };
            match key {
                "listen" => o.listen = value.parse().with_context(|| {
                    format!(
                        "web expert listen address '{value}' is not IP:PORT (e.g. {DEFAULT_LISTEN})"
                    )
                })?,
                "fps" => o.fps = Some(within("fps", MIN_FPS, 1000.0)?),
                "timeout" => o.timeout = Some(within("timeout", 0.001, 1e6)?),
                "wait" => {
                    o.wait = match value {
                        "yes" | "true" => true,
                        "no" | "false" => false,
                        _ => bail!("web expert wait must be yes or no, got '{value}'"),
                    }
                }
                _ => bail!("unknown web expert option '{key}'; known: listen, fps, timeout, wait"),
            }
        }
        Ok(o)
    }
}

impl WebOptions {
    /// The options as the spec suffix that [`FromStr`](std::str::FromStr) reads back.
    pub fn to_spec(&self) -> String {
        let mut parts = vec![format!("listen={}", self.listen)];
        parts.extend(self.fps.map(|v| format!("fps={v}")));
        parts.extend(self.timeout.map(|v| format!("timeout={v}")));
        if !self.wait {
            parts.push("wait=no".into());
        }
        format!("web:{}", parts.join(","))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_parse_and_round_trip() {
        assert_eq!("".parse::<WebOptions>().unwrap(), WebOptions::default());
        let o: WebOptions = "fps=12.5,listen=0.0.0.0:9000,timeout=30,wait=no"
            .parse()
            .unwrap();
        assert!(!o.wait);
        assert_eq!(o.listen, "0.0.0.0:9000".parse().unwrap());
        assert_eq!((o.fps, o.timeout), (Some(12.5), Some(30.0)));
        assert_eq!(
            o.to_spec()
                .strip_prefix("web:")
                .unwrap()
                .parse::<WebOptions>()
                .unwrap(),
            o
        );
        for bad in [
            "fps=0",
            "fps=-3",
            "fps=nan",
            "timeout=inf",
            "listen=localhost",
            "listen=1.2.3.4",
            "speed=3",
            "fps",
            "wait=maybe",
        ] {
            assert!(bad.parse::<WebOptions>().is_err(), "{bad} accepted");
        }
    }
}
