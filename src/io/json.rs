//! JSON in and out: one reader (any nesting, what `json.dumps` writes) and one writer (strings
//! escaped), for every JSON file and `.npz` entry the crate reads or writes (`meta.json`,
//! `config.json`, `trainer.json`, `frames.json`, `params.json`, `metrics.json`,
//! `results.json`, `upscale.json`).
//!
//! Numbers are kept as text ([`Value::Num`]): integers (seeds, steps) round-trip without f64
//! rounding, and each writer picks the float format its file has always used — [`Value::num`]
//! (Rust's `Display`: `0.00000001`, `2`), [`Value::real`] (`Debug`, always with a decimal
//! point or exponent: `1.0`, `1e-5`) or [`Value::finite`] (`Display`, non-finite as `null`).
//!
//! ```
//! use anisocb::io::json::{Layout, Object, Value};
//!
//! let o = Object::new().str("name", "fl\"ag").num("seed", 3).val("size", Value::reals(&[1.0, 0.5]));
//! assert_eq!(o.to_json(), r#"{"name": "fl\"ag", "seed": 3, "size": [1.0, 0.5]}"#);
//! let back = Object::parse(&Value::from(o.clone()).to_json_with(Layout::Indented)).unwrap();
//! assert_eq!(back, o);
//! assert_eq!(back.get("seed").and_then(Value::as_u64), Some(3));
//! # Ok::<(), String>(())
//! ```

use crate::error::Result;
use std::fmt::Write as _;
use std::path::Path;

/// A JSON value. Objects keep their keys in insertion order.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    Null,
    Bool(bool),
    /// A number as written (see the module docs).
    Num(String),
    Str(String),
    Arr(Vec<Value>),
    Obj(Object),
}

/// A JSON object, keys in insertion order (a repeated key: [`Object::get`] finds the first).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Object(pub Vec<(String, Value)>);

/// How a value is laid out as text. Nested values are always compact.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// One line: `{"a": 1, "b": [1, 2]}`.
    Compact,
    /// The top level's entries one per line, indented by two spaces: `{\n  "a": 1\n}`.
    Indented,
    /// The top level's entries one per line, not indented: `[{"a": 1},\n{"a": 2}]`.
    Rows,
}

impl Value {
    /// A number written with `Display` (integers; floats as `0.00000001`, `2`).
    pub fn num(v: impl std::fmt::Display) -> Value {
        Value::Num(v.to_string())
    }

    /// A float written with `Debug` (`1.0`, `1e-5`: always recognisable as a float); non-finite
    /// values as `null`.
    pub fn real(v: f32) -> Value {
        if v.is_finite() {
            Value::Num(format!("{v:?}"))
        } else {
            Value::Null
        }
    }

    /// A float written with `Display`; non-finite values as `null`.
    pub fn finite(v: f32) -> Value {
        if v.is_finite() {
            Value::num(v)
        } else {
            Value::Null
        }
    }

    /// An array of [`Value::real`]s.
    pub fn reals(v: &[f32]) -> Value {
        Value::Arr(v.iter().map(|&x| Value::real(x)).collect())
    }

    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::Str(s) => Some(s),
            _ => None,
        }
    }

    /// A non-negative integer, also from a string holding one (`"seed": "42"`).
    pub fn as_u64(&self) -> Option<u64> {
        match self {
            Value::Num(s) | Value::Str(s) => s.parse().ok(),
            _ => None,
        }
    }

    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Value::Num(s) => s.parse().ok(),
            _ => None,
        }
    }

    pub fn as_bool(&self) -> Option<bool> {
        match self {
            Value::Bool(b) => Some(*b),
            _ => None,
        }
    }

    pub fn as_array(&self) -> Option<&[Value]> {
        match self {
            Value::Arr(v) => Some(v),
            _ => None,
        }
    }

    pub fn as_object(&self) -> Option<&Object> {
        match self {
            Value::Obj(o) => Some(o),
            _ => None,
        }
    }

    /// Member `key` of an object (None for other values).
    pub fn get(&self, key: &str) -> Option<&Value> {
        self.as_object().and_then(|o| o.get(key))
    }

    /// The value on one line.
    pub fn to_json(&self) -> String {
        compact(self)
    }

    pub fn to_json_with(&self, layout: Layout) -> String {
        let (open, sep, close) = match layout {
            Layout::Compact => return compact(self),
            Layout::Indented => ("\n  ", ",\n  ", "\n"),
            Layout::Rows => ("", ",\n", ""),
        };
        let (entries, brackets): (Vec<String>, _) = match self {
            Value::Arr(v) if !v.is_empty() => (v.iter().map(Value::to_json).collect(), ('[', ']')),
            Value::Obj(o) if !o.0.is_empty() => (o.0.iter().map(|(k, v)| member(k, v)).collect(), ('{', '}')),
            other => return compact(other),
        };
        let mut s = String::new();
        s.push(brackets.0);
        s.push_str(open);
        s.push_str(&entries.join(sep));
        s.push_str(close);
        s.push(brackets.1);
        s
    }

    /// Parse one JSON value (surrounding whitespace allowed, nothing else after it).
    pub fn parse(text: &str) -> crate::Result<Value> {
        super::json_parse::parse(text).map_err(crate::Error::Malformed)
    }

    /// [`Value::parse`] with the message alone (for parsers that add their own context).
    pub(crate) fn parse_str(text: &str) -> std::result::Result<Value, String> {
        super::json_parse::parse(text)
    }
}

impl std::fmt::Display for Value {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.to_json())
    }
}

impl From<bool> for Value {
    fn from(b: bool) -> Value {
        Value::Bool(b)
    }
}
impl From<&str> for Value {
    fn from(s: &str) -> Value {
        Value::Str(s.into())
    }
}
impl From<String> for Value {
    fn from(s: String) -> Value {
        Value::Str(s)
    }
}
impl From<Object> for Value {
    fn from(o: Object) -> Value {
        Value::Obj(o)
    }
}
impl From<Vec<Value>> for Value {
    fn from(v: Vec<Value>) -> Value {
        Value::Arr(v)
    }
}
impl<T: Into<Value>> From<Option<T>> for Value {
    fn from(v: Option<T>) -> Value {
        v.map_or(Value::Null, Into::into)
    }
}

impl Object {
    pub fn new() -> Object {
        Object::default()
    }

    /// Appends `key` with any value.
    pub fn val(mut self, key: &str, v: impl Into<Value>) -> Self {
        self.0.push((key.into(), v.into()));
        self
    }

    /// Appends a string member.
    pub fn str(self, key: &str, v: &str) -> Self {
        self.val(key, v)
    }

    /// Appends a number member written with `Display` ([`Value::num`]).
    pub fn num(self, key: &str, v: impl std::fmt::Display) -> Self {
        self.val(key, Value::num(v))
    }

    pub fn get(&self, key: &str) -> Option<&Value> {
        self.0.iter().find(|(n, _)| n == key).map(|(_, v)| v)
    }

    /// The object on one line.
    pub fn to_json(&self) -> String {
        let mut s = String::new();
        write_object(&mut s, self);
        s
    }

    /// Parse a JSON object (anything else is an error).
    pub fn parse(text: &str) -> crate::Result<Object> {
        Object::parse_str(text).map_err(crate::Error::Malformed)
    }

    /// [`Object::parse`] with the message alone (for parsers that add their own context).
    pub(crate) fn parse_str(text: &str) -> std::result::Result<Object, String> {
        match super::json_parse::parse(text)? {
            Value::Obj(o) => Ok(o),
            _ => Err("expected a JSON object".into()),
        }
    }
}

/// Write `v` to `path` atomically in `layout`, with a final newline.
pub fn write_json(path: &Path, v: &Value, layout: Layout) -> Result<()> {
    let mut text = v.to_json_with(layout);
    text.push('\n');
    super::write_atomic_bytes(path, text.as_bytes())
}

/// Read and parse the JSON file `path`; errors name the file.
pub fn read_json(path: &Path) -> Result<Value> {
    let text = String::from_utf8(super::read_bytes(path)?)
        .map_err(|_| crate::Error::format(path, "not UTF-8 text: a JSON file is UTF-8"))?;
    Value::parse(&text).map_err(|e| e.in_file(path))
}

// ---- writer ----

fn compact(v: &Value) -> String {
    let mut s = String::new();
    write_value(&mut s, v);
    s
}

fn member(k: &str, v: &Value) -> String {
    let mut s = String::new();
    write_string(&mut s, k);
    s.push_str(": ");
    write_value(&mut s, v);
    s
}

fn write_value(s: &mut String, v: &Value) {
    match v {
        Value::Null => s.push_str("null"),
        Value::Bool(b) => s.push_str(if *b { "true" } else { "false" }),
        Value::Num(n) => s.push_str(n),
        Value::Str(t) => write_string(s, t),
        Value::Arr(items) => {
            s.push('[');
            for (i, it) in items.iter().enumerate() {
                if i > 0 {
                    s.push_str(", ");
                }
                write_value(s, it);
            }
            s.push(']');
        }
        Value::Obj(o) => write_object(s, o),
    }
}

fn write_object(s: &mut String, o: &Object) {
    s.push('{');
    for (i, (k, v)) in o.0.iter().enumerate() {
        if i > 0 {
            s.push_str(", ");
        }
        s.push_str(&member(k, v));
    }
    s.push('}');
}

/// A string literal: `"` and `\` escaped, control characters as `\u00XX`, the rest as is.
fn write_string(s: &mut String, t: &str) {
    s.push('"');
    for c in t.chars() {
        match c {
            '"' => s.push_str("\\\""),
            '\\' => s.push_str("\\\\"),
            c if (c as u32) < 0x20 => {
                let _ = write!(s, "\\u{:04x}", c as u32);
            }
            c => s.push(c),
        }
    }
    s.push('"');
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flat_object_round_trips() {
        let o = Object::default().str("kind", "geo\"metry").num("channels", 64).num("seed", u64::MAX);
        let back = Object::parse(&o.to_json()).unwrap();
        assert_eq!(back, o);
        assert_eq!(back.get("seed").unwrap().as_u64(), Some(u64::MAX));
        let py = Object::parse("{\"a\": 1.5e-3, \"b\": true, \"c\": \"x\"}").unwrap();
        assert_eq!(py.get("a").unwrap().as_f64(), Some(1.5e-3));
        assert_eq!(py.get("b").unwrap().as_bool(), Some(true));
        assert!(Object::parse("[1]").is_err());
        // A run's meta.json as other tools write it (no space after ':').
        let t = Value::parse(r#"{"scenario": "flag", "seed":42, "dt": 0.005}"#).unwrap();
        assert_eq!(t.get("scenario").and_then(Value::as_str), Some("flag"));
        assert_eq!(t.get("seed").and_then(Value::as_u64), Some(42));
        assert_eq!(t.get("dt").and_then(Value::as_f64), Some(0.005));
        assert_eq!(t.get("missing"), None);
    }

    #[test]
    fn nested_values_parse_and_keys_are_not_found_in_nested_objects() {
        let v = Value::parse(
            r#" {"domain": {"bmin": [-1.5, 0, 2e-3], "seed": 9}, "tethers": false, "x": null,
                "s": "a\"b\\c\/\n\u00e9\ud83d\ude00", "seed": 3} "#,
        )
        .unwrap();
        assert_eq!(v.get("seed").and_then(Value::as_u64), Some(3));
        let d = v.get("domain").unwrap();
        assert_eq!(d.get("bmin").and_then(Value::as_array).map(|a| a.len()), Some(3));
        assert_eq!(d.get("bmin").unwrap().as_array().unwrap()[2].as_f64(), Some(2e-3));
        assert_eq!(v.get("x"), Some(&Value::Null));
        assert_eq!(v.get("s").and_then(Value::as_str), Some("a\"b\\c/\né😀"));
    }

    #[test]
    fn writer_escapes_and_lays_out() {
        let v = Value::Arr(vec![
            Object::new().str("run", "a\"b\\c\nd").val("seed", None::<Value>).into(),
            Object::new().val("t", true).val("xs", Value::reals(&[1.0, 1e-5])).into(),
        ]);
        let compact = r#"[{"run": "a\"b\\c\u000ad", "seed": null}, {"t": true, "xs": [1.0, 1e-5]}]"#;
        assert_eq!(v.to_json(), compact);
        assert_eq!(Value::parse(compact).unwrap(), v);
        let ind = v.to_json_with(Layout::Indented);
        assert!(ind.starts_with("[\n  {\"run\"") && ind.ends_with("]}\n]"), "{ind}");
        let rows = v.to_json_with(Layout::Rows);
        assert!(rows.starts_with("[{\"run\"") && rows.contains("null},\n{\"t\""), "{rows}");
        assert_eq!(Value::parse(&ind).unwrap(), v);
        assert_eq!(Value::parse(&rows).unwrap(), v);
        assert_eq!(Value::Arr(vec![]).to_json_with(Layout::Indented), "[]");
        assert_eq!(Value::finite(f32::NAN), Value::Null);
        assert_eq!(Value::num(1e-8f32).to_json(), "0.00000001");
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        for bad in [
            "",
            "{",
            "{\"a\": }",
            "{\"a\": 1,}",
            "[1 2]",
            "\"abc",
            "\"\\x\"",
            "\"\\u12\"",
            "1.",
            "-",
            "{} x",
            "{\"a\": [1]]",
        ] {
            assert!(Value::parse(bad).is_err(), "{bad:?} parsed");
        }
        let deep = "[".repeat(10_000);
        assert!(Value::parse(&deep).unwrap_err().to_string().contains("nested deeper"));
        assert_eq!(Value::parse("NaN").unwrap().as_f64().map(f64::is_nan), Some(true));
    }
}
