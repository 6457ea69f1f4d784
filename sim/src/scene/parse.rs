//! JSON parsing with the JSON path of every error.
//!
//! [`serde_path_to_error`] tracks the path through ordinary structs, maps and arrays, but serde's
//! derived internally tagged enums (`{"kind": "cuboid", ...}`) buffer their content and parse it
//! again out of sight of the tracker, so an unknown field inside `object` would only be reported
//! at `object`. The tagged enums of the scene ([`ObjectSpec`](super::ObjectSpec),
//! [`LampSpec`](super::LampSpec)) therefore implement `Deserialize` with
//! [`deserialize_tagged`]: it reads the object into a map, takes `kind`, and parses the rest with
//! a tracker of its own. A failure inside is handed outwards as a custom error whose message
//! carries the inner path between two [`NESTED`] markers; [`json_failure`] (at the top) joins the
//! outer and inner paths, so the user sees `object.widht: unknown field ...`.

use std::path::Path;

use serde::de::DeserializeOwned;
use serde_json::{Map, Value};

use super::SceneError;

/// Delimits an inner JSON path at the start of a custom error message. A control character
/// cannot occur in a JSON key unescaped and never occurs in serde's own messages.
const NESTED: char = '\u{1}';

/// A custom deserialisation error carrying an inner JSON path.
fn nested_error<E: serde::de::Error>(inner_path: &str, message: &str) -> E {
    E::custom(format!("{NESTED}{inner_path}{NESTED}{message}"))
}

/// Splits a message made by [`nested_error`] into (inner path, message).
fn split_nested(message: &str) -> Option<(&str, &str)> {
    let rest = message.strip_prefix(NESTED)?;
    rest.split_once(NESTED)
}

/// Joins an outer and an inner JSON path: `("lamps[1]", "power")` gives `"lamps[1].power"`,
/// `("object", "[0]")` gives `"object[0]"`. `"."` and `""` stand for the root.
fn join_paths(outer: &str, inner: &str) -> String {
    let outer = if outer == "." { "" } else { outer };
    let inner = if inner == "." { "" } else { inner };
    if outer.is_empty() {
        inner.to_owned()
    } else if inner.is_empty() {
        outer.to_owned()
    } else if inner.starts_with('[') {
        format!("{outer}{inner}")
    } else {
        format!("{outer}.{inner}")
    }
}

/// `"a", "b" or "c"` for error messages.
fn quoted_list(names: &[&str]) -> String {
    names.iter().map(|n| format!("{n:?}")).collect::<Vec<_>>().join(", ")
}

/// Reads an internally tagged object: returns the value of `"kind"` (one of `kinds`) and the
/// remaining fields. Errors carry the JSON path relative to the object.
pub(crate) fn deserialize_tagged<'de, D>(deserializer: D, kinds: &[&str]) -> Result<(String, Value), D::Error>
where
    D: serde::Deserializer<'de>,
{
    let mut map: Map<String, Value> = serde::Deserialize::deserialize(deserializer)?;
    match map.remove("kind") {
        None => Err(nested_error("", &format!("missing field `kind` (one of {})", quoted_list(kinds)))),
        Some(Value::String(kind)) if kinds.contains(&kind.as_str()) => Ok((kind, Value::Object(map))),
        Some(Value::String(kind)) => {
            Err(nested_error("kind", &format!("unknown variant {kind:?}, expected one of {}", quoted_list(kinds))))
        }
        Some(other) => Err(nested_error("kind", &format!("invalid type: {other}, expected a string"))),
    }
}

/// Parses `value` (the rest of a tagged object) as `T`, keeping the JSON path of any error.
pub(crate) fn from_value_tracked<T, E>(value: Value) -> Result<T, E>
where
    T: DeserializeOwned,
    E: serde::de::Error,
{
    serde_path_to_error::deserialize(value).map_err(|err| {
        let outer = err.path().to_string();
        // Errors of `serde_json::Value` carry no position, so the message is bare.
        let message = err.into_inner().to_string();
        match split_nested(&message) {
            Some((inner, message)) => nested_error(&join_paths(&outer, inner), message),
            None => nested_error(&join_paths(&outer, ""), &message),
        }
    })
}

/// Where and why a JSON text or value failed to parse as the type asked for.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct JsonFailure {
    /// JSON path of the value being parsed (`camera.width`, `lamps[0].kind`, `[1].power`);
    /// empty for the document itself.
    pub json_path: String,
    /// What went wrong, without the location.
    pub message: String,
    /// 1-based line of the error in the text (0 if unknown, e.g. when parsing a `Value`).
    pub line: usize,
    /// 1-based column of the error in the text (0 at the start of a line or if unknown).
    pub column: usize,
    /// The text is not JSON (a syntax error or an early end): `json_path` is only where the
    /// parser was, possibly with `?` for a key it had not read.
    pub syntax: bool,
}

/// Parses a complete JSON text as `T`, with the JSON path of any error. Like
/// `serde_json::from_str`, nothing but whitespace may follow the document.
pub(crate) fn parse_str_tracked<T: DeserializeOwned>(text: &str) -> Result<T, JsonFailure> {
    let mut de = serde_json::Deserializer::from_str(text);
    let value: T = serde_path_to_error::deserialize(&mut de).map_err(|err| {
        let outer = err.path().to_string();
        json_failure(&outer, err.into_inner())
    })?;
    de.end().map_err(|err| json_failure("", err))?;
    Ok(value)
}

/// Parses `value` as `T`, with the JSON path of any error below `prefix` (`""`: the root).
/// Lines and columns are unknown (0): a `Value` has forgotten them.
pub(crate) fn parse_value_tracked<T: DeserializeOwned>(value: Value, prefix: &str) -> Result<T, JsonFailure> {
    serde_path_to_error::deserialize(value).map_err(|err| {
        let outer = join_paths(prefix, &err.path().to_string());
        let mut failure = json_failure(&outer, err.into_inner());
        (failure.line, failure.column) = (0, 0);
        failure
    })
}

/// Parses a complete JSON document as `T` with JSON paths in errors.
pub(crate) fn parse_document<T: DeserializeOwned>(text: &str, file: Option<&Path>) -> Result<T, SceneError> {
    if text.trim().is_empty() {
        return Err(SceneError::Parse {
            path: file.map(Path::to_path_buf),
            json_path: String::new(),
            message: "the scene is empty: expected a JSON object".to_owned(),
            line: 1,
            column: 0,
        });
    }
    parse_str_tracked(text).map_err(|f| SceneError::Parse {
        path: file.map(Path::to_path_buf),
        json_path: f.json_path,
        message: f.message,
        line: f.line,
        column: f.column,
    })
}

/// Converts a `serde_json` error found at JSON path `outer` into a [`JsonFailure`].
fn json_failure(outer: &str, err: serde_json::Error) -> JsonFailure {
    let (line, column) = (err.line(), err.column());
    let syntax = matches!(err.classify(), serde_json::error::Category::Syntax | serde_json::error::Category::Eof);
    let mut message = err.to_string();
    // serde_json appends the position; the position has fields of its own.
    let suffix = format!(" at line {line} column {column}");
    if let Some(stripped) = message.strip_suffix(&suffix) {
        message = stripped.to_owned();
    }
    let (json_path, mut message) = match split_nested(&message) {
        Some((inner, msg)) => (join_paths(outer, inner), msg.to_owned()),
        None => (join_paths(outer, ""), message),
    };
    if message == "number out of range" {
        // serde_json refuses numbers such as 1e999 rather than reading them as infinity.
        message = "number out of range: must be finite (|x| < 1.8e308)".to_owned();
    }
    JsonFailure { json_path, message, line, column, syntax }
}

/// Implements `Deserialize` for an internally tagged enum whose variants are newtypes around
/// structs: `tagged_enum!(LampSpec { "uniform" => Uniform, "point" => Point })`.
macro_rules! tagged_enum {
    ($ty:ident { $($kind:literal => $variant:ident),+ $(,)? }) => {
        impl $ty {
            /// The accepted values of `kind`.
            pub const KINDS: &'static [&'static str] = &[$($kind),+];
        }

        impl<'de> serde::Deserialize<'de> for $ty {
            fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
                let (kind, rest) =
                    $crate::scene::parse::deserialize_tagged(deserializer, Self::KINDS)?;
                match kind.as_str() {
                    $($kind => $crate::scene::parse::from_value_tracked(rest).map($ty::$variant),)+
                    _ => Err(<D::Error as serde::de::Error>::custom(
                        "internal error: kind accepted but not handled (a bug)",
                    )),
                }
            }
        }
    };
}
pub(crate) use tagged_enum;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_join_like_serde_path_to_error() {
        assert_eq!(join_paths(".", "object"), "object");
        assert_eq!(join_paths("lamps[1]", "power"), "lamps[1].power");
        assert_eq!(join_paths("lamps[1]", "position[2]"), "lamps[1].position[2]");
        assert_eq!(join_paths("object", "[0]"), "object[0]");
        assert_eq!(join_paths("object", "."), "object");
        assert_eq!(join_paths("", ""), "");
    }

    #[test]
    fn nested_messages_round_trip() {
        let e: serde_json::Error = nested_error("a.b", "bad thing");
        assert_eq!(split_nested(&e.to_string()), Some(("a.b", "bad thing")));
        assert_eq!(split_nested("plain"), None);
    }
}
