//! What the page shows of the environment: one [`FrameSource`] per kind of environment, side by side.
//!
//! - [`GeometryFrames`]: the built-in tasks, drawn by the page from their [`Geometry`](arld_core::env::Geometry)
//!   (a few hundred bytes a frame, crisp at any size);
//! - [`RenderedFrames`]: any environment that renders RGB images (Gymnasium's `render_mode="rgb_array"`),
//!   sent as PNG, and only when the picture changed;
//! - [`ObservationTable`]: any other environment, its observation as a labelled table (and a small chart of
//!   its recent values, drawn by the page).
//!
//! A source turns the environment's current state into the page's message ([`super::protocol::ServerMsg`]), or
//! into nothing when the page already shows that state.

use super::protocol::ServerMsg;
use anyhow::{Context, Result, ensure};
use arld_core::env::Env;
use arld_core::task::Action;
use base64::Engine;

/// The environment as the page shows it (of actions of kind `A`: every source shows either kind).
pub trait FrameSource<A: Action = usize>: Send {
    /// The message that shows the state of `env` (observation `obs`; empty when the caller has none at hand),
    /// or `None` when it would show what the page already has.
    fn frame(&mut self, env: &dyn Env<A>, obs: &[f32]) -> Result<Option<String>>;
    /// Whether the source draws the environment and observation it is given, so that it can show a copy of
    /// the environment (a replay of the agent's steps, the state after a key that may be undone). A source that
    /// asks the live environment for its picture cannot.
    fn shows_copies(&self) -> bool {
        false
    }
}

/// The built-in tasks: their geometry, drawn by the page.
pub struct GeometryFrames;

impl<A: Action> FrameSource<A> for GeometryFrames {
    fn shows_copies(&self) -> bool {
        true
    }
    fn frame(&mut self, env: &dyn Env<A>, obs: &[f32]) -> Result<Option<String>> {
        let geometry = env.geometry();
        Ok(Some(
            ServerMsg::Frame {
                geometry: geometry.as_ref(),
                obs,
            }
            .to_json(),
        ))
    }
}

/// An RGB image, row-major, 3 bytes a pixel.
pub struct RgbImage {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<u8>,
}

/// Renders the environment's current state as an image (a call into the environment's own renderer).
pub type Renderer = Box<dyn FnMut() -> Result<RgbImage> + Send>;

/// An environment that renders itself: its images as PNG, sent when they change.
pub struct RenderedFrames {
    render: Renderer,
    /// A hash of the last image sent.
    last: Option<u64>,
}

impl RenderedFrames {
    pub fn new(render: Renderer) -> Self {
        Self { render, last: None }
    }
}

impl<A: Action> FrameSource<A> for RenderedFrames {
    fn frame(&mut self, _env: &dyn Env<A>, _obs: &[f32]) -> Result<Option<String>> {
        let image = (self.render)().context("the environment could not render a frame")?;
        let hash = fnv1a(&image.pixels) ^ (u64::from(image.width) << 32 | u64::from(image.height));
        if self.last == Some(hash) {
            return Ok(None);
        }
        self.last = Some(hash);
        let png = encode_png(&image)?;
        let png = base64::engine::general_purpose::STANDARD.encode(png);
        Ok(Some(ServerMsg::Image { png: &png }.to_json()))
    }
}

/// Encodes `image` as PNG (fast compression: a frame must leave within a few milliseconds).
pub fn encode_png(image: &RgbImage) -> Result<Vec<u8>> {
    ensure!(
        image.width > 0
            && image.height > 0
            && image.pixels.len() == image.width as usize * image.height as usize * 3,
        "a rendered frame must be a non-empty height x width x 3 array of bytes (got {} bytes for {} x {})",
        image.pixels.len(),
        image.height,
        image.width
    );
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, image.width, image.height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::Fast);
    let mut writer = encoder.write_header()?;
    writer.write_image_data(&image.pixels)?;
    writer.finish()?;
    Ok(out)
}

/// FNV-1a: a cheap fingerprint of a frame (to tell whether it changed; not a defence against anything).
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

/// An environment without a picture: the observation as a labelled table.
pub struct ObservationTable {
    labels: Vec<String>,
    last: Vec<f32>,
}

impl ObservationTable {
    /// `labels`: one per observation value (`None`: `obs[0]`, `obs[1]`, ...).
    pub fn new(obs_dim: usize, labels: Option<Vec<String>>) -> Self {
        let labels = labels
            .filter(|l| l.len() == obs_dim)
            .unwrap_or_else(|| (0..obs_dim).map(|i| format!("obs[{i}]")).collect());
        Self {
            labels,
            last: Vec::new(),
        }
    }
}

impl<A: Action> FrameSource<A> for ObservationTable {
    fn shows_copies(&self) -> bool {
        true
    }
    fn frame(&mut self, _env: &dyn Env<A>, obs: &[f32]) -> Result<Option<String>> {
        if obs.is_empty() || obs == self.last.as_slice() {
            return Ok(None);
        }
        self.last = obs.to_vec();
        Ok(Some(
            ServerMsg::Table {
                labels: &self.labels,
                obs,
            }
            .to_json(),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_frames_decode_to_the_rendered_pixels() {
        let (w, h) = (7u32, 5u32);
        let pixels: Vec<u8> = (0..w * h * 3).map(|i| (i * 37 % 251) as u8).collect();
        let png = encode_png(&RgbImage {
            width: w,
            height: h,
            pixels: pixels.clone(),
        })
        .unwrap();
        let mut reader = png::Decoder::new(std::io::Cursor::new(png))
            .read_info()
            .unwrap();
        let mut buf = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height), (w, h));
        assert_eq!(&buf[..info.buffer_size()], &pixels[..]);
        let bad = RgbImage {
            width: 2,
            height: 2,
            pixels: vec![0; 11],
        };
        assert!(encode_png(&bad).is_err());
    }

    #[test]
    fn a_rendered_frame_is_sent_only_when_it_changed() {
        let env = arld_core::env::make("CartPole-v0").unwrap();
        let mut n = 0u8;
        let mut frames = RenderedFrames::new(Box::new(move || {
            n += 1;
            Ok(RgbImage {
                width: 1,
                height: 1,
                pixels: vec![n / 2, 0, 0],
            })
        }));
        let sent: Vec<bool> = (0..4)
            .map(|_| frames.frame(env.as_ref(), &[]).unwrap().is_some())
            .collect();
        // Pixels 0, 1, 1, 2: the third frame repeats the second.
        assert_eq!(sent, [true, true, false, true]);
        let mut table = ObservationTable::new(2, None);
        assert!(table.frame(env.as_ref(), &[1.0, 2.0]).unwrap().is_some());
        assert!(table.frame(env.as_ref(), &[1.0, 2.0]).unwrap().is_none());
        let msg = table.frame(env.as_ref(), &[1.0, 3.0]).unwrap().unwrap();
        assert!(msg.contains(r#""labels":["obs[0]","obs[1]"]"#), "{msg}");
    }
}
