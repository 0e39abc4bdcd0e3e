//! The scenario's JSON Schema, derived from [`crate::config`] and the compensators' parameters:
//! the one place where a scenario's names, defaults, units (in the descriptions), allowed
//! values and ranges are written. Python builds its scenario models from
//! [`scenario_schema`] (through `_core.scenario_schema()`), and [`check_ranges`] checks a
//! scenario's numbers against the same schema.
//!
//! Ranges are the schema's `minimum`, `exclusiveMinimum`, `maximum` and `exclusiveMaximum`
//! (written on the fields as `#[schemars(range(min = ...))]` or
//! `#[schemars(extend("exclusiveMinimum" = ...))]`). Vectors, quaternions and inertias carry
//! the extension key `x-value` (`"vec3"`, `"quaternion"`, `"inertia"`) so that a reader of the
//! schema knows their shape, and `x-magnitude`, the largest `|x|` of each of their numbers
//! (checked here); their other checks (non-zero, symmetric positive definite) are semantic
//! and live in [`crate::plan::Plan::resolve`]. A number whose 0 means "none" and whose other
//! values must not be tiny (a quantisation step: `x / step` must stay finite) carries
//! `x-nonzero-minimum`, the smallest value allowed other than 0 (checked here too).

use std::collections::BTreeSet;
use std::fmt;

use serde::ser::{self, Serialize};
use serde_json::Value;

use crate::config::Scenario;
use crate::error::Issues;

/// The JSON Schema (draft 2020-12) of a scenario file, with every default, description
/// (units included), allowed value and range.
pub fn scenario_schema() -> schemars::Schema {
    schemars::schema_for!(Scenario)
}

/// Records every number of `scenario` outside the range its schema allows (or not finite),
/// with the dotted key and the messages `must be > 0, got -1`, `must be >= 0, got ...`,
/// `must be between 0 and 1 (exclusive), got ...`. Returns the keys that failed.
pub fn check_ranges(scenario: &Scenario, issues: &mut Issues) -> BTreeSet<String> {
    // built once per process: building it cost about 4 % of a run (docs/performance.md)
    static SCHEMA: std::sync::OnceLock<schemars::Schema> = std::sync::OnceLock::new();
    check_ranges_of(
        scenario,
        SCHEMA.get_or_init(scenario_schema),
        "scenario",
        issues,
    )
}

/// [`check_ranges`] for any value and its JSON Schema (e.g. the real-time options of
/// `hilcontact-rt`): every number outside the range `schema` gives it (or not finite, where a
/// range is given) is recorded under its dotted key; `what` names the value when it cannot be
/// serialised. Returns the keys that failed.
pub fn check_ranges_of<T: Serialize + ?Sized>(
    value: &T,
    schema: &schemars::Schema,
    what: &str,
    issues: &mut Issues,
) -> BTreeSet<String> {
    let mut failed = BTreeSet::new();
    match value.serialize(Collect) {
        Ok(node) => walk(
            schema.as_value(),
            schema.as_value(),
            &node,
            "",
            issues,
            &mut failed,
        ),
        Err(e) => issues.push(what, e.0),
    }
    failed
}

/// What a range allows, in words (`> 0`, `between 0 and 1 (exclusive)`), and whether `x` is in
/// it; `None` if the schema sets no bound.
fn range_of(schema: &Value, x: f64) -> Option<(String, bool)> {
    let bound = |name: &str| schema.get(name).and_then(Value::as_f64);
    let (min, emin, max, emax) = (
        bound("minimum"),
        bound("exclusiveMinimum"),
        bound("maximum"),
        bound("exclusiveMaximum"),
    );
    if min.is_none() && emin.is_none() && max.is_none() && emax.is_none() {
        return None;
    }
    let ok = min.is_none_or(|b| x >= b)
        && emin.is_none_or(|b| x > b)
        && max.is_none_or(|b| x <= b)
        && emax.is_none_or(|b| x < b);
    let words = match (min, emin, max, emax) {
        (None, Some(lo), None, Some(hi)) => {
            format!("between {} and {} (exclusive)", short(lo), short(hi))
        }
        (Some(lo), None, Some(hi), None) => format!("between {} and {}", short(lo), short(hi)),
        _ => {
            let parts: Vec<String> = [(">=", min), (">", emin), ("<=", max), ("<", emax)]
                .iter()
                .filter_map(|(op, b)| b.map(|b| format!("{op} {}", short(b))))
                .collect();
            parts.join(" and ")
        }
    };
    Some((words, ok))
}

/// A range's bound, short: `0`, `0.001`, `86400`, `1e-6`, `1e11`.
fn short(x: f64) -> String {
    if x == 0.0 || (1e-3..1e6).contains(&x.abs()) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

fn join(path: &str, key: &str) -> String {
    if path.is_empty() {
        key.to_string()
    } else {
        format!("{path}.{key}")
    }
}

/// Checks `node` against `schema` (resolving `$ref`s in `root`), recursing into tables,
/// lists and the compensator variant named by `kind`.
fn walk(
    root: &Value,
    schema: &Value,
    node: &Node,
    path: &str,
    issues: &mut Issues,
    failed: &mut BTreeSet<String>,
) {
    if let Node::Number(x) = *node {
        if let Some((allowed, ok)) = range_of(schema, x) {
            if !x.is_finite() {
                issues.push(path, format!("must be a finite number, got {x}"));
                failed.insert(path.to_string());
            } else if !ok {
                issues.push(path, format!("must be {allowed}, got {x}"));
                failed.insert(path.to_string());
            } else if let Some(smallest) = schema.get("x-nonzero-minimum").and_then(Value::as_f64) {
                if x != 0.0 && x.abs() < smallest {
                    issues.push(
                        path,
                        format!("must be 0 (none) or >= {}, got {x:e}", short(smallest)),
                    );
                    failed.insert(path.to_string());
                }
            }
        }
    }
    if let (Some(limit), Node::List(_)) = (schema.get("x-magnitude").and_then(Value::as_f64), node)
    {
        let mut numbers = Vec::new();
        node.numbers(&mut numbers);
        if let Some(x) = numbers.iter().find(|x| !(x.abs() <= limit)) {
            issues.push(
                path,
                format!(
                    "every number must be finite with |x| <= {}, got {x}",
                    short(limit)
                ),
            );
            failed.insert(path.to_string());
        }
    }
    if let Some(target) = schema.get("$ref").and_then(Value::as_str) {
        let name = target.trim_start_matches("#/$defs/");
        if let Some(def) = root.get("$defs").and_then(|d| d.get(name)) {
            walk(root, def, node, path, issues, failed);
        }
    }
    for all in schema
        .get("allOf")
        .and_then(Value::as_array)
        .into_iter()
        .flatten()
    {
        walk(root, all, node, path, issues, failed);
    }
    match node {
        Node::Table(fields) => {
            if let Some(properties) = schema.get("properties") {
                for (key, value) in fields {
                    if let Some(sub) = properties.get(key) {
                        walk(root, sub, value, &join(path, key), issues, failed);
                    }
                }
            }
            // a tagged union (the compensator): the variant whose `kind` is the table's
            let kind = fields.iter().find(|(k, _)| k == "kind").map(|(_, v)| v);
            if let (Some(Node::Text(kind)), Some(variants)) =
                (kind, schema.get("oneOf").and_then(Value::as_array))
            {
                let tag = |v: &Value| v.pointer("/properties/kind/const").cloned();
                if let Some(variant) = variants
                    .iter()
                    .find(|v| tag(v) == Some(Value::from(kind.as_str())))
                {
                    walk(root, variant, node, path, issues, failed);
                }
            }
        }
        Node::List(items) => {
            if let Some(item) = schema.get("items").filter(|i| i.is_object()) {
                for (i, value) in items.iter().enumerate() {
                    walk(root, item, value, &format!("{path}[{i}]"), issues, failed);
                }
            }
        }
        _ => {}
    }
}

/// A serialised value with its numbers as they are (JSON would turn NaN and ∞ into null).
#[derive(Debug, Clone, PartialEq)]
enum Node {
    Number(f64),
    Text(String),
    Other,
    List(Vec<Node>),
    Table(Vec<(String, Node)>),
}

impl Node {
    /// Every number in this node and its lists, in order.
    fn numbers(&self, out: &mut Vec<f64>) {
        match self {
            Node::Number(x) => out.push(*x),
            Node::List(items) => items.iter().for_each(|item| item.numbers(out)),
            _ => {}
        }
    }
}

#[derive(Debug)]
struct CollectError(String);

impl fmt::Display for CollectError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for CollectError {}

impl ser::Error for CollectError {
    fn custom<T: fmt::Display>(msg: T) -> Self {
        CollectError(msg.to_string())
    }
}

/// A serializer into [`Node`]s.
struct Collect;

/// A list or table being serialised (`variant`: the enclosing externally tagged variant).
struct Compound {
    items: Vec<Node>,
    fields: Vec<(String, Node)>,
    key: Option<String>,
    variant: Option<&'static str>,
}

impl Compound {
    fn new(variant: Option<&'static str>) -> Self {
        Compound {
            items: Vec::new(),
            fields: Vec::new(),
            key: None,
            variant,
        }
    }

    /// The node, inside `{variant: node}` for an externally tagged variant.
    fn wrap(variant: Option<&'static str>, node: Node) -> Node {
        match variant {
            Some(v) => Node::Table(vec![(v.to_string(), node)]),
            None => node,
        }
    }

    fn list(self) -> Node {
        Compound::wrap(self.variant, Node::List(self.items))
    }

    fn table(self) -> Node {
        Compound::wrap(self.variant, Node::Table(self.fields))
    }
}

type R = Result<Node, CollectError>;

/// Every number serialises as its value in f64 (exact for the integers of a scenario).
macro_rules! numbers {
    ($($method:ident: $t:ty),+) => {$(
        fn $method(self, v: $t) -> R {
            Ok(Node::Number(v as f64))
        }
    )+};
}

impl ser::Serializer for Collect {
    type Ok = Node;
    type Error = CollectError;
    type SerializeSeq = Compound;
    type SerializeTuple = Compound;
    type SerializeTupleStruct = Compound;
    type SerializeTupleVariant = Compound;
    type SerializeMap = Compound;
    type SerializeStruct = Compound;
    type SerializeStructVariant = Compound;

    fn serialize_bool(self, _: bool) -> R {
        Ok(Node::Other)
    }
    numbers!(
        serialize_i8: i8,
        serialize_i16: i16,
        serialize_i32: i32,
        serialize_i64: i64,
        serialize_u8: u8,
        serialize_u16: u16,
        serialize_u32: u32,
        serialize_u64: u64,
        serialize_f32: f32,
        serialize_f64: f64
    );
    fn serialize_char(self, v: char) -> R {
        Ok(Node::Text(v.to_string()))
    }
    fn serialize_str(self, v: &str) -> R {
        Ok(Node::Text(v.to_string()))
    }
    fn serialize_bytes(self, _: &[u8]) -> R {
        Ok(Node::Other)
    }
    fn serialize_none(self) -> R {
        Ok(Node::Other)
    }
    fn serialize_some<T: ?Sized + Serialize>(self, value: &T) -> R {
        value.serialize(self)
    }
    fn serialize_unit(self) -> R {
        Ok(Node::Other)
    }
    fn serialize_unit_struct(self, _: &'static str) -> R {
        Ok(Node::Other)
    }
    fn serialize_unit_variant(self, _: &'static str, _: u32, variant: &'static str) -> R {
        Ok(Node::Text(variant.to_string()))
    }
    fn serialize_newtype_struct<T: ?Sized + Serialize>(self, _: &'static str, value: &T) -> R {
        value.serialize(self)
    }
    fn serialize_newtype_variant<T: ?Sized + Serialize>(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        value: &T,
    ) -> R {
        Ok(Node::Table(vec![(
            variant.to_string(),
            value.serialize(self)?,
        )]))
    }
    fn serialize_seq(self, _: Option<usize>) -> Result<Compound, CollectError> {
        Ok(Compound::new(None))
    }
    fn serialize_tuple(self, _: usize) -> Result<Compound, CollectError> {
        Ok(Compound::new(None))
    }
    fn serialize_tuple_struct(self, _: &'static str, _: usize) -> Result<Compound, CollectError> {
        Ok(Compound::new(None))
    }
    fn serialize_tuple_variant(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        _: usize,
    ) -> Result<Compound, CollectError> {
        Ok(Compound::new(Some(variant)))
    }
    fn serialize_map(self, _: Option<usize>) -> Result<Compound, CollectError> {
        Ok(Compound::new(None))
    }
    fn serialize_struct(self, _: &'static str, _: usize) -> Result<Compound, CollectError> {
        Ok(Compound::new(None))
    }
    fn serialize_struct_variant(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        _: usize,
    ) -> Result<Compound, CollectError> {
        Ok(Compound::new(Some(variant)))
    }
}

impl ser::SerializeSeq for Compound {
    type Ok = Node;
    type Error = CollectError;
    fn serialize_element<T: ?Sized + Serialize>(&mut self, value: &T) -> Result<(), CollectError> {
        self.items.push(value.serialize(Collect)?);
        Ok(())
    }
    fn end(self) -> R {
        Ok(self.list())
    }
}

/// The tuple-like compounds serialise as lists, element by element like a sequence.
macro_rules! list_like {
    ($($trait:ident :: $method:ident),+) => {$(
        impl ser::$trait for Compound {
            type Ok = Node;
            type Error = CollectError;
            fn $method<T: ?Sized + Serialize>(&mut self, value: &T) -> Result<(), CollectError> {
                ser::SerializeSeq::serialize_element(self, value)
            }
            fn end(self) -> R {
                Ok(self.list())
            }
        }
    )+};
}

list_like!(
    SerializeTuple::serialize_element,
    SerializeTupleStruct::serialize_field,
    SerializeTupleVariant::serialize_field
);

impl ser::SerializeMap for Compound {
    type Ok = Node;
    type Error = CollectError;
    fn serialize_key<T: ?Sized + Serialize>(&mut self, key: &T) -> Result<(), CollectError> {
        self.key = Some(match key.serialize(Collect)? {
            Node::Text(k) => k,
            other => format!("{other:?}"),
        });
        Ok(())
    }
    fn serialize_value<T: ?Sized + Serialize>(&mut self, value: &T) -> Result<(), CollectError> {
        let key = self.key.take().unwrap_or_default();
        self.fields.push((key, value.serialize(Collect)?));
        Ok(())
    }
    fn end(self) -> R {
        Ok(self.table())
    }
}

/// Structs and struct variants serialise as tables, field by field.
macro_rules! table_like {
    ($($trait:ident),+) => {$(
        impl ser::$trait for Compound {
            type Ok = Node;
            type Error = CollectError;
            fn serialize_field<T: ?Sized + Serialize>(
                &mut self,
                key: &'static str,
                value: &T,
            ) -> Result<(), CollectError> {
                self.fields.push((key.to_string(), value.serialize(Collect)?));
                Ok(())
            }
            fn end(self) -> R {
                Ok(self.table())
            }
        }
    )+};
}

table_like!(SerializeStruct, SerializeStructVariant);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::CoreError;

    /// A quantisation step as the facility's: 0 (none) or 1e-9 to 1e6.
    #[derive(serde::Serialize, schemars::JsonSchema)]
    struct Step {
        #[schemars(range(min = 0.0, max = 1e6), extend("x-nonzero-minimum" = 1e-9))]
        step: f64,
    }

    /// The problems `check_ranges_of` records for a step, as (key, message).
    fn problems(step: f64) -> Vec<(String, String)> {
        let mut issues = Issues::default();
        check_ranges_of(
            &Step { step },
            &schemars::schema_for!(Step),
            "step",
            &mut issues,
        );
        match issues.finish() {
            Ok(()) => Vec::new(),
            Err(e @ CoreError::InvalidScenario { .. }) => {
                e.issues().into_iter().map(|i| (i.key, i.message)).collect()
            }
        }
    }

    #[test]
    fn a_nonzero_minimum_allows_0_and_refuses_tiny_steps() {
        for ok in [0.0, 1e-9, 0.5, 1e6] {
            assert_eq!(problems(ok), Vec::new(), "{ok}");
        }
        for tiny in [1e-308, 5e-324, 9.99e-10] {
            assert_eq!(
                problems(tiny),
                vec![(
                    "step".to_string(),
                    format!("must be 0 (none) or >= 1e-9, got {tiny:e}")
                )]
            );
        }
        // the range comes first: a negative step is out of range, not "tiny"
        let negative = problems(-1e-12);
        assert_eq!(negative.len(), 1);
        assert!(negative[0]
            .1
            .starts_with("must be between 0 and 1e6, got -"));
    }

    #[test]
    fn the_facility_s_quantisation_steps_have_the_nonzero_minimum() {
        let schema = serde_json::to_value(scenario_schema()).expect("schema");
        let facility = &schema["$defs"]["FacilityConfig"]["properties"];
        for key in ["force_resolution", "torque_resolution"] {
            assert_eq!(facility[key]["x-nonzero-minimum"], 1e-9, "{key}");
        }
    }
}
