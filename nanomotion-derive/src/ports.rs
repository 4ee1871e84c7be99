//! The `ports = "…"` of `#[block(…)]`: read as a declaration of the block's
//! ports when it is one, and shown as written (less its markers) in any case.
//!
//! A declaration is `inputs -> outputs`, each side a comma-separated list
//! (either side may be empty) of
//!
//! ```text
//! name[width] (unit) [scheduling]
//! name[width] [unit of input]
//! ```
//!
//! - `[width]` (optional, default 1): a whole number, or the name of a `usize`
//!   field of the parameter struct (`y[width]` is `self.width` wide);
//! - `(unit)` (optional): an SI unit (`m`, `m/s²`, `V`, `rad`, `count`), which the
//!   port then carries (`Port::with_unit`);
//! - `[scheduling]` (inputs only): a scheduling input (`Port::scheduling_input`);
//! - `[unit of u]` (outputs only, instead of a `(unit)`): the output is in the
//!   unit of input `u`, whatever that is when the graph is built
//!   (`Port::unit_of_input`: sums, delays, filters, rate transitions).
//!
//! The markers are not shown in `nanomotion blocks`.
//!
//! Anything else (prose in parentheses, `...`, `<inner inputs>`, a width that
//! is not a field, `[, optional port]`) makes the string a description only:
//! the block then writes `inputs`/`outputs` itself.

use proc_macro2::TokenStream as TokenStream2;
use quote::{format_ident, quote};

/// The marker of a scheduling input.
const SCHEDULING: &str = "[scheduling]";
/// The start of the marker of an output in the unit of an input,
/// `[unit of u]`.
const UNIT_OF: &str = "[unit of ";

/// One declared port.
#[derive(Debug, PartialEq)]
pub(crate) struct PortDecl {
    pub name: String,
    pub width: Width,
    pub unit: Option<String>,
    pub scheduling: bool,
    /// `[unit of u]`: the input named, then (once the inputs are known) its
    /// index.
    pub unit_of: Option<UnitOf>,
}

/// The input an output takes its unit from.
#[derive(Debug, PartialEq)]
pub(crate) enum UnitOf {
    Named(String),
    Input(usize),
}

/// The ports a `ports` string declares.
#[derive(Debug, PartialEq)]
pub(crate) struct Declaration {
    pub inputs: Vec<PortDecl>,
    pub outputs: Vec<PortDecl>,
}

/// A declared width.
#[derive(Debug, PartialEq)]
pub(crate) enum Width {
    Fixed(usize),
    Field(String),
}

/// The text shown for `ports`: as written, without the `[scheduling]` and
/// `[unit of …]` markers (and the blank before each).
pub(crate) fn shown(ports: &str) -> String {
    let mut out = String::with_capacity(ports.len());
    let mut rest = ports;
    loop {
        let next = [SCHEDULING, UNIT_OF]
            .iter()
            .filter_map(|m| rest.find(m).map(|at| (at, *m)))
            .min();
        let Some((at, marker)) = next else { break };
        let end = if marker == UNIT_OF {
            match rest[at..].find(']') {
                Some(close) => at + close + 1,
                None => break,
            }
        } else {
            at + marker.len()
        };
        out.push_str(rest[..at].trim_end());
        rest = &rest[end..];
    }
    out.push_str(rest);
    out
}

/// The ports declared by `ports`, if it is a declaration (module doc); `fields`
/// are the parameter struct's field names. `Err`: a marker where it cannot
/// stand (a compile error, not prose).
pub(crate) fn declared(ports: &str, fields: &[String]) -> Result<Option<Declaration>, String> {
    let Some((ins, outs)) = ports.split_once("->") else {
        return Ok(None);
    };
    if outs.contains("->") {
        return Ok(None);
    }
    let (Some(ins), Some(outs)) = (side(ins, fields), side(outs, fields)) else {
        return Ok(None);
    };
    if let Some(p) = outs.iter().find(|p| p.scheduling) {
        return Err(format!(
            "`{}` is an output: only an input can be a scheduling input",
            p.name
        ));
    }
    if let Some(p) = ins.iter().find(|p| p.unit_of.is_some()) {
        return Err(format!(
            "`{}` is an input: only an output can be `[unit of …]` an input",
            p.name
        ));
    }
    let mut outs = outs;
    for p in &mut outs {
        let Some(UnitOf::Named(from)) = &p.unit_of else {
            continue;
        };
        if p.unit.is_some() {
            return Err(format!(
                "`{}` has a unit and `[unit of {from}]`: give one of them",
                p.name
            ));
        }
        let Some(k) = ins.iter().position(|i| &i.name == from) else {
            return Err(format!(
                "`{}` is `[unit of {from}]`, but there is no input `{from}`: name one of the inputs",
                p.name
            ));
        };
        p.unit_of = Some(UnitOf::Input(k));
    }
    Ok(Some(Declaration {
        inputs: ins,
        outputs: outs,
    }))
}

/// One side of `->`: its ports, or `None` if an entry is not a port declaration.
fn side(text: &str, fields: &[String]) -> Option<Vec<PortDecl>> {
    let text = text.trim();
    if text.is_empty() {
        return Some(Vec::new());
    }
    let mut ports = Vec::new();
    let mut depth = 0i32;
    let mut start = 0;
    for (i, c) in text.char_indices() {
        match c {
            '(' | '[' => depth += 1,
            ')' | ']' => depth -= 1,
            ',' if depth == 0 => {
                ports.push(port(&text[start..i], fields)?);
                start = i + 1;
            }
            _ => {}
        }
    }
    ports.push(port(&text[start..], fields)?);
    Some(ports)
}

/// `name[width] (unit) [scheduling]` or `name[width] [unit of input]`, each
/// part after the name optional.
fn port(text: &str, fields: &[String]) -> Option<PortDecl> {
    let mut rest = text.trim();
    let scheduling = match rest.strip_suffix(SCHEDULING) {
        Some(r) => {
            rest = r.trim_end();
            true
        }
        None => false,
    };
    let unit_of = match rest.rfind(UNIT_OF) {
        Some(at) if rest.ends_with(']') => {
            let from = &rest[at + UNIT_OF.len()..rest.len() - 1];
            if !is_name(from) {
                return None;
            }
            rest = rest[..at].trim_end();
            Some(UnitOf::Named(from.to_string()))
        }
        _ => None,
    };
    let unit = match rest.strip_suffix(')') {
        Some(r) => {
            let open = r.rfind('(')?;
            let unit = &r[open + 1..];
            if !is_si_unit(unit) {
                return None;
            }
            rest = r[..open].trim_end();
            Some(unit.to_string())
        }
        None => None,
    };
    let (name, width) = match rest.strip_suffix(']') {
        Some(r) => {
            let open = r.find('[')?;
            let w = &r[open + 1..];
            let width = if let Ok(n) = w.parse::<usize>() {
                Width::Fixed(n)
            } else if fields.iter().any(|f| f == w) {
                Width::Field(w.to_string())
            } else {
                return None;
            };
            (&r[..open], width)
        }
        None => (rest, Width::Fixed(1)),
    };
    if !is_name(name) {
        return None;
    }
    Some(PortDecl {
        name: name.to_string(),
        width,
        unit,
        scheduling,
        unit_of,
    })
}

/// Whether `text` is a port name (an ASCII identifier).
fn is_name(text: &str) -> bool {
    let mut chars = text.chars();
    let first_ok = chars
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_');
    first_ok && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// Whether `text` is an SI unit: factors joined by `/` or `·`, each an
/// optionally prefixed unit symbol with an optional power (`m`, `m/s²`, `µm`,
/// `rad/s`, `N·m`, `count`).
fn is_si_unit(text: &str) -> bool {
    const SYMBOLS: [&str; 17] = [
        "m", "s", "g", "A", "K", "V", "N", "W", "J", "Hz", "Pa", "rad", "Ω", "C", "T", "F", "H",
    ];
    const PREFIXES: [&str; 8] = ["p", "n", "µ", "μ", "m", "c", "k", "M"];
    let symbol = |s: &str| {
        SYMBOLS.contains(&s)
            || PREFIXES
                .iter()
                .any(|p| s.strip_prefix(p).is_some_and(|b| SYMBOLS.contains(&b)))
    };
    if text == "count" {
        return true;
    }
    !text.is_empty()
        && text.split(['/', '·']).all(|factor| {
            let base = factor.trim_end_matches(['²', '³']);
            let base = match base.split_once('^') {
                Some((b, p)) if !p.is_empty() && p.chars().all(|c| c.is_ascii_digit()) => b,
                Some(_) => return false,
                None => base,
            };
            symbol(base)
        })
}

/// `vec![Port::new(…)…, …]` for `ports`.
pub(crate) fn port_list(ports: &[PortDecl]) -> TokenStream2 {
    let items = ports.iter().map(|p| {
        let name = &p.name;
        let width = match &p.width {
            Width::Fixed(n) => quote!(#n),
            Width::Field(f) => {
                let f = format_ident!("{f}");
                quote!(self.#f)
            }
        };
        let unit = p.unit.as_ref().map(|u| quote!(.with_unit(#u)));
        let scheduling = p.scheduling.then(|| quote!(.scheduling_input()));
        let unit_of = match &p.unit_of {
            Some(UnitOf::Input(k)) => quote!(.unit_of_input(#k)),
            // `declared` resolves every name to an index
            Some(UnitOf::Named(_)) | None => quote!(),
        };
        quote!(::nanomotion_core::Port::new(#name, #width) #unit #scheduling #unit_of)
    });
    quote!(::std::vec![#(#items),*])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fields() -> Vec<String> {
        vec!["width".into()]
    }

    fn port(name: &str, width: Width, unit: Option<&str>, scheduling: bool) -> PortDecl {
        PortDecl {
            name: name.into(),
            width,
            unit: unit.map(String::from),
            scheduling,
            unit_of: None,
        }
    }

    #[test]
    fn a_declaration_reads_names_widths_units_and_markers() {
        let d = declared("e, alpha [scheduling] -> w, n", &fields())
            .unwrap()
            .unwrap();
        let (ins, outs) = (d.inputs, d.outputs);
        assert_eq!(
            ins,
            [
                port("e", Width::Fixed(1), None, false),
                port("alpha", Width::Fixed(1), None, true)
            ]
        );
        assert_eq!(outs.len(), 2);
        let d = declared("-> y[width], v (m/s), a[3] (m/s²)", &fields())
            .unwrap()
            .unwrap();
        let (ins, outs) = (d.inputs, d.outputs);
        assert!(ins.is_empty());
        assert_eq!(
            outs,
            [
                port("y", Width::Field("width".into()), None, false),
                port("v", Width::Fixed(1), Some("m/s"), false),
                port("a", Width::Fixed(3), Some("m/s²"), false)
            ]
        );
        let d = declared("u -> y (count)", &fields()).unwrap().unwrap();
        assert_eq!(d.outputs[0].unit.as_deref(), Some("count"));
    }

    #[test]
    fn prose_is_a_description_only() {
        for text in [
            "in0[n], in1[n], ... -> y[n]",
            "u[n] -> y[n]",
            "<inner inputs>, sigma[n] [scheduling] -> <inner outputs>, gain",
            "u (position) -> y (force)",
            "f_alpha[1] (Hz) -> x_s[1] (m), faults[1] (count of non-finite inputs)",
            "-> r[2] (x_r, y_r m), line (index or −1), rc_on (0/1)",
            "u (, s) -> y",
            "f_alpha (Hz) [, amplitude (V)] [, phase (rad)] -> u[4] (V)",
            "register[2+2n] -> y[3] = [x, v, a], status",
            "no arrow",
        ] {
            assert_eq!(declared(text, &fields()), Ok(None), "{text}");
        }
    }

    #[test]
    fn an_output_in_the_unit_of_an_input_names_it() {
        let d = declared("e, u[width] -> y[width] [unit of u], n", &fields())
            .unwrap()
            .unwrap();
        assert_eq!(d.outputs[0].unit_of, Some(UnitOf::Input(1)));
        assert_eq!(d.outputs[0].width, Width::Field("width".into()));
        assert_eq!(d.outputs[1].unit_of, None);
        let out = port_list(&d.outputs).to_string();
        assert!(out.contains(". unit_of_input (1usize)"), "{out}");
    }

    #[test]
    fn a_marker_where_it_cannot_stand_is_refused() {
        for text in [
            "u -> y [scheduling]",
            "u [unit of u] -> y",
            "u -> y [unit of v]",
            "u -> y (m) [unit of u]",
        ] {
            assert!(declared(text, &fields()).is_err(), "{text}");
        }
        // not a name: prose
        assert_eq!(declared("u -> y [unit of the input]", &fields()), Ok(None));
    }

    #[test]
    fn markers_are_not_shown() {
        assert_eq!(shown("e, alpha [scheduling] -> w, n"), "e, alpha -> w, n");
        assert_eq!(
            shown("<inner inputs>, sigma[n] [scheduling] -> <inner outputs>, gain"),
            "<inner inputs>, sigma[n] -> <inner outputs>, gain"
        );
        assert_eq!(shown("u -> y"), "u -> y");
        assert_eq!(
            shown("u[width] -> y[width] [unit of u]"),
            "u[width] -> y[width]"
        );
        assert_eq!(
            shown("e, a [scheduling] -> y [unit of e], n"),
            "e, a -> y, n"
        );
    }

    #[test]
    fn units_are_si_symbols() {
        for u in [
            "m", "m/s", "m/s²", "µm", "rad/s", "N·m", "Hz", "V", "count", "m^2",
        ] {
            assert!(is_si_unit(u), "{u}");
        }
        for u in ["position", "0/1", "index or −1", "", "m^", "units"] {
            assert!(!is_si_unit(u), "{u}");
        }
    }
}
