//! The world file described for people and editors: its JSON Schema, the Markdown
//! reference generated from that schema (`docs/world-file.md`), and a loaded world written
//! back as TOML with every default filled in (`check --resolved`).
//!
//! The schema is derived (`schemars`) from the same Rust types the loader deserialises,
//! so it cannot drift from what the loader accepts: doc comments become descriptions,
//! `#[serde(default)]` values become `default`, and `#[schemars(range(..))]` carries the
//! ranges the loader enforces.

use crate::world::schema::WorldFile;
use schemars::generate::SchemaSettings;
use schemars::transform::{RecursiveTransform, RestrictFormats};
use serde_json::{Map, Value};
use std::fmt::Write as _;

/// The JSON Schema (draft-07, the draft taplo and Even Better TOML support best) of a
/// world file.
pub fn json_schema() -> Value {
    let mut settings = SchemaSettings::draft07();
    settings
        .transforms
        .push(Box::new(RecursiveTransform(drop_null)));
    settings
        .transforms
        .push(Box::new(RestrictFormats::default()));
    let mut schema = settings
        .into_generator()
        .into_root_schema_for::<WorldFile>();
    schema.insert("title".into(), "hybridnav world file".into());
    schema.to_value()
}

/// Removes `null` from a schema: serde reads an absent key as `None`, and TOML has no
/// null, so `Option<T>` is just `T` in a world file.
fn drop_null(schema: &mut schemars::Schema) {
    let Some(obj) = schema.as_object_mut() else {
        return;
    };
    if obj.get("default") == Some(&Value::Null) {
        obj.remove("default");
    }
    if let Some(Value::Array(types)) = obj.get_mut("type") {
        types.retain(|t| t != "null");
        if types.len() == 1 {
            let t = types[0].clone();
            obj.insert("type".into(), t);
        }
    }
    for key in ["anyOf", "oneOf"] {
        let Some(Value::Array(alts)) = obj.get_mut(key) else {
            continue;
        };
        alts.retain(|a| a.get("type") != Some(&Value::String("null".into())));
        if alts.len() == 1 {
            let only = alts.remove(0);
            obj.remove(key);
            if let Value::Object(m) = only {
                for (k, v) in m {
                    obj.entry(k).or_insert(v);
                }
            }
        }
    }
}

/// `file` written back as TOML: every key the loader fills in from a default is written
/// out, presets are expanded into their keys, and loading the text gives the same world.
///
/// # Errors
/// When the TOML writer refuses a value (an integer above `i64::MAX`).
pub fn resolved_toml(file: &WorldFile) -> Result<String, String> {
    let mut file = file.clone();
    // The attitude model defaults from the platform kind; writing it makes it visible.
    file.platform.attitude = Some(file.platform.attitude());
    toml::to_string(&file).map_err(|e| format!("cannot write the resolved world: {e}"))
}

/// The unit a key's name carries (the project names units in keys: `range_m`,
/// `rate_hz`, `gyro_arw_deg_per_sqrt_h`): the longest run of unit words at the end of the
/// name, after at least one word that is not a unit, written with `/` and `√`.
fn unit_of(key: &str) -> String {
    fn symbol(word: &str) -> Option<&'static str> {
        Some(match word {
            "m" => "m",
            "km" => "km",
            "m2" => "m²",
            "s" => "s",
            "ms" => "ms",
            "ns" => "ns",
            "h" => "h",
            "hz" => "Hz",
            "deg" => "°",
            "rad" => "rad",
            "mrad" => "mrad",
            "kw" => "kW",
            "w" => "W",
            "db" => "dB",
            "dbm" => "dBm",
            "dbi" => "dBi",
            "dbic" => "dBic",
            "dbhz" => "dB-Hz",
            "mps" => "m/s",
            "mps2" => "m/s²",
            "m2ps" => "m²/s",
            "m2ps3" => "m²/s³",
            "m2ps4" => "m²/s⁴",
            "m2ps5" => "m²/s⁵",
            "ut" => "µT",
            "nt" => "nT",
            "am2" => "A·m²",
            "ppm" => "ppm",
            "k" => "K",
            "chips" => "chips",
            "per" => "/",
            "sqrt" => "√",
            _ => return None,
        })
    }
    let words: Vec<String> = key.split('_').map(str::to_ascii_lowercase).collect();
    let mut first = words.len();
    while first > 1 && symbol(&words[first - 1]).is_some() {
        first -= 1;
    }
    let mut unit = String::new();
    for w in &words[first..] {
        let s = symbol(w).unwrap_or("");
        if unit.is_empty() && (s == "/" || s == "√") {
            continue;
        }
        unit.push_str(s);
    }
    unit
}

/// The Markdown reference of every key of a world file (`docs/world-file.md`), generated
/// from [`json_schema`].
pub fn markdown() -> String {
    let schema = json_schema();
    let defs = schema
        .get("definitions")
        .and_then(Value::as_object)
        .cloned()
        .unwrap_or_default();
    let r = Reference { defs: &defs };
    let mut out = String::new();
    out.push_str(
        "# World-file reference\n\n\
         <!-- Generated by `hybridnav schema --markdown > docs/world-file.md`; do not edit. \
         A test fails when this file differs from what the command prints. -->\n\n\
         Every key a world file (TOML) accepts, generated from the Rust types the loader reads \
         it with. Key paths: `a.b` is key `b` of table `[a]`; `a[]` is an element of the array \
         of tables `[[a]]` (or of an array of inline tables). Units are in the key names \
         (`_m` metres, `_s` seconds, `_hz` hertz, `_deg` degrees, `_kw` kilowatts, `_db` \
         decibels, `_mps` metres per second). Rows marked *when kind = \"…\"* apply only to \
         that variant of a tagged table. Every table refuses keys it does not list. The same \
         description is available as a JSON Schema for TOML editors: `hybridnav schema --out \
         world.schema.json` (see README).\n\n\
         `hybridnav check WORLD --resolved` prints a world with every default filled in.\n",
    );
    let props = schema
        .get("properties")
        .and_then(Value::as_object)
        .cloned()
        .unwrap_or_default();
    let required = required_of(&schema);
    // The sections in the order of [`WorldFile`]'s fields (the schema's keys are sorted).
    const ORDER: &[&str] = &[
        "world",
        "platform",
        "receiver",
        "sensors",
        "scene",
        "transmitter",
        "shielding",
        "estimator",
        "montecarlo",
        "scoring",
    ];
    let mut keys: Vec<&String> = props.keys().collect();
    keys.sort_by_key(|k| ORDER.iter().position(|o| o == k).unwrap_or(ORDER.len()));
    for key in keys {
        let sub = &props[key.as_str()];
        let toml_head = match r.array_items(sub) {
            Some(_) => format!("[[{key}]]"),
            None if r.is_table(sub) => format!("[{key}]"),
            None => key.clone(),
        };
        let _ = writeln!(out, "\n## `{toml_head}`\n");
        if let Some(d) = r.description(sub) {
            let _ = writeln!(out, "{}\n", one_line(&d));
        }
        out.push_str("| key | type | unit | default | allowed | description |\n");
        out.push_str("|---|---|---|---|---|---|\n");
        let mut rows = Vec::new();
        if r.is_table(sub) || r.array_items(sub).is_some() {
            r.row(&mut rows, key, sub, required.contains(key), "");
            let (path, table) = match r.array_items(sub) {
                Some(items) => (format!("{key}[]"), items),
                None => (key.clone(), sub.clone()),
            };
            r.walk(&mut rows, &path, &table, "", 0);
        } else {
            r.row(&mut rows, key, sub, required.contains(key), "");
        }
        for row in rows {
            out.push_str(&row);
        }
    }
    out
}

/// Names listed in a schema's `required`.
fn required_of(s: &Value) -> Vec<String> {
    s.get("required")
        .and_then(Value::as_array)
        .map(|a| {
            a.iter()
                .filter_map(|v| v.as_str().map(String::from))
                .collect()
        })
        .unwrap_or_default()
}

/// Whitespace collapsed, and `|` escaped, for a table cell.
fn one_line(s: &str) -> String {
    s.split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .replace('|', "\\|")
}

/// A JSON value written as it would be in TOML (short values only).
fn toml_value(v: &Value) -> String {
    match v {
        Value::String(s) => format!("\"{s}\""),
        Value::Array(a) => format!(
            "[{}]",
            a.iter().map(toml_value).collect::<Vec<_>>().join(", ")
        ),
        Value::Object(m) if m.is_empty() => "{}".into(),
        Value::Object(_) => "(table)".into(),
        Value::Number(n) => match n.as_f64() {
            Some(f) if n.is_f64() && f.fract() == 0.0 && f.abs() < 1e15 => format!("{f:.1}"),
            _ => n.to_string(),
        },
        other => other.to_string(),
    }
}

/// The schema walker: definitions to resolve `$ref`s against.
struct Reference<'a> {
    defs: &'a Map<String, Value>,
}

impl Reference<'_> {
    /// `s` with its `$ref` (also a lone `allOf: [{$ref}]`) followed; the referring schema's
    /// own keys (description, default) are kept over the target's.
    fn resolve(&self, s: &Value) -> Value {
        let mut s = s.clone();
        for _ in 0..8 {
            let target = s
                .get("$ref")
                .or_else(|| {
                    s.get("allOf")
                        .and_then(Value::as_array)
                        .filter(|a| a.len() == 1)
                        .and_then(|a| a[0].get("$ref"))
                })
                .and_then(Value::as_str)
                .and_then(|r| r.strip_prefix("#/definitions/"))
                .and_then(|name| self.defs.get(name))
                .cloned();
            let Some(Value::Object(mut t)) = target else {
                break;
            };
            if let Value::Object(m) = &s {
                for (k, v) in m {
                    if k != "$ref" && k != "allOf" {
                        t.insert(k.clone(), v.clone());
                    }
                }
            }
            s = Value::Object(t);
        }
        s
    }

    /// The description of a key: its own, else its type's.
    fn description(&self, s: &Value) -> Option<String> {
        let own = s
            .get("description")
            .and_then(Value::as_str)
            .map(String::from);
        own.or_else(|| {
            self.resolve(s)
                .get("description")
                .and_then(Value::as_str)
                .map(String::from)
        })
    }

    /// The variants of a tagged table (`oneOf`/`anyOf` alternatives that have keys).
    fn variants(&self, s: &Value) -> Vec<Value> {
        let s = self.resolve(s);
        ["oneOf", "anyOf"]
            .iter()
            .filter_map(|k| s.get(*k).and_then(Value::as_array))
            .flatten()
            .map(|v| self.resolve(v))
            .filter(|v| v.get("properties").is_some())
            .collect()
    }

    fn is_table(&self, s: &Value) -> bool {
        let s = self.resolve(s);
        s.get("properties").is_some() || !self.variants(&s).is_empty()
    }

    /// The element schema of an array of tables.
    fn array_items(&self, s: &Value) -> Option<Value> {
        let s = self.resolve(s);
        let items = s.get("items")?;
        self.is_table(items).then(|| self.resolve(items))
    }

    /// The allowed values of a string enum, with their descriptions.
    fn enum_values(&self, s: &Value) -> Vec<(String, Option<String>)> {
        let s = self.resolve(s);
        if let Some(values) = s.get("enum").and_then(Value::as_array) {
            return values.iter().map(|v| (toml_value(v), None)).collect();
        }
        if let Some(c) = s.get("const") {
            return vec![(toml_value(c), None)];
        }
        let alts: Vec<Value> = ["oneOf", "anyOf"]
            .iter()
            .filter_map(|k| s.get(*k).and_then(Value::as_array))
            .flatten()
            .map(|v| self.resolve(v))
            .collect();
        if alts.is_empty() || alts.iter().any(|a| a.get("properties").is_some()) {
            return Vec::new();
        }
        alts.iter()
            .flat_map(|a| {
                let d = a.get("description").and_then(Value::as_str).map(one_line);
                self.enum_values(a)
                    .into_iter()
                    .map(move |(v, _)| (v, d.clone()))
            })
            .collect()
    }

    fn type_name(&self, s: &Value) -> String {
        let r = self.resolve(s);
        if !self.enum_values(&r).is_empty() {
            return "string".into();
        }
        if self.is_table(&r) {
            let tags = self.tag_values(&r);
            return if tags.is_empty() {
                "table".into()
            } else {
                format!("table, one of {}", tags.join(", "))
            };
        }
        match r.get("type") {
            Some(Value::String(t)) => match t.as_str() {
                "number" => "float".into(),
                "array" => match r.get("items") {
                    Some(i) if i.is_array() => "array".into(),
                    Some(i) if self.is_table(i) => "array of tables".into(),
                    Some(i) => format!("array of {}", self.type_name(i)),
                    None => "array".into(),
                },
                "object" => "table".into(),
                other => other.into(),
            },
            Some(Value::Array(ts)) => ts
                .iter()
                .filter_map(Value::as_str)
                .collect::<Vec<_>>()
                .join(" or "),
            _ => "any".into(),
        }
    }

    /// `tag = "value"` for each variant of a tagged table.
    fn tag_values(&self, s: &Value) -> Vec<String> {
        self.variants(s)
            .iter()
            .filter_map(|v| {
                v.get("properties")?.as_object()?.iter().find_map(|(k, p)| {
                    let vals = self.enum_values(p);
                    (vals.len() == 1 && p.get("type") == Some(&Value::String("string".into())))
                        .then(|| format!("{k} = {}", vals[0].0))
                })
            })
            .collect()
    }

    fn allowed(&self, s: &Value) -> String {
        let r = self.resolve(s);
        let mut parts = Vec::new();
        let values = self.enum_values(&r);
        if !values.is_empty() {
            parts.push(
                values
                    .iter()
                    .map(|(v, _)| format!("`{v}`"))
                    .collect::<Vec<_>>()
                    .join(", "),
            );
        }
        let item = r.get("items").map(|i| self.resolve(i));
        let item_values = item
            .as_ref()
            .map(|i| self.enum_values(i))
            .unwrap_or_default();
        if !item_values.is_empty() {
            parts.push(format!(
                "each of {}",
                item_values
                    .iter()
                    .map(|(v, _)| format!("`{v}`"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        let num = |k: &str, src: &Value| src.get(k).map(toml_value);
        for src in std::iter::once(&r).chain(item.as_ref()) {
            match (num("minimum", src), num("maximum", src)) {
                (Some(a), Some(b)) => parts.push(format!("{a} to {b}")),
                (Some(a), None) if a != "0" => parts.push(format!("≥ {a}")),
                (None, Some(b)) => parts.push(format!("≤ {b}")),
                _ => {}
            }
            if let Some(b) = num("exclusiveMaximum", src) {
                parts.push(format!("< {b}"));
            }
            if let Some(a) = num("exclusiveMinimum", src) {
                parts.push(format!("> {a}"));
            }
        }
        if let Some(n) = num("minItems", &r) {
            match num("maxItems", &r) {
                Some(m) if m == n => parts.push(format!("exactly {n} items")),
                Some(m) => parts.push(format!("{n} to {m} items")),
                None => parts.push(format!("at least {n} item(s)")),
            }
        }
        parts.join("; ")
    }

    fn row(&self, rows: &mut Vec<String>, path: &str, s: &Value, required: bool, when: &str) {
        let key = path.rsplit(['.', ']']).next().unwrap_or(path);
        let default = match s.get("default") {
            Some(d) => format!("`{}`", toml_value(d)),
            None if required => "required".into(),
            None => "—".into(),
        };
        let mut description = self
            .description(s)
            .map(|d| one_line(&d))
            .unwrap_or_default();
        if !when.is_empty() {
            description = format!("*when {when}:* {description}");
        }
        rows.push(format!(
            "| `{path}` | {} | {} | {default} | {} | {description} |\n",
            self.type_name(s),
            unit_of(key),
            self.allowed(s),
        ));
    }

    /// Rows for every key of table `s` at `path`, recursing into sub-tables and arrays of
    /// tables; for a tagged table, the keys of each variant.
    fn walk(&self, rows: &mut Vec<String>, path: &str, s: &Value, when: &str, depth: usize) {
        if depth > 8 {
            return;
        }
        let s = self.resolve(s);
        if let Some(props) = s.get("properties").and_then(Value::as_object) {
            let required = required_of(&s);
            for (key, sub) in props {
                let p = format!("{path}.{key}");
                self.row(rows, &p, sub, required.contains(key), when);
                if let Some(items) = self.array_items(sub) {
                    self.walk(rows, &format!("{p}[]"), &items, when, depth + 1);
                } else if self.is_table(sub) {
                    self.walk(rows, &p, sub, when, depth + 1);
                }
            }
        }
        for v in self.variants(&s) {
            let tag = self.tag_values(&Value::Object(
                [("oneOf".to_string(), Value::Array(vec![v.clone()]))]
                    .into_iter()
                    .collect(),
            ));
            let label = match (when.is_empty(), tag.first()) {
                (_, None) => when.to_string(),
                (true, Some(t)) => t.clone(),
                (false, Some(t)) => format!("{when}, {t}"),
            };
            self.walk(rows, path, &v, &label, depth + 1);
        }
    }
}
