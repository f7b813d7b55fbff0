//! A minimal TensorBoard event-file writer for scalar curves.
//!
//! TensorBoard reads `events.out.tfevents.*` files: a sequence of TFRecord records, each holding one serialized
//! `tensorflow.Event` protocol buffer. We only ever write scalars, so the three messages involved (`Event`,
//! `Summary`, `Summary.Value`) are encoded by hand here (about forty lines) instead of pulling in a protobuf
//! code generator. Record framing: little-endian u64 length, masked CRC-32C of the length bytes, the payload,
//! masked CRC-32C of the payload.

use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

/// Appends scalar summaries to a TensorBoard event file.
pub(crate) struct EventWriter {
    out: BufWriter<File>,
    path: PathBuf,
}

impl EventWriter {
    /// Creates `dir/events.out.tfevents.<unix time>.arld` and writes the file-version header event.
    pub fn create(dir: &Path) -> std::io::Result<Self> {
        let secs = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map(|d| d.as_secs())
            .unwrap_or(0);
        let path = dir.join(format!("events.out.tfevents.{secs}.arld"));
        let mut writer = Self {
            out: BufWriter::new(crate::files::open_own_file(&path, true)?),
            path,
        };
        let mut event = Vec::with_capacity(32);
        put_f64_field(&mut event, 1, wall_time());
        put_bytes_field(&mut event, 3, b"brain.Event:2");
        writer.write_record(&event)?;
        Ok(writer)
    }

    /// Continues the event file at `path` from byte `len` (what was written before a snapshot); anything after
    /// it is cut off.
    pub(crate) fn reopen(path: &Path, len: u64) -> std::io::Result<Self> {
        let file = crate::files::open_own_file(path, false)?;
        file.set_len(len)?;
        let mut out = BufWriter::new(file);
        out.seek(std::io::SeekFrom::Start(len))?;
        Ok(Self {
            out,
            path: path.to_path_buf(),
        })
    }

    /// Bytes written so far (after a flush).
    pub fn position(&mut self) -> std::io::Result<u64> {
        self.out.flush()?;
        self.out.get_mut().stream_position()
    }

    /// Path of the event file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Writes one scalar value `tag` at `step`.
    pub fn scalar(&mut self, tag: &str, step: u64, value: f32) -> std::io::Result<()> {
        let mut value_msg = Vec::with_capacity(tag.len() + 8);
        put_bytes_field(&mut value_msg, 1, tag.as_bytes());
        put_f32_field(&mut value_msg, 2, value);
        let mut summary = Vec::with_capacity(value_msg.len() + 4);
        put_bytes_field(&mut summary, 1, &value_msg);
        let mut event = Vec::with_capacity(summary.len() + 24);
        put_f64_field(&mut event, 1, wall_time());
        put_varint_field(&mut event, 2, step);
        put_bytes_field(&mut event, 5, &summary);
        self.write_record(&event)
    }

    /// Flushes buffered records to the file.
    pub fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }

    fn write_record(&mut self, payload: &[u8]) -> std::io::Result<()> {
        let len = (payload.len() as u64).to_le_bytes();
        self.out.write_all(&len)?;
        self.out.write_all(&masked_crc32c(&len).to_le_bytes())?;
        self.out.write_all(payload)?;
        self.out.write_all(&masked_crc32c(payload).to_le_bytes())
    }
}

impl Drop for EventWriter {
    fn drop(&mut self) {
        let _ = self.out.flush();
    }
}

fn wall_time() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0)
}

/// TFRecord's checksum: CRC-32C, rotated right by 15 bits plus a constant.
pub(crate) fn masked_crc32c(data: &[u8]) -> u32 {
    let crc = crc32c::crc32c(data);
    crc.rotate_right(15).wrapping_add(0xa282_ead8)
}

fn put_varint(buf: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        buf.push((v as u8) | 0x80);
        v >>= 7;
    }
    buf.push(v as u8);
}

fn put_varint_field(buf: &mut Vec<u8>, field: u32, v: u64) {
    put_varint(buf, u64::from(field) << 3);
    put_varint(buf, v);
}

fn put_f64_field(buf: &mut Vec<u8>, field: u32, v: f64) {
    put_varint(buf, (u64::from(field) << 3) | 1);
    buf.extend_from_slice(&v.to_le_bytes());
}

fn put_f32_field(buf: &mut Vec<u8>, field: u32, v: f32) {
    put_varint(buf, (u64::from(field) << 3) | 5);
    buf.extend_from_slice(&v.to_le_bytes());
}

fn put_bytes_field(buf: &mut Vec<u8>, field: u32, bytes: &[u8]) {
    put_varint(buf, (u64::from(field) << 3) | 2);
    put_varint(buf, bytes.len() as u64);
    buf.extend_from_slice(bytes);
}

/// The longest event file read back (a run's is a few megabytes).
const MAX_EVENTS_FILE_BYTES: u64 = 1 << 30;

/// Reads back the scalars of an event file: (tag, step, value) in file order, checking every checksum.
/// Used by tests and by `arld report` to cross-check runs.
pub fn read_scalars(path: &Path) -> anyhow::Result<Vec<(String, u64, f32)>> {
    use anyhow::{bail, ensure};
    let data = crate::files::read_bounded(path, MAX_EVENTS_FILE_BYTES)?;
    let mut out = Vec::new();
    let mut pos = 0usize;
    while pos < data.len() {
        ensure!(
            pos + 12 <= data.len(),
            "truncated record header at byte {pos}"
        );
        let len_bytes = &data[pos..pos + 8];
        let len = u64::from_le_bytes(len_bytes.try_into()?) as usize;
        let crc = u32::from_le_bytes(data[pos + 8..pos + 12].try_into()?);
        ensure!(
            crc == masked_crc32c(len_bytes),
            "bad length checksum at byte {pos}"
        );
        let start = pos + 12;
        ensure!(
            start + len + 4 <= data.len(),
            "truncated record at byte {pos}"
        );
        let payload = &data[start..start + len];
        let crc = u32::from_le_bytes(data[start + len..start + len + 4].try_into()?);
        ensure!(
            crc == masked_crc32c(payload),
            "bad payload checksum at byte {pos}"
        );
        pos = start + len + 4;
        // Parse the Event: we need the step (2) and the summary (5).
        let mut step = 0u64;
        let mut summaries = Vec::new();
        for (field, value) in ProtoFields::new(payload) {
            match (field, value) {
                (2, ProtoValue::Varint(v)) => step = v,
                (5, ProtoValue::Bytes(b)) => summaries.push(b),
                (_, ProtoValue::Invalid) => bail!("malformed event at byte {pos}"),
                _ => {}
            }
        }
        for summary in summaries {
            for (field, value) in ProtoFields::new(summary) {
                if let (1, ProtoValue::Bytes(v)) = (field, value) {
                    let mut tag = String::new();
                    let mut scalar = None;
                    for (f, val) in ProtoFields::new(v) {
                        match (f, val) {
                            (1, ProtoValue::Bytes(t)) => {
                                tag = String::from_utf8_lossy(t).into_owned()
                            }
                            (2, ProtoValue::Fixed32(x)) => scalar = Some(f32::from_bits(x)),
                            _ => {}
                        }
                    }
                    if let Some(x) = scalar {
                        out.push((tag, step, x));
                    }
                }
            }
        }
    }
    Ok(out)
}

enum ProtoValue<'a> {
    Varint(u64),
    Fixed64,
    Fixed32(u32),
    Bytes(&'a [u8]),
    Invalid,
}

/// Iterates the (field number, value) pairs of a protobuf message.
struct ProtoFields<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> ProtoFields<'a> {
    fn new(data: &'a [u8]) -> Self {
        Self { data, pos: 0 }
    }
    fn varint(&mut self) -> Option<u64> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let b = *self.data.get(self.pos)?;
            self.pos += 1;
            v |= u64::from(b & 0x7f) << shift;
            if b < 0x80 {
                return Some(v);
            }
        }
        None
    }
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let s = self.data.get(self.pos..self.pos.checked_add(n)?)?;
        self.pos += n;
        Some(s)
    }
}

impl<'a> Iterator for ProtoFields<'a> {
    type Item = (u64, ProtoValue<'a>);
    fn next(&mut self) -> Option<Self::Item> {
        if self.pos >= self.data.len() {
            return None;
        }
        let Some(key) = self.varint() else {
            self.pos = self.data.len();
            return Some((0, ProtoValue::Invalid));
        };
        let value = match key & 7 {
            0 => self.varint().map(ProtoValue::Varint),
            1 => self.take(8).map(|_| ProtoValue::Fixed64),
            2 => self
                .varint()
                .and_then(|n| self.take(n as usize))
                .map(ProtoValue::Bytes),
            5 => self
                .take(4)
                .map(|b| ProtoValue::Fixed32(u32::from_le_bytes(b.try_into().unwrap()))),
            _ => None,
        };
        match value {
            Some(v) => Some((key >> 3, v)),
            None => {
                self.pos = self.data.len();
                Some((0, ProtoValue::Invalid))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32c_matches_the_standard_check_value() {
        // CRC-32C of the ASCII digits "123456789" is 0xE3069283 (RFC 3720, appendix B.4).
        assert_eq!(crc32c::crc32c(b"123456789"), 0xE306_9283);
    }

    #[test]
    fn scalars_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = EventWriter::create(dir.path()).unwrap();
        w.scalar("eval/mean_return", 1000, 12.5).unwrap();
        w.scalar("train/epsilon", 2000, 0.25).unwrap();
        let path = w.path().to_path_buf();
        drop(w);
        let got = read_scalars(&path).unwrap();
        assert_eq!(
            got,
            vec![
                ("eval/mean_return".to_string(), 1000, 12.5),
                ("train/epsilon".to_string(), 2000, 0.25)
            ]
        );
    }

    #[test]
    fn corrupted_file_is_rejected() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = EventWriter::create(dir.path()).unwrap();
        w.scalar("x", 1, 1.0).unwrap();
        let path = w.path().to_path_buf();
        drop(w);
        let mut bytes = std::fs::read(&path).unwrap();
        let n = bytes.len();
        bytes[n - 6] ^= 0xff;
        std::fs::write(&path, &bytes).unwrap();
        assert!(read_scalars(&path).is_err());
    }
}
