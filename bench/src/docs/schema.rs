//! Markdown from a JSON Schema (as `schemars` writes them): one section per object the root
//! reaches, with a table of its fields (type, default, description as the doc comments give
//! it, units included), and one per enumeration with its values. `$ref`s become links to the
//! definition's section; definitions nothing reaches are left out.

use super::cell;
use serde_json::{Map, Value};
use std::collections::BTreeSet;

/// The reconstruction's schema as the default build has it: without the opt-in `experimental`
/// section (feature `experimental`), so the reference is the same whichever features built
/// the binary.
pub fn default_build(mut schema: Value) -> Value {
    if let Some(props) = schema.get_mut("properties").and_then(Value::as_object_mut) {
        props.remove("experimental");
    }
    schema
}

/// The Markdown page for `schema` titled `title`; `source` says where the schema comes from.
pub fn render(title: &str, source: &str, schema: &Value) -> String {
    let defs = definitions(schema);
    let mut out = format!("# {title}\n\n{}\n", super::generated_note(source));
    if let Some(d) = description(schema) {
        out += &format!("{d}\n\n");
    }
    out += "Units are SI (m, s, K, W, J) unless a field says otherwise. Types link to their section below.\n\n";
    let root_name = schema.get("title").and_then(Value::as_str).unwrap_or("Root");
    out += &section(root_name, schema, false);
    for name in reachable(schema, &defs) {
        if let Some(def) = defs.get(&name) {
            out += &section(&name, def, true);
        }
    }
    out
}

/// The schema's definitions (`$defs` or the older `definitions`).
fn definitions(schema: &Value) -> Map<String, Value> {
    ["$defs", "definitions"].iter().find_map(|k| schema.get(*k).and_then(Value::as_object).cloned()).unwrap_or_default()
}

/// The definitions `schema` refers to, directly or through other definitions, sorted by name.
fn reachable(schema: &Value, defs: &Map<String, Value>) -> BTreeSet<String> {
    let mut seen = BTreeSet::new();
    let mut todo = Vec::new();
    collect_refs(schema, &mut todo);
    while let Some(name) = todo.pop() {
        if seen.insert(name.clone()) {
            if let Some(def) = defs.get(&name) {
                collect_refs(def, &mut todo);
            }
        }
    }
    seen
}

/// Pushes the definition names of every `$ref` inside `v` (not descending into the
/// definitions themselves).
fn collect_refs(v: &Value, out: &mut Vec<String>) {
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                if k == "$ref" {
                    if let Some(name) = x.as_str().and_then(ref_name) {
                        out.push(name.to_string());
                    }
                } else if k != "$defs" && k != "definitions" {
                    collect_refs(x, out);
                }
            }
        }
        Value::Array(a) => a.iter().for_each(|x| collect_refs(x, out)),
        _ => {}
    }
}

/// `Name` from `#/$defs/Name` or `#/definitions/Name`.
fn ref_name(r: &str) -> Option<&str> {
    r.strip_prefix("#/$defs/").or_else(|| r.strip_prefix("#/definitions/"))
}

/// The Markdown anchor of a section titled `name` (GitHub's rule for a one-word heading).
fn anchor(name: &str) -> String {
    name.to_lowercase()
}

/// The section of one object or enumeration; `is_def` is false for the root, whose
/// description the page already printed.
fn section(name: &str, s: &Value, is_def: bool) -> String {
    let mut out = format!("## {name}\n\n");
    if is_def {
        if let Some(d) = description(s) {
            out += &format!("{d}\n\n");
        }
    }
    if s.get("properties").is_some() {
        out += &fields_table(s);
    } else if let Some(variants) = variants(s) {
        out += &variants_section(variants);
    } else {
        out += &format!("Type: {}.\n\n", type_of(s));
    }
    out
}

/// The variants of an enumeration (`oneOf`, or `anyOf` when it is not just an optional value).
fn variants(s: &Value) -> Option<&Vec<Value>> {
    s.get("oneOf").or_else(|| s.get("anyOf")).and_then(Value::as_array)
}

/// The table of an enumeration's plain values, then one table per variant that is an object.
fn variants_section(variants: &[Value]) -> String {
    let mut out = String::from("One of:\n\n| Value | Description |\n|---|---|\n");
    let mut objects = String::new();
    for v in variants {
        let value = variant_label(v);
        let desc = description(v).unwrap_or_default();
        out += &format!("| {} | {} |\n", cell(&value), cell(&desc));
        if v.get("properties").is_some() {
            objects += &format!("### {value}\n\n{}", fields_table(v));
        }
    }
    out + "\n" + &objects
}

/// How a variant is written: its constant, the tag of a tagged object (`kind: "point"`), or an
/// object's required keys.
fn variant_label(v: &Value) -> String {
    if let Some(c) = v.get("const").or_else(|| single_enum(v)) {
        return format!("`{c}`");
    }
    if let Some(props) = v.get("properties").and_then(Value::as_object) {
        if let Some((k, c)) = props.iter().find_map(|(k, p)| p.get("const").map(|c| (k, c))) {
            return format!("`{k}: {c}`");
        }
        let keys: Vec<String> = props.keys().map(|k| format!("`{k}`")).collect();
        return format!("object with {}", keys.join(", "));
    }
    type_of(v)
}

/// The value of a one-value `enum`, the older spelling of `const`.
fn single_enum(v: &Value) -> Option<&Value> {
    v.get("enum").and_then(Value::as_array).filter(|a| a.len() == 1).map(|a| &a[0])
}

/// The table of an object's fields.
fn fields_table(s: &Value) -> String {
    let required: BTreeSet<&str> =
        s.get("required").and_then(Value::as_array).into_iter().flatten().filter_map(Value::as_str).collect();
    let mut out = String::from("| Field | Type | Default | Description |\n|---|---|---|---|\n");
    for (name, p) in s.get("properties").and_then(Value::as_object).into_iter().flatten() {
        let default = match p.get("default") {
            Some(Value::Object(_)) => "each field's default".to_string(),
            Some(d) => format!("`{d}`"),
            None if required.contains(name.as_str()) => "required".to_string(),
            None => "none".to_string(),
        };
        let desc = description(p).unwrap_or_default();
        out += &format!("| `{name}` | {} | {} | {} |\n", cell(&type_of(p)), cell(&default), cell(&desc));
    }
    if s.get("additionalProperties") == Some(&Value::Bool(false)) {
        out += "\nOther fields are refused.\n";
    }
    out + "\n"
}

/// A short type: `number`, `integer`, `array of number [3]`, a link to a definition, the
/// alternatives of an `anyOf` (`null` for an optional value).
fn type_of(p: &Value) -> String {
    if let Some(name) = p.get("$ref").and_then(Value::as_str).and_then(ref_name) {
        return format!("[{name}](#{})", anchor(name));
    }
    if let Some(c) = p.get("const").or_else(|| single_enum(p)) {
        return format!("`{c}`");
    }
    if let Some(alts) = variants(p) {
        let parts: Vec<String> = alts.iter().map(type_of).collect();
        return parts.join(" or ");
    }
    if let Some(all) = p.get("allOf").and_then(Value::as_array) {
        let parts: Vec<String> = all.iter().map(type_of).collect();
        return parts.join(" and ");
    }
    match p.get("type") {
        Some(Value::String(t)) => named_type(t, p),
        Some(Value::Array(ts)) => {
            let parts: Vec<String> = ts.iter().filter_map(Value::as_str).map(|t| named_type(t, p)).collect();
            parts.join(" or ")
        }
        _ => "any".to_string(),
    }
}

/// The text of one JSON type `t` of the schema `p` (arrays and maps name their items).
fn named_type(t: &str, p: &Value) -> String {
    match t {
        "array" => {
            let items = p.get("items").map(type_of).unwrap_or_else(|| "any".to_string());
            let (min, max) = (p.get("minItems"), p.get("maxItems"));
            match (min, max) {
                (Some(a), Some(b)) if a == b => format!("array of {items} [{a}]"),
                _ => format!("array of {items}"),
            }
        }
        "object" => match p.get("additionalProperties") {
            Some(v @ Value::Object(_)) => format!("map of string to {}", type_of(v)),
            _ => "object".to_string(),
        },
        other => other.to_string(),
    }
}

/// The description with rustdoc's link syntax (``[`x`]``, ``[`x`](path)``) reduced to `` `x` ``,
/// which has no target outside rustdoc.
fn description(s: &Value) -> Option<String> {
    let d = s.get("description")?.as_str()?;
    Some(strip_rustdoc_links(d))
}

fn strip_rustdoc_links(d: &str) -> String {
    let mut out = String::with_capacity(d.len());
    let mut rest = d;
    while let Some(start) = rest.find("[`") {
        let Some(len) = rest[start + 2..].find("`]") else { break };
        out += &rest[..start];
        out += &rest[start + 1..start + 2 + len + 1];
        rest = &rest[start + 2 + len + 2..];
        // A rustdoc link target `(path)` without spaces follows: drop it too.
        if let Some(close) = rest.strip_prefix('(').and_then(|r| r.find(')')) {
            if !rest[1..=close].contains(char::is_whitespace) {
                rest = &rest[close + 2..];
            }
        }
    }
    out + rest
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rustdoc_links_become_code() {
        assert_eq!(strip_rustdoc_links("a [`X::y`] b"), "a `X::y` b");
        assert_eq!(strip_rustdoc_links("call [`validate`](Scene::validate)."), "call `validate`.");
        assert_eq!(strip_rustdoc_links("[1, 2] and `[x]`"), "[1, 2] and `[x]`");
    }

    #[test]
    fn refs_link_and_optional_values_say_null() {
        let p = serde_json::json!({"anyOf": [{"$ref": "#/$defs/Lamp"}, {"type": "null"}]});
        assert_eq!(type_of(&p), "[Lamp](#lamp) or null");
        let a = serde_json::json!({"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3});
        assert_eq!(type_of(&a), "array of number [3]");
    }
}
