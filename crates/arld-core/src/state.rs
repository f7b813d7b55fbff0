//! The state of a component as named raw arrays and small JSON values: what a run's snapshot is made of
//! (`train::snapshot` gathers one [`StateDict`] from every part of a run and writes it to disk).
//!
//! Components at every layer fill and read a `StateDict` through [`Persist`] (`save_state` / `load_state`) under
//! a prefix of their own (`agent.`, `replay.`, ...), so a snapshot knows nothing about their insides. Arrays stay
//! raw numbers (they become little-endian safetensors tensors), borrowed from the component while a snapshot
//! is written, so that writing one copies nothing; small values (counters, generator states) are JSON. Reading
//! checks every name, type and length: a damaged or foreign snapshot is an error, never a panic.

use serde::Serialize;
use serde::de::DeserializeOwned;
use std::borrow::Cow;
use std::collections::BTreeMap;

/// One array: its element type and its numbers, borrowed from a component (saving) or owned (read back).
#[derive(Debug, Clone, PartialEq)]
pub enum Array<'a> {
    F32(Cow<'a, [f32]>),
    F64(Cow<'a, [f64]>),
    U64(Cow<'a, [u64]>),
    U8(Cow<'a, [u8]>),
}

impl Array<'_> {
    pub(crate) fn type_name(&self) -> &'static str {
        match self {
            Array::F32(_) => "f32",
            Array::F64(_) => "f64",
            Array::U64(_) => "u64",
            Array::U8(_) => "u8",
        }
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        match self {
            Array::F32(v) => v.len(),
            Array::F64(v) => v.len(),
            Array::U64(v) => v.len(),
            Array::U8(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes of one element.
    pub(crate) fn element_bytes(&self) -> usize {
        match self {
            Array::F32(_) => 4,
            Array::F64(_) | Array::U64(_) => 8,
            Array::U8(_) => 1,
        }
    }
}

/// A missing, mistyped or misshapen entry.
#[derive(Debug, thiserror::Error)]
pub enum StateError {
    #[error("the snapshot has no `{0}`")]
    Missing(String),
    #[error("`{name}` in the snapshot is {found}, expected {expected}")]
    Type {
        name: String,
        found: &'static str,
        expected: &'static str,
    },
    #[error("`{name}` in the snapshot has {found} elements, expected {expected}")]
    Length {
        name: String,
        found: usize,
        expected: usize,
    },
    #[error("`{name}` in the snapshot cannot be read: {msg}")]
    Value { name: String, msg: String },
}

/// A component whose state goes into snapshots: it writes its arrays and values into a [`StateDict`] under names
/// that start with `prefix.`, and reads back what it wrote into a component built with the same configuration
/// (a mismatch is an error).
pub trait Persist {
    /// Writes the state into `state` under `prefix`, borrowing the arrays.
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>);
    /// Reads what [`Persist::save_state`] wrote.
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError>;
}

/// Named arrays and JSON values; `'a` is the life of the components whose arrays it borrows.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StateDict<'a> {
    pub arrays: BTreeMap<String, Array<'a>>,
    pub values: BTreeMap<String, serde_json::Value>,
}

macro_rules! typed_access {
    ($put:ident, $get:ident, $get_into:ident, $variant:ident, $t:ty, $name:literal) => {
        /// Stores an array: borrowed (`&[_]`, no copy) or owned (`Vec<_>`, e.g. numbers converted for the
        /// snapshot).
        pub fn $put(&mut self, name: &str, data: impl Into<Cow<'a, [$t]>>) {
            self.arrays
                .insert(name.to_string(), Array::$variant(data.into()));
        }

        pub fn $get(&self, name: &str) -> Result<&[$t], StateError> {
            match self.arrays.get(name) {
                None => Err(StateError::Missing(name.to_string())),
                Some(Array::$variant(v)) => Ok(v.as_ref()),
                Some(other) => Err(StateError::Type {
                    name: name.to_string(),
                    found: other.type_name(),
                    expected: $name,
                }),
            }
        }

        /// Copies the array into `out`, which must have its length.
        pub fn $get_into(&self, name: &str, out: &mut [$t]) -> Result<(), StateError> {
            let data = self.$get(name)?;
            if data.len() != out.len() {
                return Err(StateError::Length {
                    name: name.to_string(),
                    found: data.len(),
                    expected: out.len(),
                });
            }
            out.copy_from_slice(data);
            Ok(())
        }
    };
}

impl<'a> StateDict<'a> {
    typed_access!(put_f32, f32s, f32s_into, F32, f32, "f32");
    typed_access!(put_f64, f64s, f64s_into, F64, f64, "f64");
    typed_access!(put_u64, u64s, u64s_into, U64, u64, "u64");
    typed_access!(put_u8, u8s, u8s_into, U8, u8, "u8");

    /// Stores a small value as JSON.
    pub(crate) fn put_value<T: Serialize>(&mut self, name: &str, value: &T) {
        let json = serde_json::to_value(value).expect("state values serialise to JSON");
        self.values.insert(name.to_string(), json);
    }

    /// Reads a small value back.
    pub fn value<T: DeserializeOwned>(&self, name: &str) -> Result<T, StateError> {
        let json = self
            .values
            .get(name)
            .ok_or_else(|| StateError::Missing(name.to_string()))?;
        serde_json::from_value(json.clone()).map_err(|e| StateError::Value {
            name: name.to_string(),
            msg: e.to_string(),
        })
    }

    /// Stores a value that holds 128-bit integers (generator states), as JSON text: a JSON value tree cannot
    /// hold them, JSON text can.
    pub(crate) fn put_text<T: Serialize>(&mut self, name: &str, value: &T) {
        let text = serde_json::to_string(value).expect("state values serialise to JSON");
        self.put_value(name, &text);
    }

    /// Reads what `StateDict::put_text` stored.
    pub fn text<T: DeserializeOwned>(&self, name: &str) -> Result<T, StateError> {
        let text: String = self.value(name)?;
        serde_json::from_str(&text).map_err(|e| StateError::Value {
            name: name.to_string(),
            msg: e.to_string(),
        })
    }

    /// Total bytes of the arrays.
    pub fn array_bytes(&self) -> usize {
        self.arrays
            .values()
            .map(|a| a.len() * a.element_bytes())
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_round_trip_and_mismatches_are_named() {
        let mut s = StateDict::default();
        s.put_f32("a.w", &[1.0, -2.5][..]);
        s.put_value("a.step", &7u64);
        assert_eq!(s.f32s("a.w").unwrap(), &[1.0, -2.5]);
        assert_eq!(s.value::<u64>("a.step").unwrap(), 7);
        let mut three = [0.0f32; 3];
        let err = s.f32s_into("a.w", &mut three).unwrap_err();
        assert!(
            err.to_string().contains("has 2 elements, expected 3"),
            "{err}"
        );
        assert!(s.u64s("a.w").unwrap_err().to_string().contains("is f32"));
        assert!(s.f32s("b").unwrap_err().to_string().contains("no `b`"));
        assert_eq!(s.array_bytes(), 8);
    }
}
