//! Strict decoding of config text, shared by every config dialect (the project's TOML and
//! JSON, PhysGaussian's and PhysFlow's scene JSON, `r4d prepare`'s preprocessing keys, the fit
//! settings): one set of rules, one wording.
//!
//! * The document must be a table of keys (a TOML document or a JSON object): `[]`, a number
//!   or a string is refused.
//! * A key given twice in one table is an error naming the key (JSON parsers usually keep the
//!   last; TOML refuses it by its grammar).
//! * An unknown key at any depth is an error naming its path (`solver.gravty`,
//!   `boundary[1].strat_time`) with the closest known key by edit distance ("did you mean
//!   `gravity`?"); an unknown enum value (`material = "jely"`) likewise.

use serde::de::{DeserializeOwned, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::Serialize;
use serde_json::{Map, Number, Value};
use std::fmt;
use std::path::Path;

/// The syntax of a config file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// JSON.
    Json,
    /// TOML.
    Toml,
}

impl Format {
    /// JSON for a `.json` extension, TOML otherwise (the project's rule for `--config`).
    pub fn of_path(path: &Path) -> Format {
        if path.extension().and_then(|e| e.to_str()) == Some("json") {
            Format::Json
        } else {
            Format::Toml
        }
    }
}

/// A JSON value read with duplicate keys refused.
struct StrictValue(Value);

impl<'de> serde::Deserialize<'de> for StrictValue {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(StrictVisitor).map(StrictValue)
    }
}

struct StrictVisitor;

impl<'de> Visitor<'de> for StrictVisitor {
    type Value = Value;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a JSON value")
    }
    fn visit_bool<E>(self, v: bool) -> Result<Value, E> {
        Ok(Value::Bool(v))
    }
    fn visit_i64<E>(self, v: i64) -> Result<Value, E> {
        Ok(Value::from(v))
    }
    fn visit_u64<E>(self, v: u64) -> Result<Value, E> {
        Ok(Value::from(v))
    }
    fn visit_f64<E>(self, v: f64) -> Result<Value, E> {
        Ok(Number::from_f64(v).map_or(Value::Null, Value::Number))
    }
    fn visit_str<E>(self, v: &str) -> Result<Value, E> {
        Ok(Value::String(v.to_string()))
    }
    fn visit_string<E>(self, v: String) -> Result<Value, E> {
        Ok(Value::String(v))
    }
    fn visit_unit<E>(self) -> Result<Value, E> {
        Ok(Value::Null)
    }
    fn visit_none<E>(self) -> Result<Value, E> {
        Ok(Value::Null)
    }
    fn visit_some<D: Deserializer<'de>>(self, d: D) -> Result<Value, D::Error> {
        d.deserialize_any(StrictVisitor)
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Value, A::Error> {
        let mut out = Vec::new();
        while let Some(StrictValue(v)) = seq.next_element()? {
            out.push(v);
        }
        Ok(Value::Array(out))
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Value, A::Error> {
        let mut out = Map::new();
        while let Some(key) = map.next_key::<String>()? {
            if out.contains_key(&key) {
                return Err(serde::de::Error::custom(format_args!(
                    "duplicate key `{key}` (a key may appear once in a table)"
                )));
            }
            let StrictValue(v) = map.next_value()?;
            out.insert(key, v);
        }
        Ok(Value::Object(out))
    }
}

/// Parses JSON text into a value, refusing a key given twice in one object (the error names
/// the key, with its line and column).
pub fn parse_json(text: &str) -> Result<Value, String> {
    serde_json::from_str::<StrictValue>(text)
        .map(|v| v.0)
        .map_err(|e| e.to_string())
}

/// Parses JSON text that must be an object, refusing duplicate keys.
pub fn parse_json_object(text: &str) -> Result<Map<String, Value>, String> {
    match parse_json(text)? {
        Value::Object(m) => Ok(m),
        other => Err(not_a_table(&other)),
    }
}

fn not_a_table(v: &Value) -> String {
    let found = match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    };
    format!("expected a table of keys (a JSON object or a TOML document), found {found}")
}

/// The keys of a parsed document, for naming the path of an unknown key.
enum Tree {
    Map(Vec<(String, Tree)>),
    List(Vec<Tree>),
    Text(String),
    Other,
}

impl Tree {
    fn of_json(v: &Value) -> Tree {
        match v {
            Value::Object(m) => Tree::Map(
                m.iter()
                    .map(|(k, v)| (k.clone(), Tree::of_json(v)))
                    .collect(),
            ),
            Value::Array(a) => Tree::List(a.iter().map(Tree::of_json).collect()),
            Value::String(s) => Tree::Text(s.clone()),
            _ => Tree::Other,
        }
    }
    fn of_toml(v: &toml::Value) -> Tree {
        match v {
            toml::Value::Table(m) => Tree::Map(
                m.iter()
                    .map(|(k, v)| (k.clone(), Tree::of_toml(v)))
                    .collect(),
            ),
            toml::Value::Array(a) => Tree::List(a.iter().map(Tree::of_toml).collect()),
            toml::Value::String(s) => Tree::Text(s.clone()),
            _ => Tree::Other,
        }
    }
    /// Paths (`a.b[2].c`) of the entries named `key` (or, with `value`, whose value is the
    /// text `key`), each with the keys of its table.
    fn find(&self, key: &str, value: bool, path: &str, out: &mut Vec<(String, Vec<String>)>) {
        match self {
            Tree::Map(m) => {
                for (k, v) in m {
                    let p = if path.is_empty() {
                        k.clone()
                    } else {
                        format!("{path}.{k}")
                    };
                    let hit = if value {
                        matches!(v, Tree::Text(s) if s == key)
                    } else {
                        k == key
                    };
                    if hit {
                        out.push((p.clone(), m.iter().map(|(k, _)| k.clone()).collect()));
                    }
                    v.find(key, value, &p, out);
                }
            }
            Tree::List(a) => {
                for (i, v) in a.iter().enumerate() {
                    v.find(key, value, &format!("{path}[{i}]"), out);
                }
            }
            Tree::Text(_) | Tree::Other => {}
        }
    }
}

/// Decodes config text into `T` (whose structs deny unknown fields) under the rules of this
/// module; the error is a message without the file name (callers add it).
pub fn decode<T: DeserializeOwned + Serialize>(text: &str, format: Format) -> Result<T, String> {
    let tree = match format {
        Format::Json => Tree::of_json(&Value::Object(parse_json_object(text)?)),
        // TOML refuses duplicate keys by itself, and a document is always a table.
        Format::Toml => Tree::Map(
            toml::from_str::<toml::Table>(text)
                .map_err(|e| e.to_string())?
                .into_iter()
                .map(|(k, v)| (k, Tree::of_toml(&v)))
                .collect(),
        ),
    };
    let r = match format {
        Format::Json => serde_json::from_str::<T>(text).map_err(|e| e.to_string()),
        Format::Toml => toml::from_str::<T>(text).map_err(|e| e.to_string()),
    };
    let t = r.map_err(|m| explain_with(&m, &tree))?;
    refuse_array_tables(&tree, &t)?;
    Ok(t)
}

/// Decodes a parsed JSON value into `T`, with unknown keys and values explained as in
/// [`decode`] (their path is relative to `value`).
pub fn decode_value<T: DeserializeOwned + Serialize>(value: Value) -> Result<T, String> {
    let tree = Tree::of_json(&value);
    let t = serde_json::from_value::<T>(value).map_err(|e| explain_with(&e.to_string(), &tree))?;
    refuse_array_tables(&tree, &t)?;
    Ok(t)
}

/// Refuses a table written as an array (`domain = [1.0, 64]`: serde accepts a struct's
/// fields in order as a sequence, which would silently bind values to fields by position):
/// the decoded value, serialised again, shows where the document has an array and the
/// config a table.
fn refuse_array_tables<T: Serialize>(tree: &Tree, decoded: &T) -> Result<(), String> {
    let Ok(v) = serde_json::to_value(decoded) else {
        return Ok(());
    };
    match array_for_table(tree, &v, "") {
        Some(path) => Err(format!(
            "`{path}` must be a table of named keys (e.g. [{path}] in TOML, {{\"key\": value}} in \
             JSON), not an array of values"
        )),
        None => Ok(()),
    }
}

/// The path of the first entry that is an array in the document and a table in `decoded`.
fn array_for_table(input: &Tree, decoded: &Value, path: &str) -> Option<String> {
    match (input, decoded) {
        (Tree::List(_), Value::Object(_)) => Some(path.to_string()),
        (Tree::Map(m), Value::Object(o)) => m.iter().find_map(|(k, v)| {
            let p = if path.is_empty() {
                k.clone()
            } else {
                format!("{path}.{k}")
            };
            o.get(k).and_then(|d| array_for_table(v, d, &p))
        }),
        (Tree::List(a), Value::Array(b)) => a
            .iter()
            .zip(b)
            .enumerate()
            .find_map(|(i, (x, y))| array_for_table(x, y, &format!("{path}[{i}]"))),
        _ => None,
    }
}

/// Rewrites serde's `unknown field `x`, expected ...` / `unknown variant `x`, expected ...`
/// in `message` into the path of the key in the document and the closest known name.
fn explain_with(message: &str, tree: &Tree) -> String {
    for (prefix, is_value) in [("unknown field `", false), ("unknown variant `", true)] {
        let Some(start) = message.find(prefix) else {
            continue;
        };
        let rest = &message[start + prefix.len()..];
        let Some(end) = rest.find('`') else {
            continue;
        };
        let word = &rest[..end];
        let (expected, tail) = parse_expected(&rest[end + 1..]);
        let mut hits = Vec::new();
        tree.find(word, is_value, "", &mut hits);
        // Where several tables hold the word, the one whose other keys are all known is it.
        let path = hits
            .iter()
            .find(|(_, keys)| !is_value && keys.iter().all(|k| k == word || expected.contains(k)))
            .or(hits.first())
            .map(|(p, _)| p.clone())
            .unwrap_or_else(|| word.to_string());
        let names: Vec<&str> = expected.iter().map(String::as_str).collect();
        let what = if is_value {
            format!("unknown value `{word}` of `{path}`")
        } else {
            format!("unknown key `{path}`")
        };
        let new = format!("{what}{}", known_list(word, &names));
        let old_len = message.len() - tail.len();
        return format!("{}{new}{}", &message[..start], &message[old_len..]);
    }
    message.to_string()
}

/// `: did you mean `y`? (known: ...)`, or ` (known: ...)` without a close name.
fn known_list(word: &str, names: &[&str]) -> String {
    let list = if names.is_empty() {
        "none".to_string()
    } else {
        names
            .iter()
            .map(|n| format!("`{n}`"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    match suggest(word, names) {
        Some(s) => format!(": did you mean `{s}`? (known: {list})"),
        None => format!(" (known: {list})"),
    }
}

/// Parses serde's list of expected names (`one of `a`, `b``, `` `a` or `b` ``, `` `a` ``,
/// `there are no fields`) after `, expected `; returns the names and the text after them.
fn parse_expected(s: &str) -> (Vec<String>, &str) {
    let mut names = Vec::new();
    let Some(mut rest) = s.strip_prefix(", expected ") else {
        let rest = s
            .strip_prefix(", there are no fields")
            .or_else(|| s.strip_prefix(", there are no variants"))
            .unwrap_or(s);
        return (names, rest);
    };
    rest = rest.strip_prefix("one of ").unwrap_or(rest);
    while let Some(r) = rest.strip_prefix('`') {
        let Some(e) = r.find('`') else {
            break;
        };
        names.push(r[..e].to_string());
        rest = &r[e + 1..];
        match rest
            .strip_prefix(", ")
            .or_else(|| rest.strip_prefix(" or "))
        {
            Some(r) if r.starts_with('`') => rest = r,
            _ => break,
        }
    }
    (names, rest)
}

/// Checks the keys of a table read by hand (PhysGaussian's scene JSON): the first key not in
/// `known` is an error naming `path.key` and the closest known key.
pub fn check_keys<'a>(
    keys: impl IntoIterator<Item = &'a String>,
    known: &[&str],
    path: &str,
) -> Result<(), String> {
    for k in keys {
        if !known.contains(&k.as_str()) {
            let p = if path.is_empty() {
                k.clone()
            } else {
                format!("{path}.{k}")
            };
            return Err(format!("unknown key `{p}`{}", known_list(k, known)));
        }
    }
    Ok(())
}

/// An unknown value of a key read by hand: `unknown value `x` of `path``, with the closest
/// known value, worded as [`decode`] words serde's unknown variants.
pub fn unknown_value(path: &str, word: &str, known: &[&str]) -> String {
    format!(
        "unknown value `{word}` of `{path}`{}",
        known_list(word, known)
    )
}

/// Levenshtein distance between two strings (by characters).
pub fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = (prev + usize::from(ca != cb)).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}

/// The known name closest to `word` (case-insensitive edit distance at most 2, or a third of
/// the word's length, or a name that starts with the word or the word with it), if any.
pub fn suggest<'a>(word: &str, known: &[&'a str]) -> Option<&'a str> {
    let w = word.to_lowercase();
    let limit = 2.max(w.chars().count() / 3);
    known
        .iter()
        .map(|k| {
            let kl = k.to_lowercase();
            let d = edit_distance(&w, &kl);
            let prefix = w.len() >= 3 && (kl.starts_with(&w) || w.starts_with(&kl));
            (if prefix { d.min(limit) } else { d }, *k)
        })
        .filter(|(d, _)| *d <= limit)
        .min_by_key(|(d, _)| *d)
        .map(|(_, k)| k)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::{Deserialize, Serialize};

    #[derive(Debug, Deserialize, Serialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Inner {
        gravity: f64,
        #[serde(default)]
        force: Option<Kind>,
    }
    #[derive(Debug, Deserialize, Serialize)]
    #[serde(rename_all = "snake_case")]
    enum Kind {
        Mls,
        Classic,
    }
    #[derive(Debug, Deserialize, Serialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Outer {
        #[serde(default)]
        solver: Option<Inner>,
        #[serde(default)]
        list: Vec<Inner>,
    }

    #[test]
    fn nested_typos_name_the_path_and_the_closest_key() {
        let e = decode::<Outer>("[solver]\ngravty = 1.0\n", Format::Toml).unwrap_err();
        assert!(
            e.contains("unknown key `solver.gravty`") && e.contains("did you mean `gravity`?"),
            "{e}"
        );
        assert!(e.contains("line 2"), "the TOML position is kept: {e}");
        let e = decode::<Outer>(
            r#"{"list": [{"gravity": 1}, {"gravity": 1, "forse": "mls"}]}"#,
            Format::Json,
        )
        .unwrap_err();
        assert!(
            e.contains("`list[1].forse`") && e.contains("did you mean `force`?"),
            "{e}"
        );
        let e = decode::<Outer>(
            r#"{"solver": {"gravity": 1, "force": "clasic"}}"#,
            Format::Json,
        )
        .unwrap_err();
        assert!(
            e.contains("unknown value `clasic` of `solver.force`") && e.contains("`classic`?"),
            "{e}"
        );
        let e = decode::<Outer>("zzz = 1\n", Format::Toml).unwrap_err();
        assert!(
            e.contains("unknown key `zzz` (known: `solver`, `list`)"),
            "{e}"
        );
    }

    #[test]
    fn duplicate_keys_and_non_tables_are_refused() {
        let e = decode::<Outer>(r#"{"solver": {"gravity": 1, "gravity": 2}}"#, Format::Json)
            .unwrap_err();
        assert!(e.contains("duplicate key `gravity`"), "{e}");
        let e = decode::<Outer>("[solver]\ngravity = 1\ngravity = 2\n", Format::Toml).unwrap_err();
        assert!(e.contains("duplicate key"), "{e}");
        for text in ["[]", "3", "\"x\"", "null"] {
            let e = decode::<Outer>(text, Format::Json).unwrap_err();
            assert!(e.contains("expected a table of keys"), "{text}: {e}");
        }
        let e = parse_json_object(r#"{"a": {"b": [{"c": 1, "c": 1}]}}"#).unwrap_err();
        assert!(e.contains("duplicate key `c`"), "{e}");
    }

    #[test]
    fn a_table_written_as_an_array_is_refused_by_path() {
        let e = decode::<Outer>("solver = [1.0]\n", Format::Toml).unwrap_err();
        assert!(e.contains("`solver` must be a table"), "{e}");
        let e = decode::<Outer>(r#"{"list": [{"gravity": 1}, [2.0]]}"#, Format::Json).unwrap_err();
        assert!(e.contains("`list[1]` must be a table"), "{e}");
        let e = decode_value::<Outer>(serde_json::json!({"solver": [1.0, "mls"]})).unwrap_err();
        assert!(e.contains("`solver` must be a table"), "{e}");
        // The table forms decode.
        decode::<Outer>(
            "[solver]\ngravity = 1.0\n[[list]]\ngravity = 2.0\n",
            Format::Toml,
        )
        .unwrap();
    }

    #[test]
    fn suggestions_use_edit_distance() {
        assert_eq!(edit_distance("kitten", "sitting"), 3);
        assert_eq!(suggest("gravty", &["gravity", "force"]), Some("gravity"));
        assert_eq!(
            suggest("youngs_modulus", &["youngs_modulus_pa"]),
            Some("youngs_modulus_pa")
        );
        assert_eq!(suggest("zzzzzz", &["gravity", "force"]), None);
        let e = check_keys(
            [&"densty".to_string()],
            &["density", "E"],
            "additional_material_params[0]",
        )
        .unwrap_err();
        assert!(
            e.contains("`additional_material_params[0].densty`") && e.contains("`density`?"),
            "{e}"
        );
    }
}
