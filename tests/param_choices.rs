//! Every choice a block parameter lists (`nanomotion blocks`, `nanomotion
//! schema`) is derived from the enum serde reads it with: each listed name is
//! accepted by the block's own deserialiser, and a name outside the list is
//! refused by serde with names that are all in the list. Covers plain choices
//! (`discretisation: zoh | tustin`, an `enum` list), tagged ones
//! (`shape: {kind: sinusoidal | asymmetric | …}`), externally tagged ones
//! (`topography: flat | {grating: {…}}`) and lists of them (`schedule`).

use nanomotion::core::Block;
use nanomotion::core::block::block_docs;
use serde_json::{Value, json};

/// The names serde says it expects: "expected `a`", "expected `a` or `b`",
/// "expected one of `a`, `b`, `c`".
fn serde_names(message: &str) -> Vec<String> {
    let Some(pos) = message.find("expected ") else {
        return Vec::new();
    };
    let rest = &message[pos + "expected ".len()..];
    let line = rest.split(" at line ").next().unwrap_or(rest);
    line.split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect()
}

/// A block of type `t` with the one parameter `name: value`, read as a graph
/// entry is read (typetag on `type`).
fn read(t: &str, name: &str, value: Value) -> Result<(), String> {
    let mut entry = serde_json::Map::new();
    entry.insert("type".into(), json!(t));
    entry.insert(name.into(), value);
    serde_json::from_value::<Box<dyn Block>>(Value::Object(entry))
        .map(|_| ())
        .map_err(|e| e.to_string())
}

/// The choices of a parameter's schema: `(None, names)` for an `enum` list or
/// an externally tagged enum (a name, or a map from the name to the data),
/// `(Some(tag), names)` for variants told apart by a constant `tag` field; and
/// whether the parameter is a list of them.
fn choices(schema: &Value) -> Option<(Option<String>, Vec<String>, bool)> {
    let mut s = schema;
    // an optional value: its non-null branch
    if let Some(a) = s.get("anyOf").and_then(Value::as_array)
        && a.len() == 2
        && a[1].get("type") == Some(&json!("null"))
    {
        s = &a[0];
    }
    let list = s.get("type") == Some(&json!("array"));
    if list {
        s = s.get("items")?;
    }
    if let Some(names) = s.get("enum").and_then(Value::as_array) {
        let names = names
            .iter()
            .map(|v| v.as_str().expect("string choices").to_string())
            .collect();
        return Some((None, names, list));
    }
    let branches = s.get("anyOf")?.as_array()?;
    let mut tag = None;
    let mut names = Vec::new();
    for b in branches {
        if let Some(name) = b.get("const").and_then(Value::as_str) {
            // externally tagged: a variant without data is its name
            names.push(name.to_string());
            continue;
        }
        let props = b.get("properties")?.as_object()?;
        match props
            .iter()
            .find_map(|(k, v)| Some((k.clone(), v.get("const")?.as_str()?.to_string())))
        {
            Some((k, c)) => {
                if tag.get_or_insert_with(|| k.clone()) != &k {
                    return None;
                }
                names.push(c);
            }
            // externally tagged: a variant with data is a map from its name
            None if props.len() == 1 => names.extend(props.keys().cloned()),
            None => return None,
        }
    }
    Some((tag, names, list))
}

const NOT_A_CHOICE: &str = "not_a_choice_of_any_block";

#[test]
fn every_listed_choice_is_what_serde_accepts() {
    nanomotion::link_plugins();
    let mut checked = Vec::new();
    for doc in block_docs() {
        for p in doc.param_docs().iter().filter(|p| !p.flatten) {
            let Some((tag, names, list)) = choices(&p.schema) else {
                continue;
            };
            let wrap = |n: &str| {
                let v = match &tag {
                    None => json!(n),
                    Some(t) => json!({ t.as_str(): n }),
                };
                if list { json!([v]) } else { v }
            };
            let place = format!("{}.{}", doc.type_name, p.name);
            for n in &names {
                if let Err(e) = read(doc.type_name, p.name, wrap(n)) {
                    assert!(
                        !e.contains("unknown variant"),
                        "{place}: the listed choice `{n}` is refused: {e}"
                    );
                }
            }
            let e = read(doc.type_name, p.name, wrap(NOT_A_CHOICE))
                .expect_err(&format!("{place}: `{NOT_A_CHOICE}` was accepted"));
            assert!(
                e.contains(&format!("unknown variant `{NOT_A_CHOICE}`")),
                "{place}: a name outside {names:?} gives another error: {e}"
            );
            let known = serde_names(&e);
            assert!(!known.is_empty(), "{place}: {e}");
            for k in &known {
                assert!(
                    names.contains(k),
                    "{place}: serde accepts `{k}`, the listing does not show it ({names:?})"
                );
            }
            checked.push((place, names));
        }
    }
    let find = |place: &str| {
        checked
            .iter()
            .find(|(p, _)| p == place)
            .map(|(_, n)| n.clone())
            .unwrap_or_else(|| panic!("{place} lists no choices; checked: {checked:#?}"))
    };
    // enums that list their choices since they derive `Params` (#26)
    assert_eq!(find("rotation_estimator.on_failure"), ["stop", "plain_rc"]);
    assert_eq!(
        find("frame_rotation.direction"),
        ["to_sample", "to_actuator"]
    );
    assert_eq!(
        find("walking_piezo_driver.shape"),
        [
            "sinusoidal",
            "asymmetric",
            "asymmetric_fourier",
            "rhombic",
            "free"
        ]
    );
    // an externally tagged enum (a name, or a map from the name to its data)
    assert_eq!(find("afm_stage.topography"), ["flat", "grating"]);
    // a list of internally tagged laws
    assert_eq!(
        find("gain_scheduled.schedule"),
        ["constant", "table", "table_db", "power_db"]
    );
    assert!(
        checked.len() >= 10,
        "only {} parameters with choices: {checked:#?}",
        checked.len()
    );
}
