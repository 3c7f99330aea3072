//! ROS 2 messages of any type, decoded at run time from the definition an MCAP
//! channel carries (schema encoding `ros2msg`): for the topics whose type
//! kinegen cannot know in advance, such as a robot's own range-bearing
//! detections. Fields are then picked by path (`detections[].range`).
//!
//! The definition text is parsed here: a line format (`type name`, constants,
//! `MSG: pkg/Type` sections). The bytes are read by the `cdr` crate's
//! deserializer (alignment, byte order, sizes), driven by the definition
//! through serde's `DeserializeSeed`, so no byte reading is written by hand.
//! (`ros2_message` 0.0.5, the crate for this, panics on valid definitions with
//! a `builtin_interfaces/Duration` field and calls itself untested.)
use serde::de::{self, DeserializeSeed, SeqAccess, Visitor};
use serde::Deserialize;
use std::collections::HashMap;
use std::fmt;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Prim {
    Bool,
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
    Str,
}

#[derive(Debug, Clone, PartialEq)]
enum Ty {
    Prim(Prim),
    /// A nested message, by full name (`pkg/msg/Name`).
    Msg(String),
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Arity {
    One,
    Fixed(usize),
    Seq,
}

#[derive(Debug, Clone)]
struct Field {
    name: String,
    ty: Ty,
    arity: Arity,
}

/// A message type and every type it uses, from a `ros2msg` definition.
#[derive(Debug, Clone)]
pub struct Schema {
    root: String,
    types: HashMap<String, Vec<Field>>,
}

/// A decoded value.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    Bool(bool),
    Int(i128),
    Float(f64),
    Text(String),
    List(Vec<Value>),
    Msg(Vec<(String, Value)>),
}

/// `pkg/Name` or `pkg/msg/Name` as `pkg/msg/Name`; a bare `Name` belongs to
/// `package` (`Header` is `std_msgs`'s, as in ROS 1 definitions).
fn full_name(name: &str, package: &str) -> String {
    let parts: Vec<&str> = name.split('/').collect();
    match parts.as_slice() {
        ["Header"] => "std_msgs/msg/Header".into(),
        [n] => format!("{package}/msg/{n}"),
        [p, n] => format!("{p}/msg/{n}"),
        _ => name.to_string(),
    }
}

fn prim(name: &str) -> Option<Prim> {
    // bounded strings (`string<=10`) are strings
    let base = name.split("<=").next().unwrap_or(name);
    Some(match base {
        "bool" => Prim::Bool,
        "int8" => Prim::I8,
        "byte" | "char" | "uint8" => Prim::U8,
        "int16" => Prim::I16,
        "uint16" => Prim::U16,
        "int32" => Prim::I32,
        "uint32" => Prim::U32,
        "int64" => Prim::I64,
        "uint64" => Prim::U64,
        "float32" => Prim::F32,
        "float64" => Prim::F64,
        "string" => Prim::Str,
        _ => return None,
    })
}

/// A message definition kinegen cannot read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SchemaError {
    #[error("definition line {line}: `{text}` is not `type name`")]
    NotAField { line: usize, text: String },
    #[error("definition line {line}: array size in `{ty}`")]
    ArraySize { line: usize, ty: String },
    #[error("definition line {0}: `wstring` fields are not supported")]
    WideString(usize),
    #[error("a section of the definition starts with `{0}`, not `MSG: pkg/Type`")]
    Section(String),
    #[error("`{0}` nests deeper than 32 levels (a type that contains itself?)")]
    TooDeep(String),
    #[error("the definition does not define `{0}`")]
    Undefined(String),
}

/// A message that does not decode by its schema.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    #[error("{0} bytes: not a CDR message")]
    TooShort(usize),
    #[error("unknown CDR encapsulation {0}")]
    Encapsulation(u8),
    /// The body, as the CDR reader says.
    #[error("{0}")]
    Body(String),
}

/// The fields of one message definition (`package` resolves bare type names).
fn parse_fields(text: &str, package: &str) -> Result<Vec<Field>, SchemaError> {
    let mut fields = Vec::new();
    for (n, raw) in text.lines().enumerate() {
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let mut words = line.split_whitespace();
        let (Some(ty), Some(rest)) = (words.next(), words.next()) else {
            return Err(SchemaError::NotAField {
                line: n + 1,
                text: raw.to_string(),
            });
        };
        // a constant (`int32 MAX=5`, `int32 MAX = 5`) is not in the message's bytes
        if rest.contains('=') || words.next() == Some("=") {
            continue;
        }
        let (base, arity) = match ty.find('[') {
            None => (ty, Arity::One),
            Some(i) => {
                let inside = ty[i + 1..].trim_end_matches(']');
                let arity = if inside.is_empty() || inside.starts_with("<=") {
                    Arity::Seq
                } else {
                    Arity::Fixed(inside.parse().map_err(|_| SchemaError::ArraySize {
                        line: n + 1,
                        ty: ty.to_string(),
                    })?)
                };
                (&ty[..i], arity)
            }
        };
        if base.starts_with("wstring") {
            return Err(SchemaError::WideString(n + 1));
        }
        let ty = match prim(base) {
            Some(p) => Ty::Prim(p),
            None if base == "time" || base == "duration" => {
                Ty::Msg(format!("builtin_interfaces/msg/{}", capitalise(base)))
            }
            None => Ty::Msg(full_name(base, package)),
        };
        fields.push(Field {
            name: rest.to_string(),
            ty,
            arity,
        });
    }
    Ok(fields)
}

fn capitalise(s: &str) -> String {
    let mut c = s.chars();
    c.next()
        .map(|f| f.to_uppercase().chain(c).collect())
        .unwrap_or_default()
}

impl Schema {
    /// Parse the definition of `name` (`pkg/msg/Name`) with the definitions of
    /// the types it uses, in sections after `====` lines headed `MSG: pkg/Type`.
    pub fn parse(name: &str, text: &str) -> Result<Schema, SchemaError> {
        let root = full_name(name, "");
        let package = |n: &str| n.split('/').next().unwrap_or("").to_string();
        let mut types = HashMap::new();
        let mut sections = text
            .split('\n')
            .fold(vec![String::new()], |mut acc, line| {
                if line.trim_start().starts_with("==") && line.trim().chars().all(|c| c == '=') {
                    acc.push(String::new());
                } else {
                    let s = acc.last_mut().unwrap();
                    s.push_str(line);
                    s.push('\n');
                }
                acc
            })
            .into_iter();
        let main = sections.next().unwrap_or_default();
        types.insert(root.clone(), parse_fields(&main, &package(&root))?);
        for s in sections {
            let s = s.trim_start();
            let Some(head) = s.lines().next() else {
                continue;
            };
            let Some(n) = head.trim().strip_prefix("MSG:") else {
                return Err(SchemaError::Section(head.to_string()));
            };
            let n = full_name(n.trim(), "");
            let body = &s[head.len()..];
            types.insert(n.clone(), parse_fields(body, &package(&n))?);
        }
        for (n, def) in [
            ("builtin_interfaces/msg/Time", "int32 sec\nuint32 nanosec"),
            (
                "builtin_interfaces/msg/Duration",
                "int32 sec\nuint32 nanosec",
            ),
        ] {
            types
                .entry(n.to_string())
                .or_insert_with(|| parse_fields(def, "builtin_interfaces").unwrap());
        }
        let schema = Schema { root, types };
        schema.check(&schema.root, 0)?;
        Ok(schema)
    }

    /// Every nested type is defined, and none contains itself.
    fn check(&self, name: &str, depth: usize) -> Result<(), SchemaError> {
        if depth > 32 {
            return Err(SchemaError::TooDeep(name.to_string()));
        }
        let fields = self
            .types
            .get(name)
            .ok_or_else(|| SchemaError::Undefined(name.to_string()))?;
        for f in fields {
            if let Ty::Msg(m) = &f.ty {
                self.check(m, depth + 1)?;
            }
        }
        Ok(())
    }

    /// Decode one CDR message (4-byte encapsulation header, then the body).
    pub fn decode(&self, data: &[u8]) -> Result<Value, DecodeError> {
        let Some((head, body)) = data.split_at_checked(4) else {
            return Err(DecodeError::TooShort(data.len()));
        };
        let budget = Budget::for_message(body.len());
        let root = Ty::Msg(self.root.clone());
        let seed = Elem {
            schema: self,
            ty: &root,
            limit: body.len(),
            budget: &budget,
        };
        let limit = cdr::Bounded(body.len() as u64);
        let value = match head[1] {
            0 | 2 => seed.deserialize(&mut cdr::Deserializer::<_, _, cdr::BigEndian>::new(
                body, limit,
            )),
            1 | 3 => seed.deserialize(&mut cdr::Deserializer::<_, _, cdr::LittleEndian>::new(
                body, limit,
            )),
            k => return Err(DecodeError::Encapsulation(k)),
        };
        value.map_err(|e| DecodeError::Body(e.to_string()))
    }
}

/// One value of type `ty`. `limit`: the message's length in bytes, which
/// no sequence in it can have more elements than (an element that takes no
/// bytes, a message of empty fixed arrays, would otherwise let a corrupt
/// length of 0xFFFFFFFF fill memory).
struct Elem<'a> {
    schema: &'a Schema,
    ty: &'a Ty,
    limit: usize,
    budget: &'a Budget,
}

/// How many values one message may still decode into, shared by all its
/// arrays: [`VALUES_PER_BYTE`] per byte of the message. Each array alone is
/// bounded by the message's length, but nested arrays of elements that take
/// no bytes (40,000 of 1,000,000 empty arrays each, in 2.6 MB) multiply those
/// bounds; this bounds their product, so a message's values (and memory)
/// stay a fixed multiple of its size.
struct Budget {
    left: std::cell::Cell<usize>,
    of: usize,
}

/// Values a message may decode into per byte: a value of real data takes at
/// least one byte, so honest messages stay far below; elements that take
/// none get this much slack before the message is refused.
const VALUES_PER_BYTE: usize = 8;

impl Budget {
    fn for_message(bytes: usize) -> Budget {
        let of = VALUES_PER_BYTE * bytes.max(16);
        Budget {
            left: std::cell::Cell::new(of),
            of,
        }
    }

    fn take<E: de::Error>(&self) -> Result<(), E> {
        match self.left.get().checked_sub(1) {
            Some(left) => {
                self.left.set(left);
                Ok(())
            }
            None => Err(E::custom(format!(
                "more than {} values in one message ({VALUES_PER_BYTE} per byte): nested arrays of a corrupt or hostile length",
                self.of
            ))),
        }
    }
}

/// A field: one value, a fixed array or a sequence.
struct Slot<'a> {
    schema: &'a Schema,
    field: &'a Field,
    limit: usize,
    budget: &'a Budget,
}

struct Fields<'a> {
    schema: &'a Schema,
    fields: &'a [Field],
    limit: usize,
    budget: &'a Budget,
}

struct List<'a> {
    elem: Elem<'a>,
}

impl<'de> DeserializeSeed<'de> for Elem<'_> {
    type Value = Value;
    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<Value, D::Error> {
        use Prim::*;
        self.budget.take()?;
        Ok(match self.ty {
            Ty::Prim(Bool) => Value::Bool(bool::deserialize(d)?),
            Ty::Prim(I8) => Value::Int(i8::deserialize(d)?.into()),
            Ty::Prim(U8) => Value::Int(u8::deserialize(d)?.into()),
            Ty::Prim(I16) => Value::Int(i16::deserialize(d)?.into()),
            Ty::Prim(U16) => Value::Int(u16::deserialize(d)?.into()),
            Ty::Prim(I32) => Value::Int(i32::deserialize(d)?.into()),
            Ty::Prim(U32) => Value::Int(u32::deserialize(d)?.into()),
            Ty::Prim(I64) => Value::Int(i64::deserialize(d)?.into()),
            Ty::Prim(U64) => Value::Int(u64::deserialize(d)?.into()),
            Ty::Prim(F32) => Value::Float(f32::deserialize(d)?.into()),
            Ty::Prim(F64) => Value::Float(f64::deserialize(d)?),
            // the length read here, the bytes one at a time: the cdr crate's own
            // string reader reserves the (untrusted) length before checking it
            // against the message, so a corrupt one would allocate gigabytes
            Ty::Prim(Str) => Value::Text(d.deserialize_tuple(2, CdrString)?),
            Ty::Msg(name) => {
                let fields = &self.schema.types[name];
                if fields.is_empty() {
                    // ROS 2 gives an empty message one byte
                    u8::deserialize(d)?;
                    Value::Msg(Vec::new())
                } else {
                    d.deserialize_tuple(
                        fields.len(),
                        Fields {
                            schema: self.schema,
                            fields,
                            limit: self.limit,
                            budget: self.budget,
                        },
                    )?
                }
            }
        })
    }
}

impl<'de> DeserializeSeed<'de> for Slot<'_> {
    type Value = Value;
    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<Value, D::Error> {
        let elem = Elem {
            schema: self.schema,
            ty: &self.field.ty,
            limit: self.limit,
            budget: self.budget,
        };
        match self.field.arity {
            Arity::One => elem.deserialize(d),
            Arity::Fixed(n) => d.deserialize_tuple(n, List { elem }),
            Arity::Seq => d.deserialize_seq(List { elem }),
        }
    }
}

impl<'de> Visitor<'de> for Fields<'_> {
    type Value = Value;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "a message of {} fields", self.fields.len())
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Value, A::Error> {
        let mut out = Vec::with_capacity(self.fields.len());
        for field in self.fields {
            let v = seq
                .next_element_seed(Slot {
                    schema: self.schema,
                    field,
                    limit: self.limit,
                    budget: self.budget,
                })?
                .ok_or_else(|| de::Error::custom(format!("field `{}` missing", field.name)))?;
            out.push((field.name.clone(), v));
        }
        Ok(Value::Msg(out))
    }
}

impl<'de> Visitor<'de> for List<'_> {
    type Value = Value;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "an array")
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Value, A::Error> {
        // no capacity from the length prefix: a corrupt one would reserve
        // gigabytes; the size limit stops reading at the end of the message
        let mut out = Vec::new();
        while let Some(v) = seq.next_element_seed(Elem {
            schema: self.elem.schema,
            ty: self.elem.ty,
            limit: self.elem.limit,
            budget: self.elem.budget,
        })? {
            if out.len() >= self.elem.limit {
                return Err(de::Error::custom(format!(
                    "an array of more elements than the message has bytes ({}): a corrupt length",
                    self.elem.limit
                )));
            }
            out.push(v);
        }
        Ok(Value::List(out))
    }
}

/// A CDR string: a u32 length (with the terminating NUL), then the bytes.
struct CdrString;

/// A CDR string field of a serde type (`#[serde(deserialize_with)]`), read
/// as [`CdrString`] does: never the cdr crate's reader, which reserves an
/// untrusted length first.
pub fn cdr_string<'de, D: de::Deserializer<'de>>(d: D) -> Result<String, D::Error> {
    d.deserialize_tuple(2, CdrString)
}

/// A CDR sequence of strings (`string[]`), each as [`cdr_string`].
pub fn cdr_strings<'de, D: de::Deserializer<'de>>(d: D) -> Result<Vec<String>, D::Error> {
    struct Strings;
    struct One;
    impl<'de> DeserializeSeed<'de> for One {
        type Value = String;
        fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<String, D::Error> {
            cdr_string(d)
        }
    }
    impl<'de> Visitor<'de> for Strings {
        type Value = Vec<String>;
        fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
            write!(f, "a sequence of strings")
        }
        fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Vec<String>, A::Error> {
            let mut out = Vec::new();
            while let Some(s) = seq.next_element_seed(One)? {
                out.push(s);
            }
            Ok(out)
        }
    }
    d.deserialize_seq(Strings)
}

/// `n` bytes, each checked against the end of the message as it is read.
struct Bytes(usize);

impl<'de> Visitor<'de> for CdrString {
    type Value = String;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "a string")
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<String, A::Error> {
        let len: u32 = seq
            .next_element()?
            .ok_or_else(|| de::Error::custom("string length missing"))?;
        let mut bytes: Vec<u8> = seq
            .next_element_seed(Bytes(len as usize))?
            .ok_or_else(|| de::Error::custom("string bytes missing"))?;
        if bytes.last() == Some(&0) {
            bytes.pop();
        }
        String::from_utf8(bytes).map_err(|_| de::Error::custom("a string is not UTF-8"))
    }
}

impl<'de> DeserializeSeed<'de> for Bytes {
    type Value = Vec<u8>;
    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<Vec<u8>, D::Error> {
        d.deserialize_tuple(self.0, self)
    }
}

impl<'de> Visitor<'de> for Bytes {
    type Value = Vec<u8>;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "{} bytes", self.0)
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Vec<u8>, A::Error> {
        let mut out = Vec::new();
        while let Some(b) = seq.next_element::<u8>()? {
            out.push(b);
        }
        Ok(out)
    }
}

/// One step of a field path: a field, optionally every element (`[]`) or one
/// element (`[k]`) of it.
#[derive(Debug, Clone, PartialEq)]
enum Step {
    Field(String),
    Each,
    At(usize),
}

/// A field path such as `header.stamp.sec`, `ranges[]` or
/// `detections[].pose.position.x`, with at most one `[]`.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldPath {
    text: String,
    steps: Vec<Step>,
}

/// A field path that is not one, or that a message does not have. Each
/// names the path as the user wrote it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PathError {
    #[error("`{path}`: `{part}` is not a field name")]
    FieldName { path: String, part: String },
    #[error("`{path}`: `{rest}` is not `[]` or `[index]`")]
    Brackets { path: String, rest: String },
    #[error("`{path}`: `[{inside}]` is not an index")]
    Index { path: String, inside: String },
    #[error("`{0}`: at most one `[]` per path")]
    SeveralEach(String),
    /// `at` is the part of the path that was found ("" for the message).
    #[error("`{path}`: {} has no field `{field}` (it has: {})", if at.is_empty() { "the message".to_string() } else { format!("`{at}`") }, has.join(", "))]
    NoField {
        path: String,
        at: String,
        field: String,
        has: Vec<String>,
    },
    #[error("`{path}`: `{at}` has {len} elements, no [{index}]")]
    OutOfRange {
        path: String,
        at: String,
        len: usize,
        index: usize,
    },
    #[error("`{path}`: `{at}` is not a message, so it has no field `{field}`")]
    NotMessage {
        path: String,
        at: String,
        field: String,
    },
    #[error("`{path}`: `{at}` is not an array")]
    NotArray { path: String, at: String },
}

impl FieldPath {
    pub fn parse(text: &str) -> Result<FieldPath, PathError> {
        let mut steps = Vec::new();
        for part in text.split('.') {
            let (name, mut rest) = part.split_at(part.find('[').unwrap_or(part.len()));
            if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
                return Err(PathError::FieldName {
                    path: text.to_string(),
                    part: part.to_string(),
                });
            }
            steps.push(Step::Field(name.to_string()));
            while !rest.is_empty() {
                let Some(end) = rest.find(']').filter(|_| rest.starts_with('[')) else {
                    return Err(PathError::Brackets {
                        path: text.to_string(),
                        rest: rest.to_string(),
                    });
                };
                let inside = &rest[1..end];
                steps.push(if inside.is_empty() {
                    Step::Each
                } else {
                    Step::At(inside.parse().map_err(|_| PathError::Index {
                        path: text.to_string(),
                        inside: inside.to_string(),
                    })?)
                });
                rest = &rest[end + 1..];
            }
        }
        if steps.iter().filter(|s| **s == Step::Each).count() > 1 {
            return Err(PathError::SeveralEach(text.to_string()));
        }
        Ok(FieldPath {
            text: text.to_string(),
            steps,
        })
    }

    pub fn has_each(&self) -> bool {
        self.steps.contains(&Step::Each)
    }

    /// The values at this path (several with `[]`).
    pub fn values<'v>(&self, v: &'v Value) -> Result<Vec<&'v Value>, PathError> {
        let mut cur = vec![v];
        for (i, step) in self.steps.iter().enumerate() {
            let shown = || {
                let done: Vec<String> = self.steps[..i]
                    .iter()
                    .map(|s| match s {
                        Step::Field(f) => format!(".{f}"),
                        Step::Each => "[]".into(),
                        Step::At(k) => format!("[{k}]"),
                    })
                    .collect();
                let s = done.concat();
                s.trim_start_matches('.').to_string()
            };
            let mut next = Vec::with_capacity(cur.len());
            for v in cur {
                match (step, v) {
                    (Step::Field(f), Value::Msg(fields)) => {
                        match fields.iter().find(|(n, _)| n == f) {
                            Some((_, x)) => next.push(x),
                            None => {
                                return Err(PathError::NoField {
                                    path: self.text.clone(),
                                    at: shown(),
                                    field: f.clone(),
                                    has: fields.iter().map(|(n, _)| n.clone()).collect(),
                                });
                            }
                        }
                    }
                    (Step::Each, Value::List(items)) => next.extend(items.iter()),
                    (Step::At(k), Value::List(items)) => {
                        next.push(items.get(*k).ok_or_else(|| PathError::OutOfRange {
                            path: self.text.clone(),
                            at: shown(),
                            len: items.len(),
                            index: *k,
                        })?)
                    }
                    (Step::Field(f), _) => {
                        return Err(PathError::NotMessage {
                            path: self.text.clone(),
                            at: shown(),
                            field: f.clone(),
                        })
                    }
                    (_, _) => {
                        return Err(PathError::NotArray {
                            path: self.text.clone(),
                            at: shown(),
                        })
                    }
                }
            }
            cur = next;
        }
        Ok(cur)
    }

    pub fn text(&self) -> &str {
        &self.text
    }
}

impl Value {
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Value::Float(x) => Some(*x),
            Value::Int(i) => Some(*i as f64),
            _ => None,
        }
    }

    /// An identifier: text as it is, an integer in decimal.
    pub fn as_id(&self) -> Option<String> {
        match self {
            Value::Text(s) => Some(s.clone()),
            Value::Int(i) => Some(i.to_string()),
            _ => None,
        }
    }

    /// `builtin_interfaces/Time` in seconds.
    pub fn as_time(&self) -> Option<f64> {
        let Value::Msg(f) = self else { return None };
        let get = |n: &str| f.iter().find(|(k, _)| k == n).and_then(|(_, v)| v.as_f64());
        Some(get("sec")? + get("nanosec")? * 1e-9)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DEF: &str =
        "std_msgs/Header header\nDetection[] detections\nfloat32[3] extra\nint32 MAX=3\n\
================================================================================\n\
MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n\
================================================================================\n\
MSG: my_msgs/Detection\nuint16 id # the tag\nfloat64 range\nfloat64 bearing\n";

    /// CDR little-endian bytes of the message above, written by the `cdr`
    /// crate's serializer from plain Rust types with the same layout.
    fn bytes() -> Vec<u8> {
        #[derive(serde::Serialize)]
        struct Time(i32, u32);
        #[derive(serde::Serialize)]
        struct Header(Time, String);
        #[derive(serde::Serialize)]
        struct Det(u16, f64, f64);
        #[derive(serde::Serialize)]
        struct Msg(Header, Vec<Det>, [f32; 3]);
        let m = Msg(
            Header(Time(12, 500_000_000), "base".into()),
            vec![Det(7, 2.5, 0.25), Det(9, 4.0, -1.0)],
            [1.0, 2.0, 3.0],
        );
        cdr::serialize::<_, _, cdr::CdrLe>(&m, cdr::Infinite).unwrap()
    }

    #[test]
    fn decodes_a_user_message_and_picks_fields_by_path() {
        let s = Schema::parse("my_msgs/msg/Detections", DEF).unwrap();
        let v = s.decode(&bytes()).unwrap();
        let p = |t: &str| FieldPath::parse(t).unwrap();
        let stamp = p("header.stamp").values(&v).unwrap()[0].as_time().unwrap();
        assert_eq!(stamp, 12.5);
        let ids: Vec<String> = p("detections[].id")
            .values(&v)
            .unwrap()
            .iter()
            .map(|x| x.as_id().unwrap())
            .collect();
        assert_eq!(ids, ["7", "9"]);
        let r: Vec<f64> = p("detections[].range")
            .values(&v)
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert_eq!(r, [2.5, 4.0]);
        assert_eq!(p("extra[2]").values(&v).unwrap()[0].as_f64(), Some(3.0));
        let e = p("detections[].rng").values(&v).unwrap_err();
        assert!(
            matches!(&e, PathError::NoField { field, .. } if field == "rng"),
            "{e}"
        );
        assert!(
            e.to_string()
                .contains("no field `rng` (it has: id, range, bearing)"),
            "{e}"
        );
        // a truncated message is an error, not a panic or a short answer
        let b = bytes();
        assert!(s.decode(&b[..b.len() - 5]).is_err());
    }

    /// Corrupt messages (random bytes, every truncation, flipped bytes) are
    /// errors or values, never a panic or a hang: lengths come from the data.
    #[test]
    fn corrupt_bytes_never_panic() {
        let s = Schema::parse("my_msgs/msg/Detections", DEF).unwrap();
        let good = bytes();
        for cut in 0..good.len() {
            let _ = s.decode(&good[..cut]);
        }
        let mut seed = 1u64;
        for _ in 0..2000 {
            let mut b = good.clone();
            for _ in 0..3 {
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
                let i = (seed >> 33) as usize % b.len();
                b[i] = (seed >> 13) as u8;
            }
            let _ = s.decode(&b);
        }
    }

    /// A corrupt string length (4 GB) in a message kinegen decodes with its
    /// serde types is an error at once, with nothing reserved for it.
    #[test]
    fn a_corrupt_string_length_is_refused_without_reserving_it() {
        let mut b = vec![0u8, 1, 0, 0]; // CDR, little-endian
        b.extend(12i32.to_le_bytes()); // stamp.sec
        b.extend(5u32.to_le_bytes()); // stamp.nanosec
        b.extend(0xffff_fff0u32.to_le_bytes()); // frame_id length
        b.extend(b"base\0");
        let t0 = std::time::Instant::now();
        assert!(crate::logs::rosmsg::decode::<crate::logs::rosmsg::Header>(&b).is_err());
        assert!(t0.elapsed().as_secs_f64() < 0.5, "{:?}", t0.elapsed());
        b[12..16].copy_from_slice(&5u32.to_le_bytes());
        let h: crate::logs::rosmsg::Header = crate::logs::rosmsg::decode(&b).unwrap();
        assert_eq!(h.frame_id, "base");
    }

    /// Issue #37.2: a sequence of 0xFFFFFFFF elements that take no bytes (a
    /// message of empty fixed arrays) is refused at once; it filled memory
    /// until the process aborted.
    #[test]
    fn a_sequence_of_empty_elements_cannot_fill_memory() {
        let def = "my_msgs/Nothing[] items\n\
================================================================================\n\
MSG: my_msgs/Nothing\nfloat64[0] none\n";
        let s = Schema::parse("my_msgs/msg/Many", def).unwrap();
        let mut b = vec![0u8, 1, 0, 0];
        b.extend(0xffff_ffffu32.to_le_bytes());
        let t0 = std::time::Instant::now();
        let e = s.decode(&b).unwrap_err();
        assert!(e.to_string().contains("corrupt length"), "{e}");
        assert!(t0.elapsed().as_secs_f64() < 0.5, "{:?}", t0.elapsed());
        // an honest empty sequence still decodes
        let mut ok = vec![0u8, 1, 0, 0];
        ok.extend(0u32.to_le_bytes());
        assert!(s.decode(&ok).is_ok());
    }

    /// Issue #67.2: nested sequences of elements that take no bytes pass
    /// each array's own bound (no more elements than the message has bytes)
    /// but multiply: 1,000 sequences of 1,000 empty elements in 4 kB (40,000
    /// of 1,000,000 in a 2.6 MB bag exhausted any memory). The message's
    /// values are bounded by a multiple of its size, so it is refused.
    #[test]
    fn nested_sequences_of_empty_elements_cannot_multiply_past_the_message() {
        let def = "my_msgs/Inner[] items\n\
================================================================================\n\
MSG: my_msgs/Inner\nmy_msgs/Nothing[] nothings\n\
================================================================================\n\
MSG: my_msgs/Nothing\nfloat64[0] none\n";
        let s = Schema::parse("my_msgs/msg/Nested", def).unwrap();
        let message = |outer: u32, inner: u32| {
            let mut b = vec![0u8, 1, 0, 0];
            b.extend(outer.to_le_bytes());
            for _ in 0..outer {
                b.extend(inner.to_le_bytes());
            }
            b
        };
        let e = s.decode(&message(1000, 1000)).unwrap_err();
        assert!(e.to_string().contains("values in one message"), "{e}");
        // an honest nesting of the same shape decodes
        assert!(s.decode(&message(1000, 3)).is_ok());
    }

    #[test]
    fn bad_definitions_and_paths_are_refused() {
        assert_eq!(
            Schema::parse("a/msg/B", "Missing m\n").unwrap_err(),
            SchemaError::Undefined("a/msg/Missing".into())
        );
        assert!(matches!(
            Schema::parse("a/msg/B", "B b\n").unwrap_err(),
            SchemaError::TooDeep(_)
        ));
        assert!(FieldPath::parse("a[].b[]").is_err());
        assert!(FieldPath::parse("a[x]").is_err());
        assert!(FieldPath::parse("").is_err());
    }
}
