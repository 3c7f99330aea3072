//! The spec text of a model an effect changed: the user's file with only
//! what the typed change touched written in (`toml_edit`), so comments, key
//! order and formatting survive. What `add-effect` writes, what diagnose
//! shows as a spec change, and what a derivation reads; and the spec with
//! calibrated values as its nominals ([`with_nominals`]).
use super::definition::role_key;
use super::ApplyError;
use crate::decl::Param;
use crate::expr::Expr;
use crate::spec::{Kinematics, Model};
use toml_edit::{value, Array, ArrayOfTables, DocumentMut, Item, Table};

/// `before`'s spec text with `after`'s changes: new parameters, effects
/// and observations appended; rewritten definitions, twist, constraint
/// coefficients, observation expressions and inverse written back; an
/// inverse `after` dropped removed.
pub(super) fn spec_text(before: &Model, after: &Model) -> Result<String, ApplyError> {
    let mut doc: DocumentMut = before
        .source
        .parse()
        .map_err(|e: toml_edit::TomlError| ApplyError::NotToml(e.to_string()))?;
    append_parameters(&mut doc, before, after)?;
    write_definitions(&mut doc, before, after);
    write_kinematics(&mut doc, before, after);
    write_observations(&mut doc, before, after)?;
    write_inverse(&mut doc, before, after);
    let added = after
        .effects
        .iter()
        .skip(before.effects.len())
        .map(String::as_str);
    // the effect list, a top-level key (rendered before the tables)
    match doc.get_mut("effects").and_then(Item::as_array_mut) {
        Some(a) => a.extend(added),
        None => {
            doc.insert("effects", value(Array::from_iter(added)));
        }
    }
    Ok(doc.to_string())
}

/// `model`'s spec text with each parameter of `values` given that nominal
/// value, written into its `[[parameter]]` table (the rest of the file as it
/// was). What `fit --export spec` writes: the calibration as the spec's own
/// values.
pub fn with_nominals(model: &Model, values: &[(&str, f64)]) -> Result<String, ApplyError> {
    let mut doc: DocumentMut = model
        .source
        .parse()
        .map_err(|e: toml_edit::TomlError| ApplyError::NotToml(e.to_string()))?;
    let arr = doc
        .entry("parameter")
        .or_insert(Item::ArrayOfTables(ArrayOfTables::new()))
        .as_array_of_tables_mut()
        .ok_or(ApplyError::Shape("`parameter` is not an array of tables"))?;
    for &(name, v) in values {
        let named = arr
            .iter_mut()
            .find(|t| t.get("name").and_then(|n| n.as_str()) == Some(name));
        match named {
            Some(t) => match t.get_mut("nominal").and_then(Item::as_value_mut) {
                Some(old) => {
                    let decor = old.decor().clone();
                    *old = v.into();
                    *old.decor_mut() = decor;
                }
                None => {
                    t.insert("nominal", value(v));
                }
            },
            None => {
                return Err(ApplyError::Shape(
                    "a calibrated parameter has no [[parameter]] table",
                ))
            }
        }
    }
    Ok(doc.to_string())
}

/// What adding an effect changes, for people: the lines that differ.
pub(super) fn line_change(before: &str, after: &str) -> String {
    let before: Vec<&str> = before.lines().collect();
    let mut s = String::new();
    // a line diff is enough: the edit keeps every untouched line as it was
    let mut i = 0;
    for line in after.lines() {
        if i < before.len() && before[i] == line {
            i += 1;
            continue;
        }
        match before[i..].iter().position(|b| *b == line) {
            Some(skip) if skip < 3 => {
                for b in &before[i..i + skip] {
                    s += &format!("- {b}\n");
                }
                i += skip + 1;
            }
            _ => s += &format!("+ {line}\n"),
        }
    }
    s
}

fn append_parameters(
    doc: &mut DocumentMut,
    before: &Model,
    after: &Model,
) -> Result<(), ApplyError> {
    let new: Vec<&Param> = after
        .params
        .iter()
        .filter(|p| !before.params.iter().any(|q| q.name == p.name))
        .collect();
    if new.is_empty() {
        return Ok(());
    }
    let arr = doc
        .entry("parameter")
        .or_insert(Item::ArrayOfTables(ArrayOfTables::new()))
        .as_array_of_tables_mut()
        .ok_or(ApplyError::Shape("`parameter` is not an array of tables"))?;
    for p in new {
        arr.push(parameter_table(p));
    }
    Ok(())
}

/// A parameter as a spec declares it (defaults left out).
fn parameter_table(p: &Param) -> Table {
    let mut t = Table::new();
    t.insert("name", value(&p.name));
    t.insert("nominal", value(p.nominal));
    if !p.unit.is_empty() {
        t.insert("unit", value(&p.unit));
    }
    for (k, b) in [("min", p.min), ("max", p.max), ("tolerance", p.tolerance)] {
        if let Some(b) = b {
            t.insert(k, value(b));
        }
    }
    for (k, set) in [
        ("const", p.constant),
        ("measurement_delay", p.measurement_delay),
        ("input_delay", p.input_delay),
        ("input_lag", p.input_lag),
    ] {
        if set {
            t.insert(k, value(true));
        }
    }
    if !p.free && !p.constant {
        t.insert("free", value(false));
    }
    if !p.doc.is_empty() {
        t.insert("doc", value(&p.doc));
    }
    t
}

/// Rewrite a string value in place when the expression changed, keeping
/// its surrounding whitespace and comment.
fn write_expr(item: Option<&mut Item>, old: &Expr, new: &Expr) {
    if old.same_as(new) {
        return;
    }
    if let Some(v) = item.and_then(Item::as_value_mut) {
        let decor = v.decor().clone();
        *v = new.to_string().into();
        *v.decor_mut() = decor;
    }
}

fn write_definitions(doc: &mut DocumentMut, before: &Model, after: &Model) {
    let tables = doc.get_mut("define").and_then(Item::as_array_of_tables_mut);
    for t in tables.into_iter().flat_map(|a| a.iter_mut()) {
        let Some(name) = t.get("name").and_then(|n| n.as_str()).map(str::to_string) else {
            continue;
        };
        let find = |m: &Model| m.defines.iter().find(|d| d.0 == name).map(|d| d.1.clone());
        if let (Some(old), Some(new)) = (find(before), find(after)) {
            write_expr(t.get_mut("expr"), &old, &new);
        }
    }
}

fn write_kinematics(doc: &mut DocumentMut, before: &Model, after: &Model) {
    match (&before.kinematics, &after.kinematics) {
        (Kinematics::Twist(old), Kinematics::Twist(new)) => {
            let Some(motion) = doc.get_mut("motion").and_then(Item::as_table_mut) else {
                return;
            };
            for (k, key) in ["vx", "vy", "omega"].into_iter().enumerate() {
                write_expr(motion.get_mut(key), &old[k], &new[k]);
            }
        }
        (Kinematics::Constraints(old), Kinematics::Constraints(new)) => {
            let rows = doc
                .get_mut("constraints")
                .and_then(|c| c.get_mut("row"))
                .and_then(Item::as_array_of_tables_mut);
            for row in rows.into_iter().flat_map(|a| a.iter_mut()) {
                let rate = row
                    .get("rate")
                    .and_then(|r| r.as_str())
                    .unwrap_or_default()
                    .to_string();
                let find = |c: &crate::spec::Constraints| {
                    c.rows.iter().find(|r| r.0 == rate).map(|r| r.1.clone())
                };
                let (Some(o), Some(n)) = (find(old), find(new)) else {
                    continue;
                };
                let Some(coeffs) = row.get_mut("coeffs").and_then(Item::as_array_mut) else {
                    continue;
                };
                for (j, c) in coeffs.iter_mut().enumerate().take(3) {
                    if !o[j].same_as(&n[j]) {
                        let decor = c.decor().clone();
                        *c = n[j].to_string().into();
                        *c.decor_mut() = decor;
                    }
                }
            }
        }
        _ => {}
    }
}

fn write_observations(
    doc: &mut DocumentMut,
    before: &Model,
    after: &Model,
) -> Result<(), ApplyError> {
    let arr = doc
        .entry("observation")
        .or_insert(Item::ArrayOfTables(ArrayOfTables::new()))
        .as_array_of_tables_mut()
        .ok_or(ApplyError::Shape("`observation` is not an array of tables"))?;
    for (k, obs) in after.observations.iter().enumerate() {
        let exprs: Array = obs.exprs.iter().map(|e| e.to_string()).collect();
        let Some(old) = before.observations.get(k) else {
            let mut t = Table::new();
            t.insert("name", value(&obs.name));
            t.insert("doc", value(&obs.doc));
            t.insert("columns", value(obs.columns.iter().collect::<Array>()));
            t.insert("angle", value(obs.angle.iter().copied().collect::<Array>()));
            t.insert("expr", value(exprs));
            // patched expressions need not show the role: declare it
            t.insert("role", value(role_key(obs.role)));
            arr.push(t);
            continue;
        };
        let same = old.exprs.len() == obs.exprs.len()
            && old.exprs.iter().zip(&obs.exprs).all(|(a, b)| a.same_as(b));
        let table = arr
            .get_mut(k)
            .ok_or(ApplyError::Shape("observation table not found"))?;
        if !same {
            table.insert("expr", value(exprs));
            // the patched expressions no longer show the role: declare it
            if !table.contains_key("role") {
                table.insert("role", value(role_key(obs.role)));
            }
        }
    }
    if arr.is_empty() {
        doc.remove("observation");
    }
    Ok(())
}

fn write_inverse(doc: &mut DocumentMut, before: &Model, after: &Model) {
    match (&before.inverse, &after.inverse) {
        (Some(_), None) => {
            doc.remove("inverse");
        }
        (Some((old, _)), Some((new, _))) => {
            let inputs = doc
                .get_mut("inverse")
                .and_then(|i| i.get_mut("inputs"))
                .and_then(Item::as_array_mut);
            for (k, v) in inputs.into_iter().flat_map(|a| a.iter_mut().enumerate()) {
                if let (Some(o), Some(n)) = (old.get(k), new.get(k)) {
                    if !o.same_as(n) {
                        let decor = v.decor().clone();
                        *v = n.to_string().into();
                        *v.decor_mut() = decor;
                    }
                }
            }
        }
        _ => {}
    }
}
