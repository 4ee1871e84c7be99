//! The `ports = "…"` of `#[block(…)]`: read as a declaration of the block's
//! ports when it is one, and shown as written (less its markers) in any case.
//!
//! A declaration is `inputs -> outputs`, each side a comma-separated list
//! (either side may be empty) of
//!
//! ```text
//! name[width] (unit) "note" [scheduling]
//! name[width] "note" [unit of input]
//! name[width] (unit) if flag
//! name{i}[width] (unit) for i in 0..count
//! ```
//!
//! - `[width]` (optional, default 1): a whole number, the name of a `usize`
//!   field of the parameter struct (`y[width]` is `self.width` wide), or the
//!   sum of a list of widths, `[Σwidths]`;
//! - `(unit)` (optional): an SI unit (`m`, `m/s²`, `V`, `rad`, `count`), which the
//!   port then carries (`Port::with_unit`);
//! - `"note"` (optional): words for the reader, shown in parentheses in the
//!   listing (`pair[1] "1 or 2"` lists as `pair[1] (1 or 2)`), right after a
//!   unit inside its parentheses (`faults (count) "of non-finite inputs"` lists
//!   as `faults (count of non-finite inputs)`); the port carries no unit from it;
//! - `[scheduling]` (inputs only): a scheduling input (`Port::scheduling_input`);
//! - `[unit of u]` (outputs only, instead of a `(unit)`): the output is in the
//!   unit of input `u`, whatever that is when the graph is built
//!   (`Port::unit_of_input`: sums, delays, filters, rate transitions); `u` is an
//!   input that every input before it precedes unconditionally, or the first of
//!   a repeated group (`[unit of in0]`);
//! - `if flag`: the port exists when the `bool` field `flag` is true (a driver's
//!   optional amplitude input);
//! - `for i in 0..count`: a repeated group, one port per `i`, named with `{i}`
//!   in its name (`in{i}` gives `in0`, `in1`, …): `count` a `usize` field
//!   (`0..factors`) or the entries of a list or the characters of a string
//!   (`0..len(widths)`, `0..len(signs)`); with `0..len(widths)`, port `i` may be
//!   `[widths[i]]` wide.
//!
//! In a `#[serde(transparent)]` block (its parameters one wrapped struct),
//! the names are the wrapped struct's fields (`self.params.amplitude_input`);
//! the derive cannot see them, so any name is taken and the compiler checks it.
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
    /// The name; in a repeated group with `{i}` standing for the index.
    pub name: String,
    pub width: Width,
    pub unit: Option<String>,
    pub scheduling: bool,
    /// `[unit of u]`: the input named, then (once the inputs are known) its
    /// index.
    pub unit_of: Option<UnitOf>,
    /// `if flag`: the field whose truth makes the port exist.
    pub when: Option<String>,
    /// `for i in 0..count`: a repeated group.
    pub repeat: Option<Repeat>,
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
    /// `[Σwidths]`: the sum of a list field.
    Sum(String),
    /// `[widths[i]]` in a group `for i in 0..len(widths)`: entry `i` (the
    /// list, the index).
    Entry(String, String),
}

/// A repeated group, `for var in 0..count`.
#[derive(Debug, PartialEq)]
pub(crate) struct Repeat {
    pub var: String,
    pub count: Count,
}

/// How many ports a repeated group has.
#[derive(Debug, PartialEq)]
pub(crate) enum Count {
    /// `0..factors`: a `usize` field.
    Field(String),
    /// `0..len(widths)`: the entries of a list (the characters of a string).
    Len(String),
}

/// The fields a declaration may name.
pub(crate) struct Fields {
    /// The parameter struct's field names.
    pub names: Vec<String>,
    /// `#[serde(transparent)]`: the wrapped field, whose own fields (unseen
    /// here) the declaration names.
    pub wrapped: Option<String>,
}

impl Fields {
    /// Whether `name` can be a field the declaration names.
    fn has(&self, name: &str) -> bool {
        match &self.wrapped {
            Some(_) => is_name(name),
            None => self.names.iter().any(|f| f == name),
        }
    }
    /// `self.name`, or `self.wrapped.name`.
    fn access(&self, name: &str) -> TokenStream2 {
        let f = format_ident!("{name}");
        match &self.wrapped {
            Some(w) => {
                let w = format_ident!("{w}");
                quote!(self.#w.#f)
            }
            None => quote!(self.#f),
        }
    }
}

/// The text shown for `ports`: as written, without the `[scheduling]` and
/// `[unit of …]` markers (and the blank before each), a `"note"` in
/// parentheses (after a unit, in the unit's).
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
    // a note in parentheses; right after a unit, inside the unit's
    let mut shown = String::with_capacity(out.len());
    let mut in_note = false;
    for c in out.chars() {
        match c {
            '"' if !in_note => {
                in_note = true;
                let before = shown.trim_end().len();
                if shown[..before].ends_with(')') {
                    shown.truncate(before - 1);
                    shown.push(' ');
                } else {
                    shown.push('(');
                }
            }
            '"' => {
                in_note = false;
                shown.push(')');
            }
            c => shown.push(c),
        }
    }
    shown
}

/// The ports declared by `ports`, if it is a declaration (module doc); `fields`
/// are the parameter struct's fields. `Err`: a marker or clause where it cannot
/// stand (a compile error, not prose).
pub(crate) fn declared(ports: &str, fields: &Fields) -> Result<Option<Declaration>, String> {
    let Some((ins, outs)) = ports.split_once("->") else {
        return Ok(None);
    };
    if outs.contains("->") {
        return Ok(None);
    }
    let (Some(ins), Some(outs)) = (side(ins, fields)?, side(outs, fields)?) else {
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
        let Some(k) = ins.iter().position(|i| &first_name(i) == from) else {
            return Err(format!(
                "`{}` is `[unit of {from}]`, but there is no input `{from}`: name one of the inputs (the first of a repeated group: `in0` of `in{{i}}`)",
                p.name
            ));
        };
        if ins[k].when.is_some() {
            return Err(format!(
                "`{}` is `[unit of {from}]`, but `{from}` exists only `if {}`: name an input that is always there",
                p.name,
                ins[k].when.as_deref().unwrap_or_default()
            ));
        }
        if let Some(before) = ins[..k]
            .iter()
            .find(|i| i.when.is_some() || i.repeat.is_some())
        {
            return Err(format!(
                "`{}` is `[unit of {from}]`, but the input `{}` before `{from}` may be there or not, or repeated, so `{from}`'s place is not known: put `{from}` before it",
                p.name, before.name
            ));
        }
        p.unit_of = Some(UnitOf::Input(k));
    }
    Ok(Some(Declaration {
        inputs: ins,
        outputs: outs,
    }))
}

/// A port's name, or the name of the first port of a repeated group (`in0` of
/// `in{i}`).
fn first_name(p: &PortDecl) -> String {
    match &p.repeat {
        Some(r) => p.name.replace(&format!("{{{}}}", r.var), "0"),
        None => p.name.clone(),
    }
}

/// One side of `->`: its ports, or `None` if an entry is not a port declaration.
fn side(text: &str, fields: &Fields) -> Result<Option<Vec<PortDecl>>, String> {
    let text = text.trim();
    if text.is_empty() {
        return Ok(Some(Vec::new()));
    }
    let mut ports = Vec::new();
    let mut depth = 0i32;
    let mut quoted = false;
    let mut start = 0;
    for (i, c) in text.char_indices() {
        match c {
            '"' => quoted = !quoted,
            _ if quoted => {}
            '(' | '[' => depth += 1,
            ')' | ']' => depth -= 1,
            ',' if depth == 0 => {
                let Some(p) = port(&text[start..i], fields)? else {
                    return Ok(None);
                };
                ports.push(p);
                start = i + 1;
            }
            _ => {}
        }
    }
    let Some(p) = port(&text[start..], fields)? else {
        return Ok(None);
    };
    ports.push(p);
    Ok(Some(ports))
}

/// `name[width] (unit) "note" [scheduling]` or `name[width] [unit of input]`,
/// each part after the name optional, then optionally `if flag` or `for i in
/// 0..count`. `Ok(None)`: not a port declaration (prose); `Err`: a declaration
/// with a clause that cannot stand.
fn port(text: &str, fields: &Fields) -> Result<Option<PortDecl>, String> {
    let text = text.trim();
    // the note, cut out: its words may hold anything but a quote
    let unquoted;
    let mut rest = match (text.find('"'), text.rfind('"')) {
        (None, None) => text,
        (Some(a), Some(b)) if a < b && !text[a + 1..b].contains('"') => {
            unquoted = format!("{} {}", &text[..a], &text[b + 1..]);
            unquoted.trim()
        }
        _ => return Ok(None),
    };
    let mut when = None;
    let mut repeat = None;
    if let Some(at) = rest.rfind(" for ") {
        let Some(r) = repeated(&rest[at + 5..], fields) else {
            return Ok(None);
        };
        repeat = Some(r);
        rest = rest[..at].trim_end();
    } else if let Some(at) = rest.rfind(" if ") {
        let flag = rest[at + 4..].trim();
        if !fields.has(flag) {
            return Ok(None);
        }
        when = Some(flag.to_string());
        rest = rest[..at].trim_end();
    }
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
                return Ok(None);
            }
            rest = rest[..at].trim_end();
            Some(UnitOf::Named(from.to_string()))
        }
        _ => None,
    };
    let unit = match rest.strip_suffix(')') {
        Some(r) => {
            let Some(open) = r.rfind('(') else {
                return Ok(None);
            };
            let unit = &r[open + 1..];
            if !is_si_unit(unit) {
                return Ok(None);
            }
            rest = r[..open].trim_end();
            Some(unit.to_string())
        }
        None => None,
    };
    let (name, width) = match rest.strip_suffix(']') {
        Some(r) => {
            let Some(open) = r.find('[') else {
                return Ok(None);
            };
            let Some(width) = width(&r[open + 1..], fields) else {
                return Ok(None);
            };
            (&r[..open], width)
        }
        None => (rest, Width::Fixed(1)),
    };
    let named = match &repeat {
        Some(Repeat { var, .. }) => {
            let slot = format!("{{{var}}}");
            name.matches(&slot).count() == 1 && is_name(&name.replace(&slot, "0"))
        }
        None => is_name(name),
    };
    if !named {
        return Ok(None);
    }
    if let Width::Entry(list, index) = &width {
        let fits = matches!(
            &repeat,
            Some(Repeat { var, count: Count::Len(of) }) if of == list && var == index
        );
        if !fits {
            return Err(format!(
                "`{name}` is `[{list}[…]]` wide, an entry of `{list}`: declare it `for i in 0..len({list})` and give it `[{list}[i]]`"
            ));
        }
    }
    Ok(Some(PortDecl {
        name: name.to_string(),
        width,
        unit,
        scheduling,
        unit_of,
        when,
        repeat,
    }))
}

/// `i in 0..count` or `i in 0..len(list)`.
fn repeated(text: &str, fields: &Fields) -> Option<Repeat> {
    let mut words = text.split_whitespace();
    let (var, in_, range) = (words.next()?, words.next()?, words.next()?);
    if words.next().is_some() || in_ != "in" || !is_name(var) {
        return None;
    }
    let count = range.strip_prefix("0..")?;
    let count = match count.strip_prefix("len(").and_then(|c| c.strip_suffix(')')) {
        Some(list) if fields.has(list) => Count::Len(list.to_string()),
        Some(_) => return None,
        None if fields.has(count) => Count::Field(count.to_string()),
        None => return None,
    };
    Some(Repeat {
        var: var.to_string(),
        count,
    })
}

/// The width between `[` and `]`: a number, a field, `Σlist` or `list[i]`.
fn width(w: &str, fields: &Fields) -> Option<Width> {
    if let Ok(n) = w.parse::<usize>() {
        return Some(Width::Fixed(n));
    }
    if let Some(list) = w.strip_prefix('Σ') {
        return fields.has(list).then(|| Width::Sum(list.to_string()));
    }
    if let Some((list, var)) = w.strip_suffix(']').and_then(|w| w.split_once('[')) {
        // the index is checked against the group's variable by the caller
        return (fields.has(list) && is_name(var))
            .then(|| Width::Entry(list.to_string(), var.to_string()));
    }
    fields.has(w).then(|| Width::Field(w.to_string()))
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

/// The code of the list of `ports`: `vec![Port::new(…)…, …]` when every port
/// is always there once, a list built port by port otherwise.
pub(crate) fn port_list(ports: &[PortDecl], fields: &Fields) -> TokenStream2 {
    let port = |p: &PortDecl, name: TokenStream2, width: TokenStream2| {
        let unit = p.unit.as_ref().map(|u| quote!(.with_unit(#u)));
        let scheduling = p.scheduling.then(|| quote!(.scheduling_input()));
        let unit_of = match &p.unit_of {
            Some(UnitOf::Input(k)) => quote!(.unit_of_input(#k)),
            // `declared` resolves every name to an index
            Some(UnitOf::Named(_)) | None => quote!(),
        };
        quote!(::nanomotion_core::Port::new(#name, #width) #unit #scheduling #unit_of)
    };
    let width = |w: &Width| match w {
        Width::Fixed(n) => quote!(#n),
        Width::Field(f) => fields.access(f),
        Width::Sum(list) => {
            let list = fields.access(list);
            quote!(#list.iter().fold(0usize, |__a, &__w| __a.saturating_add(__w)))
        }
        // only in a group over the list's entries, which binds `__w`
        Width::Entry(..) => quote!(__w),
    };
    if ports.iter().all(|p| p.when.is_none() && p.repeat.is_none()) {
        let items = ports.iter().map(|p| {
            let name = &p.name;
            port(p, quote!(#name), width(&p.width))
        });
        return quote!(::std::vec![#(#items),*]);
    }
    let steps = ports.iter().map(|p| {
        let Some(r) = &p.repeat else {
            let name = &p.name;
            let one = port(p, quote!(#name), width(&p.width));
            return match &p.when {
                Some(flag) => {
                    let flag = fields.access(flag);
                    quote!(if #flag { __ports.push(#one); })
                }
                None => quote!(__ports.push(#one);),
            };
        };
        let var = format_ident!("{}", r.var);
        let format = p.name.replace(&format!("{{{}}}", r.var), "{}");
        let one = port(p, quote!(::std::format!(#format, #var)), width(&p.width));
        match (&r.count, &p.width) {
            (Count::Len(list), Width::Entry(..)) => {
                let list = fields.access(list);
                quote!(__ports.extend(#list.iter().enumerate().map(|(#var, &__w)| #one));)
            }
            (Count::Len(list), _) => {
                let list = fields.access(list);
                quote!(__ports.extend(
                    (0..::nanomotion_core::doc::__derive::port_count(&#list)).map(|#var| #one)
                );)
            }
            (Count::Field(n), _) => {
                let n = fields.access(n);
                quote!(__ports.extend((0..#n).map(|#var| #one));)
            }
        }
    });
    quote!({
        let mut __ports = ::std::vec::Vec::new();
        #(#steps)*
        __ports
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fields() -> Fields {
        Fields {
            names: vec!["width".into()],
            wrapped: None,
        }
    }

    /// The fields of a block with lists, counts and flags.
    fn more_fields() -> Fields {
        Fields {
            names: ["width", "widths", "signs", "factors", "phase_input"]
                .map(String::from)
                .to_vec(),
            wrapped: None,
        }
    }

    fn port(name: &str, width: Width, unit: Option<&str>, scheduling: bool) -> PortDecl {
        PortDecl {
            name: name.into(),
            width,
            unit: unit.map(String::from),
            scheduling,
            unit_of: None,
            when: None,
            repeat: None,
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
        let out = port_list(&d.outputs, &fields()).to_string();
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

    #[test]
    fn a_repeated_group_counts_its_ports_from_a_field_or_a_list() {
        let d = declared(
            "in{i}[width] for i in 0..len(signs) -> y[width] [unit of in0]",
            &more_fields(),
        )
        .unwrap()
        .unwrap();
        let group = &d.inputs[0];
        assert_eq!(group.name, "in{i}");
        assert_eq!(
            group.repeat,
            Some(Repeat {
                var: "i".into(),
                count: Count::Len("signs".into())
            })
        );
        assert_eq!(d.outputs[0].unit_of, Some(UnitOf::Input(0)));
        let ins = port_list(&d.inputs, &more_fields()).to_string();
        assert!(ins.contains("port_count (& self . signs)"), "{ins}");
        assert!(ins.contains("format ! (\"in{}\" , i)"), "{ins}");

        let d = declared(
            "in{k}[width] for k in 0..factors -> y[width]",
            &more_fields(),
        )
        .unwrap()
        .unwrap();
        let ins = port_list(&d.inputs, &more_fields()).to_string();
        assert!(ins.contains("(0 .. self . factors) . map (| k |"), "{ins}");

        let d = declared(
            "in{i}[widths[i]] for i in 0..len(widths) -> y[Σwidths]",
            &more_fields(),
        )
        .unwrap()
        .unwrap();
        assert_eq!(d.inputs[0].width, Width::Entry("widths".into(), "i".into()));
        assert_eq!(d.outputs[0].width, Width::Sum("widths".into()));
        let ins = port_list(&d.inputs, &more_fields()).to_string();
        assert!(
            ins.contains("self . widths . iter () . enumerate ()"),
            "{ins}"
        );
        let outs = port_list(&d.outputs, &more_fields()).to_string();
        assert!(outs.contains("saturating_add"), "{outs}");
        // a plain list stays a `vec![…]`
        assert!(outs.starts_with(":: std :: vec !"), "{outs}");
    }

    #[test]
    fn a_port_may_exist_on_a_flag_and_carry_a_note() {
        let d = declared(
            "f (Hz), phase (rad) if phase_input -> y[2] (m), pair \"1 or 2\", s[2] \"direction ±1, count\"",
            &more_fields(),
        )
        .unwrap()
        .unwrap();
        assert_eq!(d.inputs[1].when.as_deref(), Some("phase_input"));
        assert_eq!(d.inputs[1].unit.as_deref(), Some("rad"));
        assert_eq!(d.outputs.len(), 3);
        assert_eq!(
            (d.outputs[1].unit.as_ref(), &d.outputs[1].name),
            (None, &"pair".to_string())
        );
        assert_eq!(d.outputs[2].width, Width::Fixed(2));
        let ins = port_list(&d.inputs, &more_fields()).to_string();
        assert!(ins.contains("if self . phase_input"), "{ins}");
        assert_eq!(
            shown("r (m) -> v (V), state[2] \"direction ±1, out-of-range count\""),
            "r (m) -> v (V), state[2] (direction ±1, out-of-range count)"
        );
        assert_eq!(
            shown("u -> faults[1] (count) \"of non-finite inputs\", n \"1 or 2\""),
            "u -> faults[1] (count of non-finite inputs), n (1 or 2)"
        );
        // a flag that is no field: prose
        assert_eq!(declared("u if nothing -> y", &more_fields()), Ok(None));
    }

    #[test]
    fn a_transparent_block_names_its_wrapped_fields() {
        let wrapped = Fields {
            names: vec!["params".into(), "faults".into()],
            wrapped: Some("params".into()),
        };
        let d = declared("f, a (V) if amplitude_input -> u[4] (V)", &wrapped)
            .unwrap()
            .unwrap();
        let ins = port_list(&d.inputs, &wrapped).to_string();
        assert!(ins.contains("if self . params . amplitude_input"), "{ins}");
    }

    #[test]
    fn a_group_or_clause_where_it_cannot_stand_is_refused() {
        for text in [
            // an entry of a list outside a group over that list
            "u[widths[i]] -> y",
            "in{i}[widths[i]] for i in 0..factors -> y",
            "in{i}[widths[j]] for i in 0..len(widths) -> y",
            // a unit from an input whose place or presence depends on parameters
            "u if phase_input -> y [unit of u]",
            "in{i} for i in 0..factors, u -> y [unit of u]",
        ] {
            assert!(declared(text, &more_fields()).is_err(), "{text}");
        }
        for text in [
            // no `{i}` in the name, an unknown count, a range not from 0: prose
            "in for i in 0..factors -> y",
            "in{i} for i in 0..n -> y",
            "in{i} for i in 1..factors -> y",
            "in{i}{i} for i in 0..factors -> y",
            "u \"unclosed -> y",
        ] {
            assert_eq!(declared(text, &more_fields()), Ok(None), "{text}");
        }
    }
}
