//! The web expert's options, as its spec writes them (`web:listen=ADDR,fps=N,segment_s=S,timeout=S,wait=no`):
//! parsed with the other expert specs ([`super::ExpertSpec`]), so that a configuration naming the web expert is
//! checked before any work. The expert itself (server and page) is the `arld-web` crate.
//!
//! In real time a person answers for a stretch of seconds, not of steps: a segment lasts `segment_s` seconds of
//! play ([`DEFAULT_SEGMENT_S`] unless given), [`WebOptions::segment_steps`] steps at `fps`. A run whose
//! configuration does not set `segment_len` takes that as its segment length (`ConfigInput::resolve`), and its
//! config.toml records it.

use anyhow::{Context, Result, bail, ensure};
use std::net::SocketAddr;

/// The default address: this machine only.
pub const DEFAULT_LISTEN: &str = "127.0.0.1:8765";
/// The slowest real-time pace (one step in 100 s): the step period 1/fps stays a time a clock can hold.
const MIN_FPS: f64 = 0.01;
/// Real time: the seconds of play one question hands the person, unless `segment_s` is given.
pub const DEFAULT_SEGMENT_S: f64 = 3.0;
/// The longest real-time segment (ten minutes of play).
const MAX_SEGMENT_S: f64 = 600.0;

/// How the web expert listens and how the person answers. Written as the spec
/// `web:listen=ADDR,fps=N,segment_s=S,timeout=S,wait=no` (every part optional, e.g. `web` or `web:fps=10`).
#[derive(Clone, Debug, PartialEq)]
pub struct WebOptions {
    pub listen: SocketAddr,
    /// Real-time steps per second; `None`: turn-based.
    pub fps: Option<f64>,
    /// Real time: seconds of play per question; `None`: [`DEFAULT_SEGMENT_S`]. Only with `fps`.
    pub segment_s: Option<f64>,
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
            segment_s: None,
            timeout: None,
            wait: true,
        }
    }
}

impl std::str::FromStr for WebOptions {
    type Err = anyhow::Error;
    /// Parses `listen=ADDR,fps=N,segment_s=S,timeout=S,wait=no` (any subset, any order; empty: the defaults).
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
                "segment_s" => o.segment_s = Some(within("segment_s", 0.01, MAX_SEGMENT_S)?),
                "timeout" => o.timeout = Some(within("timeout", 0.001, 1e6)?),
                "wait" => {
                    o.wait = match value {
                        "yes" | "true" => true,
                        "no" | "false" => false,
                        _ => bail!("web expert wait must be yes or no, got '{value}'"),
                    }
                }
                _ => bail!(
                    "unknown web expert option '{key}'; known: listen, fps, segment_s, timeout, wait"
                ),
            }
        }
        ensure!(
            o.segment_s.is_none() || o.fps.is_some(),
            "web expert segment_s (seconds of play per question) is for real time: give fps too (turn-based, \
             a question lasts segment_len steps, one per key)"
        );
        Ok(o)
    }
}

impl WebOptions {
    /// The options as the spec suffix that [`FromStr`](std::str::FromStr) reads back.
    pub fn to_spec(&self) -> String {
        let mut parts = vec![format!("listen={}", self.listen)];
        parts.extend(self.fps.map(|v| format!("fps={v}")));
        parts.extend(self.segment_s.map(|v| format!("segment_s={v}")));
        parts.extend(self.timeout.map(|v| format!("timeout={v}")));
        if !self.wait {
            parts.push("wait=no".into());
        }
        format!("web:{}", parts.join(","))
    }

    /// Real time: the steps one question's segment lasts, `segment_s` seconds of play at `fps` (rounded up;
    /// a product within 1e-9 of a whole number is that number); `None` turn-based.
    pub fn segment_steps(&self) -> Option<usize> {
        let fps = self.fps?;
        let steps = self.segment_s.unwrap_or(DEFAULT_SEGMENT_S) * fps;
        let whole = steps.round();
        let steps = if (steps - whole).abs() < 1e-9 {
            whole
        } else {
            steps.ceil()
        };
        // Both bounded by the parse: at most 600 s x 1000 fps.
        Some((steps as usize).max(1))
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
            "segment_s=2",
            "fps=10,segment_s=0",
            "fps=10,segment_s=601",
            "fps=10,segment_s=nan",
        ] {
            assert!(bad.parse::<WebOptions>().is_err(), "{bad} accepted");
        }
    }

    #[test]
    fn a_real_time_segment_lasts_its_seconds_of_play() {
        let steps = |spec: &str| spec.parse::<WebOptions>().unwrap().segment_steps();
        // Turn-based: no seconds; real time: DEFAULT_SEGMENT_S (3 s) of play, or segment_s, at fps, rounded up.
        assert_eq!(steps(""), None);
        assert_eq!(steps("fps=20"), Some(60));
        assert_eq!(steps("fps=20,segment_s=0.25"), Some(5));
        assert_eq!(steps("fps=30,segment_s=0.1"), Some(3));
        assert_eq!(steps("fps=7,segment_s=1.5"), Some(11));
        assert_eq!(steps("fps=0.5,segment_s=0.5"), Some(1));
        let o: WebOptions = "fps=20,segment_s=2.5".parse().unwrap();
        assert_eq!(
            o.to_spec(),
            "web:listen=127.0.0.1:8765,fps=20,segment_s=2.5"
        );
    }
}
