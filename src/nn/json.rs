//! The tiny JSON subset used for metadata entries (`config.json`, `trainer.json`): one flat
//! object whose values are strings, numbers or booleans. Enough to read what we write and what
//! `json.dumps` writes for such a dict; anything nested is refused with a message.

use std::fmt::Write as _;

#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    Str(String),
    /// Kept as written, so integers (seeds, steps) round-trip without f64 rounding.
    Num(String),
    Bool(bool),
}

impl Value {
    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::Str(s) => Some(s),
            _ => None,
        }
    }
    pub fn as_u64(&self) -> Option<u64> {
        match self {
            Value::Num(s) => s.parse().ok(),
            Value::Str(s) => s.parse().ok(),
            _ => None,
        }
    }
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Value::Num(s) => s.parse().ok(),
            _ => None,
        }
    }
}

impl std::fmt::Display for Value {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Value::Str(s) => write!(f, "\"{s}\""),
            Value::Num(n) => f.write_str(n),
            Value::Bool(b) => write!(f, "{b}"),
        }
    }
}

/// A flat JSON object, keys in insertion order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Object(pub Vec<(String, Value)>);

impl Object {
    pub fn str(mut self, k: &str, v: &str) -> Self {
        self.0.push((k.into(), Value::Str(v.into())));
        self
    }
    pub fn num(mut self, k: &str, v: impl std::fmt::Display) -> Self {
        self.0.push((k.into(), Value::Num(v.to_string())));
        self
    }
    pub fn get(&self, k: &str) -> Option<&Value> {
        self.0.iter().find(|(n, _)| n == k).map(|(_, v)| v)
    }

    pub fn to_json(&self) -> String {
        let mut s = String::from("{");
        for (i, (k, v)) in self.0.iter().enumerate() {
            if i > 0 {
                s.push_str(", ");
            }
            write_str(&mut s, k);
            s.push_str(": ");
            match v {
                Value::Str(t) => write_str(&mut s, t),
                Value::Num(n) => s.push_str(n),
                Value::Bool(b) => s.push_str(if *b { "true" } else { "false" }),
            }
        }
        s.push('}');
        s
    }

    pub fn parse(text: &str) -> Result<Object, String> {
        let mut p = Parser { b: text.as_bytes(), i: 0 };
        p.ws();
        p.expect(b'{')?;
        let mut obj = Object::default();
        p.ws();
        if p.peek() == Some(b'}') {
            return Ok(obj);
        }
        loop {
            p.ws();
            let k = p.string()?;
            p.ws();
            p.expect(b':')?;
            p.ws();
            let v = match p.peek() {
                Some(b'"') => Value::Str(p.string()?),
                Some(b't') if p.b[p.i..].starts_with(b"true") => {
                    p.i += 4;
                    Value::Bool(true)
                }
                Some(b'f') if p.b[p.i..].starts_with(b"false") => {
                    p.i += 5;
                    Value::Bool(false)
                }
                Some(c) if c == b'-' || c.is_ascii_digit() => {
                    let st = p.i;
                    while p.peek().is_some_and(|c| b"+-.eE0123456789".contains(&c)) {
                        p.i += 1;
                    }
                    Value::Num(String::from_utf8_lossy(&p.b[st..p.i]).into_owned())
                }
                _ => return Err(format!("value of '{k}': only strings, numbers and booleans are supported")),
            };
            obj.0.push((k, v));
            p.ws();
            match p.peek() {
                Some(b',') => p.i += 1,
                Some(b'}') => return Ok(obj),
                _ => return Err(format!("expected ',' or '}}' at byte {}", p.i)),
            }
        }
    }
}

fn write_str(s: &mut String, t: &str) {
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

struct Parser<'a> {
    b: &'a [u8],
    i: usize,
}

impl Parser<'_> {
    fn peek(&self) -> Option<u8> {
        self.b.get(self.i).copied()
    }
    fn ws(&mut self) {
        while self.peek().is_some_and(|c| c.is_ascii_whitespace()) {
            self.i += 1;
        }
    }
    fn expect(&mut self, c: u8) -> Result<(), String> {
        if self.peek() == Some(c) {
            self.i += 1;
            Ok(())
        } else {
            Err(format!("expected '{}' at byte {}", c as char, self.i))
        }
    }
    fn string(&mut self) -> Result<String, String> {
        self.expect(b'"')?;
        let mut out = Vec::new();
        loop {
            match self.peek() {
                None => return Err("unterminated string".into()),
                Some(b'"') => {
                    self.i += 1;
                    return String::from_utf8(out).map_err(|_| "invalid UTF-8 in string".into());
                }
                Some(b'\\') => {
                    let e = self.b.get(self.i + 1).copied().ok_or("unterminated escape")?;
                    self.i += 2;
                    match e {
                        b'n' => out.push(b'\n'),
                        b't' => out.push(b'\t'),
                        b'u' => {
                            let hex = self.b.get(self.i..self.i + 4).ok_or("bad \\u escape")?;
                            let cp = u32::from_str_radix(std::str::from_utf8(hex).unwrap_or("x"), 16)
                                .map_err(|_| "bad \\u escape")?;
                            self.i += 4;
                            let ch = char::from_u32(cp).unwrap_or('\u{fffd}');
                            out.extend_from_slice(ch.to_string().as_bytes());
                        }
                        c => out.push(c),
                    }
                }
                Some(c) => {
                    out.push(c);
                    self.i += 1;
                }
            }
        }
    }
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
        assert!(Object::parse("{\"a\": [1]}").is_err());
    }
}
