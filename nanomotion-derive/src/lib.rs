//! # nanomotion-derive
//!
//! `#[derive(Params)]`: one declaration per block. The parameter struct (its doc
//! comments, its `#[serde(default …)]` attributes and `#[param(…)]` bounds) is the
//! only place a block's parameters are described; the derive turns it into
//!
//! - the block's documentation for `nanomotion blocks` (a `BlockDoc` registered with
//!   `inventory` when the struct carries `#[block(…)]`),
//! - the JSON Schema of its parameters (for `nanomotion schema` and editors),
//! - `check_params()`, the validation of the declared bounds with the same
//!   `nanomotion_core::block::check` messages a hand-written `build()` gave.
//!
//! The generated code names only `::nanomotion_core` paths, so a plugin (or a
//! third-party crate) needs no dependency besides `nanomotion-core`, which
//! re-exports this macro. See `nanomotion_core::doc` for the attribute reference and
//! an example.

mod declared;
mod ports;

use proc_macro::TokenStream;
use proc_macro2::TokenStream as TokenStream2;
use quote::{format_ident, quote};
use syn::meta::ParseNestedMeta;
use syn::punctuated::Punctuated;
use syn::{
    Attribute, Data, DeriveInput, Expr, Fields, GenericArgument, Ident, LitStr, PathArguments,
    Token, Type, parse_macro_input,
};

/// Derive `nanomotion_core::doc::Params` (and `ParamSchema`) for a parameter struct
/// or enum; with `#[block(type_name = "…", role = …, ports = "…")]` on a struct,
/// also register the block's documentation. See `nanomotion_core::doc`.
#[proc_macro_derive(Params, attributes(block, param))]
pub fn derive_params(input: TokenStream) -> TokenStream {
    let input = parse_macro_input!(input as DeriveInput);
    match expand(&input) {
        Ok(ts) => ts.into(),
        Err(e) => e.to_compile_error().into(),
    }
}

/// Complete an `impl Block for T` from `T`'s `#[block(…)]` declaration (`T`
/// derives `Params`): register it with typetag under the declared `type_name`,
/// and write the methods the impl leaves out —
///
/// - `inputs` and `outputs` (when the impl writes neither) from the declared
///   `ports` (`nanomotion_core::block::DeclaredPorts`; a `ports` string that is
///   prose, not a declaration, does not compile here: write both by hand),
/// - `role` from the declared role,
/// - `live_params` from the declared `live` parameters (the impl writes only
///   `set_live_param`; a hand-written `live_params` does not compile),
/// - `build` as the declared checks: `check_params()`, then
///   `check_at_rate(ctx.dt)`,
/// - `output`, for a source: `Source::sample` at the tick's time (a block
///   that writes no `output` and invokes no macro must implement
///   `nanomotion_core::Source`; a macro invoked in the impl is taken to write
///   `output`).
///
/// What the impl writes itself is kept. See `nanomotion_core::block`.
#[proc_macro_attribute]
pub fn declared_block(args: TokenStream, item: TokenStream) -> TokenStream {
    let args = TokenStream2::from(args);
    let item = parse_macro_input!(item as syn::ItemImpl);
    match declared::expand(args, item) {
        Ok(ts) => ts.into(),
        Err(e) => e.to_compile_error().into(),
    }
}

/// Rustdoc markup a terminal reader does not need: intra-doc links
/// (`` [`X`](path) `` and `` [`X`] `` become `` `X` ``) and escaped brackets.
fn plain(line: &str) -> String {
    let mut out = String::new();
    let mut rest = line;
    while let Some(i) = rest.find("[`") {
        out.push_str(&rest[..i]);
        let after = &rest[i + 1..];
        let Some(j) = after.find("`]") else {
            out.push_str(&rest[i..]);
            rest = "";
            break;
        };
        out.push_str(&after[..j + 1]);
        rest = &after[j + 2..];
        if rest.starts_with('(')
            && let Some(k) = rest.find(')')
        {
            rest = &rest[k + 1..];
        }
    }
    out.push_str(rest);
    out.replace("\\[", "[").replace("\\]", "]")
}

/// Doc comment lines of an item, trimmed, in plain text; fenced code blocks
/// (examples for rustdoc) are left out.
fn doc_lines(attrs: &[Attribute]) -> Vec<String> {
    let mut lines = Vec::new();
    let mut in_code = false;
    for a in attrs {
        if a.path().is_ident("doc")
            && let syn::Meta::NameValue(nv) = &a.meta
            && let Expr::Lit(syn::ExprLit {
                lit: syn::Lit::Str(s),
                ..
            }) = &nv.value
        {
            let line = s.value();
            let line = line.trim();
            if line.starts_with("```") {
                in_code = !in_code;
            } else if !in_code {
                lines.push(plain(line));
            }
        }
    }
    lines
}

/// Doc comment as one line of text (paragraphs joined with a space).
fn doc_text(attrs: &[Attribute]) -> String {
    doc_lines(attrs)
        .into_iter()
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join(" ")
}

/// The first paragraph of the doc comment, without a leading "`tag`: ".
fn summary_of(attrs: &[Attribute], tag: &str) -> String {
    let lines = doc_lines(attrs);
    let first: Vec<String> = lines
        .into_iter()
        .skip_while(|l| l.is_empty())
        .take_while(|l| !l.is_empty())
        .collect();
    let s = first.join(" ");
    let prefix = format!("`{tag}`:");
    match s.strip_prefix(&prefix) {
        Some(rest) => rest.trim().to_string(),
        None => s,
    }
}

/// Consume the value of a nested meta we do not interpret.
fn skip_meta(meta: &ParseNestedMeta) -> syn::Result<()> {
    if meta.input.peek(Token![=]) {
        let _: Expr = meta.value()?.parse()?;
    } else if meta.input.peek(syn::token::Paren) {
        let content;
        syn::parenthesized!(content in meta.input);
        let _: TokenStream2 = content.parse()?;
    }
    Ok(())
}

fn meta_name(meta: &ParseNestedMeta) -> String {
    meta.path
        .get_ident()
        .map(|i| i.to_string())
        .unwrap_or_default()
}

#[derive(Default)]
struct SerdeContainer {
    deny_unknown_fields: bool,
    default: bool,
    rename_all: Option<String>,
    tag: Option<String>,
    untagged: bool,
    transparent: bool,
}

fn serde_container(attrs: &[Attribute]) -> syn::Result<SerdeContainer> {
    let mut c = SerdeContainer::default();
    for a in attrs.iter().filter(|a| a.path().is_ident("serde")) {
        a.parse_nested_meta(|meta| {
            match meta_name(&meta).as_str() {
                "deny_unknown_fields" => c.deny_unknown_fields = true,
                "default" => {
                    c.default = true;
                    skip_meta(&meta)?;
                }
                "untagged" => c.untagged = true,
                "transparent" => c.transparent = true,
                "rename_all" if meta.input.peek(Token![=]) => {
                    let s: LitStr = meta.value()?.parse()?;
                    c.rename_all = Some(s.value());
                }
                "tag" => {
                    let s: LitStr = meta.value()?.parse()?;
                    c.tag = Some(s.value());
                }
                _ => skip_meta(&meta)?,
            }
            Ok(())
        })?;
    }
    Ok(c)
}

enum DefaultKind {
    Trait,
    Path(syn::ExprPath),
}

#[derive(Default)]
struct SerdeField {
    skip: bool,
    default: Option<DefaultKind>,
    rename: Option<String>,
    aliases: Vec<String>,
    custom: bool,
    flatten: bool,
}

fn serde_field(attrs: &[Attribute]) -> syn::Result<SerdeField> {
    let mut s = SerdeField::default();
    for a in attrs.iter().filter(|a| a.path().is_ident("serde")) {
        a.parse_nested_meta(|meta| {
            match meta_name(&meta).as_str() {
                "skip" | "skip_deserializing" => s.skip = true,
                "default" => {
                    if meta.input.peek(Token![=]) {
                        let lit: LitStr = meta.value()?.parse()?;
                        s.default = Some(DefaultKind::Path(lit.parse()?));
                    } else {
                        s.default = Some(DefaultKind::Trait);
                    }
                }
                "rename" if meta.input.peek(Token![=]) => {
                    let lit: LitStr = meta.value()?.parse()?;
                    s.rename = Some(lit.value());
                }
                "alias" => {
                    let lit: LitStr = meta.value()?.parse()?;
                    s.aliases.push(lit.value());
                }
                "with" | "deserialize_with" => {
                    s.custom = true;
                    skip_meta(&meta)?;
                }
                "flatten" => s.flatten = true,
                _ => skip_meta(&meta)?,
            }
            Ok(())
        })?;
    }
    Ok(s)
}

/// One end of a `range(…)`: its value and whether it is strict (`>`, `<`).
struct End {
    value: Expr,
    exclusive: bool,
}

/// A declared bound of a parameter.
enum Bound {
    Finite,
    Positive,
    NonNegative,
    /// `range(lo, hi)`: both ends inclusive.
    Range(Expr, Expr),
    /// `range(> lo)`, `range(>= lo, < hi)`, `range(<= hi)`, …: each end with
    /// its operator, either end may be left out.
    Between(Option<End>, Option<End>),
    Width,
    Size(Expr, Expr),
    AtLeastOne,
    /// `len(…)`: how many entries a list holds, in `range(…)`'s forms.
    Len(Option<End>, Option<End>),
    /// `increasing`: a list of numbers each above the one before.
    Increasing,
}

#[derive(Default)]
struct ParamAttr {
    bounds: Vec<Bound>,
    default_doc: Option<String>,
    nested: bool,
    schema: Option<syn::ExprPath>,
    at_most: Option<Ident>,
    /// `same_len = other`: this list has as many entries as `other`.
    same_len: Option<Ident>,
    /// `below_nyquist`: a frequency (Hz) below half the block's rate, checked
    /// by `check_at_rate(dt)`.
    below_nyquist: bool,
    /// Words added to the fix of every bound error of the field.
    hint: Option<String>,
}

/// The items of `range(…)`: two plain bounds (`lo, hi`, inclusive), or one or
/// two bounds each led by its operator (`> lo`, `>= lo`, `< hi`, `<= hi`).
fn range_items(meta: &ParseNestedMeta) -> syn::Result<Bound> {
    let content;
    syn::parenthesized!(content in meta.input);
    // (operator, value); operator: Some((lower, exclusive))
    let mut items: Vec<(Option<(bool, bool)>, Expr)> = Vec::new();
    while !content.is_empty() {
        let op = if content.peek(Token![>=]) {
            content.parse::<Token![>=]>()?;
            Some((true, false))
        } else if content.peek(Token![<=]) {
            content.parse::<Token![<=]>()?;
            Some((false, false))
        } else if content.peek(Token![>]) {
            content.parse::<Token![>]>()?;
            Some((true, true))
        } else if content.peek(Token![<]) {
            content.parse::<Token![<]>()?;
            Some((false, true))
        } else {
            None
        };
        let value: Expr = content.parse()?;
        items.push((op, value));
        if content.is_empty() {
            break;
        }
        content.parse::<Token![,]>()?;
    }
    const FORMS: &str = "expected range(lo, hi) (both inclusive) or one or two bounds with \
                         their operators: range(> lo), range(>= lo), range(< hi), \
                         range(<= hi), range(> lo, <= hi), …";
    if items.iter().all(|(op, _)| op.is_none()) {
        if items.len() != 2 {
            return Err(meta.error(FORMS));
        }
        let hi = items.pop().map(|(_, e)| e);
        let lo = items.pop().map(|(_, e)| e);
        return match (lo, hi) {
            (Some(lo), Some(hi)) => Ok(Bound::Range(lo, hi)),
            _ => Err(meta.error(FORMS)),
        };
    }
    let (mut lo, mut hi) = (None, None);
    for (op, value) in items {
        let Some((lower, exclusive)) = op else {
            return Err(meta.error(FORMS));
        };
        let slot = if lower { &mut lo } else { &mut hi };
        if slot.is_some() {
            return Err(meta.error(format!(
                "two {} bounds in range(…): give at most one lower (> or >=) and one upper (< or <=)",
                if lower { "lower" } else { "upper" }
            )));
        }
        *slot = Some(End { value, exclusive });
    }
    Ok(Bound::Between(lo, hi))
}

fn two_exprs(meta: &ParseNestedMeta) -> syn::Result<(Expr, Expr)> {
    let content;
    syn::parenthesized!(content in meta.input);
    let list = Punctuated::<Expr, Token![,]>::parse_terminated(&content)?;
    let v: Vec<Expr> = list.into_iter().collect();
    if v.len() != 2 {
        return Err(meta.error("expected two bounds: (lo, hi)"));
    }
    Ok((v[0].clone(), v[1].clone()))
}

fn param_attr(attrs: &[Attribute]) -> syn::Result<ParamAttr> {
    let mut p = ParamAttr::default();
    for a in attrs.iter().filter(|a| a.path().is_ident("param")) {
        a.parse_nested_meta(|meta| {
            match meta_name(&meta).as_str() {
                "finite" => p.bounds.push(Bound::Finite),
                "positive" => p.bounds.push(Bound::Positive),
                "non_negative" => p.bounds.push(Bound::NonNegative),
                "width" => p.bounds.push(Bound::Width),
                "at_least_one" => p.bounds.push(Bound::AtLeastOne),
                "range" => p.bounds.push(range_items(&meta)?),
                "len" => {
                    let (lo, hi) = match range_items(&meta)? {
                        Bound::Range(lo, hi) => (
                            Some(End {
                                value: lo,
                                exclusive: false,
                            }),
                            Some(End {
                                value: hi,
                                exclusive: false,
                            }),
                        ),
                        Bound::Between(lo, hi) => (lo, hi),
                        _ => unreachable!("range_items gives a range"),
                    };
                    for e in lo.iter().chain(hi.iter()) {
                        if is_float_literal(&e.value) {
                            return Err(
                                meta.error("a fractional number of entries: give a whole number")
                            );
                        }
                    }
                    p.bounds.push(Bound::Len(lo, hi));
                }
                "increasing" => p.bounds.push(Bound::Increasing),
                "below_nyquist" => p.below_nyquist = true,
                "same_len" => {
                    let id: Ident = meta.value()?.parse()?;
                    p.same_len = Some(id);
                }
                "size" => {
                    let (lo, hi) = two_exprs(&meta)?;
                    p.bounds.push(Bound::Size(lo, hi));
                }
                "nested" => p.nested = true,
                "default_doc" => {
                    let lit: LitStr = meta.value()?.parse()?;
                    p.default_doc = Some(lit.value());
                }
                "schema" => {
                    let lit: LitStr = meta.value()?.parse()?;
                    p.schema = Some(lit.parse()?);
                }
                "at_most" => {
                    let id: Ident = meta.value()?.parse()?;
                    p.at_most = Some(id);
                }
                "hint" => {
                    let lit: LitStr = meta.value()?.parse()?;
                    p.hint = Some(lit.value());
                }
                other => {
                    return Err(meta.error(format!(
                        "unknown #[param] item `{other}`: expected finite, positive, \
                         non_negative, range(lo, hi), range(> lo), range(>= lo, < hi), …, \
                         width, size(lo, hi), at_least_one, len(lo, hi), len(>= lo), …, \
                         increasing, below_nyquist, at_most = field, same_len = field, nested, \
                         default_doc = \"…\", hint = \"…\" or schema = \"path\""
                    )));
                }
            }
            Ok(())
        })?;
    }
    Ok(p)
}

#[derive(Default)]
struct BlockAttr {
    type_name: Option<String>,
    role: Option<Ident>,
    ports: Option<String>,
    /// `live = "a, b"`: the parameters that may change while the graph runs.
    live: Vec<String>,
}

fn block_attr(attrs: &[Attribute]) -> syn::Result<Option<BlockAttr>> {
    let mut found = None;
    for a in attrs.iter().filter(|a| a.path().is_ident("block")) {
        let mut b = BlockAttr::default();
        a.parse_nested_meta(|meta| {
            match meta_name(&meta).as_str() {
                "type_name" => b.type_name = Some(meta.value()?.parse::<LitStr>()?.value()),
                "role" => b.role = Some(meta.value()?.parse()?),
                "ports" => b.ports = Some(meta.value()?.parse::<LitStr>()?.value()),
                "live" => {
                    b.live = meta
                        .value()?
                        .parse::<LitStr>()?
                        .value()
                        .split(',')
                        .map(|s| s.trim().to_string())
                        .filter(|s| !s.is_empty())
                        .collect()
                }
                other => {
                    return Err(meta.error(format!(
                        "unknown #[block] item `{other}`: expected type_name, role, ports, live"
                    )));
                }
            }
            Ok(())
        })?;
        if b.type_name.is_none() || b.role.is_none() || b.ports.is_none() {
            return Err(syn::Error::new_spanned(
                a,
                "#[block] needs type_name = \"…\", role = Role variant, ports = \"…\"",
            ));
        }
        found = Some(b);
    }
    Ok(found)
}

/// `Outer<Inner>`: the generic argument of a one-argument type named `outer`.
fn generic_of<'a>(ty: &'a Type, outer: &str) -> Option<&'a Type> {
    let Type::Path(tp) = ty else { return None };
    let seg = tp.path.segments.last()?;
    if seg.ident != outer {
        return None;
    }
    let PathArguments::AngleBracketed(args) = &seg.arguments else {
        return None;
    };
    args.args.iter().rev().find_map(|a| match a {
        GenericArgument::Type(t) => Some(t),
        _ => None,
    })
}

fn last_ident(ty: &Type) -> Option<String> {
    match ty {
        Type::Path(tp) if tp.qself.is_none() => {
            tp.path.segments.last().map(|s| s.ident.to_string())
        }
        _ => None,
    }
}

fn is_dyn_block(ty: &Type) -> bool {
    match ty {
        Type::TraitObject(t) => t.bounds.iter().any(|b| match b {
            syn::TypeParamBound::Trait(tb) => {
                tb.path.segments.last().is_some_and(|s| s.ident == "Block")
            }
            _ => false,
        }),
        _ => false,
    }
}

/// An expression building the JSON Schema of a value of type `ty`.
fn schema_of(ty: &Type) -> TokenStream2 {
    let d = quote!(::nanomotion_core::doc::__derive);
    if is_dyn_block(ty) {
        return quote!(#d::block_ref());
    }
    if let Type::Array(arr) = ty {
        let inner = schema_of(&arr.elem);
        let len = &arr.len;
        return quote!(#d::fixed_array(#inner, #len));
    }
    if let Type::Reference(r) = ty {
        return schema_of(&r.elem);
    }
    for (outer, f) in [
        ("Option", quote!(nullable)),
        ("Vec", quote!(array)),
        ("VecDeque", quote!(array)),
        ("BTreeMap", quote!(map)),
        ("HashMap", quote!(map)),
    ] {
        if let Some(inner) = generic_of(ty, outer) {
            let inner = schema_of(inner);
            return quote!(#d::#f(#inner));
        }
    }
    if let Some(inner) = generic_of(ty, "Box").or_else(|| generic_of(ty, "Arc")) {
        return schema_of(inner);
    }
    match last_ident(ty).as_deref() {
        Some("f64" | "f32") => quote!(#d::number()),
        Some("u8" | "u16" | "u32" | "u64" | "usize") => quote!(#d::unsigned()),
        Some("i8" | "i16" | "i32" | "i64" | "isize") => quote!(#d::integer()),
        Some("bool") => quote!(#d::boolean()),
        Some("String" | "str" | "PathBuf") => quote!(#d::string()),
        _ => quote!({
            #[allow(unused_imports)]
            use #d::{ViaAny as _, ViaSchema as _};
            (&&#d::Probe::<#ty>::new()).schema()
        }),
    }
}

/// Whether a type is a value serde reads itself (a list, a map, an optional,
/// a number, a string) rather than a parameter struct of its own.
fn is_value_type(ty: &Type) -> bool {
    matches!(ty, Type::Array(_))
        || ["Vec", "VecDeque", "Option", "BTreeMap", "HashMap"]
            .iter()
            .any(|o| generic_of(ty, o).is_some())
        || is_integer(ty)
        || matches!(
            last_ident(ty).as_deref(),
            Some("f64" | "f32" | "bool" | "String" | "PathBuf")
        )
}

/// Whether a (leaf) type is one of Rust's integer types.
fn is_integer(ty: &Type) -> bool {
    matches!(
        last_ident(ty).as_deref(),
        Some("u8" | "u16" | "u32" | "u64" | "usize" | "i8" | "i16" | "i32" | "i64" | "isize")
    )
}

/// A bound written as a float literal (`0.5`, `-1.0`), which an integer field
/// cannot take.
fn is_float_literal(e: &Expr) -> bool {
    match e {
        Expr::Lit(l) => matches!(l.lit, syn::Lit::Float(_)),
        Expr::Unary(u) => is_float_literal(&u.expr),
        Expr::Paren(p) => is_float_literal(&p.expr),
        _ => false,
    }
}

/// `Some(Limit::Inclusive(x))`/`Some(Limit::Exclusive(x))`/`None` for one end,
/// its value cast to `as_ty` (`f64` or `i128`).
fn limit(end: Option<&End>, as_ty: TokenStream2) -> TokenStream2 {
    let c = quote!(::nanomotion_core::block::check);
    match end {
        None => quote!(::core::option::Option::None),
        Some(End {
            value,
            exclusive: false,
        }) => quote!(::core::option::Option::Some(#c::Limit::Inclusive((#value) as #as_ty))),
        Some(End {
            value,
            exclusive: true,
        }) => quote!(::core::option::Option::Some(#c::Limit::Exclusive((#value) as #as_ty))),
    }
}

/// The lower and upper end a bound declares (`None` for `finite`).
fn ends(b: &Bound) -> Option<(Option<End>, Option<End>)> {
    let end = |value: Expr, exclusive: bool| Some(End { value, exclusive });
    let copy = |e: &Option<End>| {
        e.as_ref().map(|e| End {
            value: e.value.clone(),
            exclusive: e.exclusive,
        })
    };
    Some(match b {
        Bound::Finite => return None,
        Bound::Positive => (end(syn::parse_quote!(0), true), None),
        Bound::NonNegative => (end(syn::parse_quote!(0), false), None),
        Bound::Range(lo, hi) | Bound::Size(lo, hi) => {
            (end(lo.clone(), false), end(hi.clone(), false))
        }
        Bound::Between(lo, hi) => (copy(lo), copy(hi)),
        Bound::Width => (
            end(syn::parse_quote!(1), false),
            end(
                syn::parse_quote!(::nanomotion_core::block::MAX_WIDTH),
                false,
            ),
        ),
        Bound::AtLeastOne => (end(syn::parse_quote!(1), false), None),
        Bound::Len(..) | Bound::Increasing => return None,
    })
}

/// Code checking one bound on the value `access` (an expression of type `&T`).
fn check_of(
    ty: &Type,
    access: TokenStream2,
    name: TokenStream2,
    b: &Bound,
    depth: usize,
) -> syn::Result<TokenStream2> {
    let c = quote!(::nanomotion_core::block::check);
    if let Some(inner) = generic_of(ty, "Option") {
        let v = format_ident!("__v{depth}");
        let body = check_of(inner, quote!(#v), name, b, depth + 1)?;
        return Ok(quote!(if let ::core::option::Option::Some(#v) = #access { #body }));
    }
    let elem = generic_of(ty, "Vec").or(match ty {
        Type::Array(a) => Some(&*a.elem),
        _ => None,
    });
    // bounds on the list itself rather than on each entry
    match (b, elem) {
        (Bound::Len(lo, hi), Some(_)) => {
            let lo = limit(lo.as_ref(), quote!(i128));
            let hi = limit(hi.as_ref(), quote!(i128));
            return Ok(quote!(#c::entries(#name, (#access).len(), #lo, #hi)?;));
        }
        (Bound::Increasing, Some(inner)) if last_ident(inner).as_deref() == Some("f64") => {
            return Ok(quote!(#c::increasing(#name, &(#access)[..])?;));
        }
        (Bound::Increasing, _) => {
            return Err(syn::Error::new_spanned(
                ty,
                "`increasing` is for a list of numbers (Vec<f64>, [f64; N])",
            ));
        }
        (Bound::Len(..), None) => {
            return Err(syn::Error::new_spanned(
                ty,
                "`len(…)` bounds how many entries a list holds: declare it on a Vec or an array",
            ));
        }
        _ => {}
    }
    if let Some(inner) = elem {
        if matches!(b, Bound::Finite) && last_ident(inner).as_deref() == Some("f64") {
            return Ok(quote!(#c::all_finite(#name, #access)?;));
        }
        let v = format_ident!("__v{depth}");
        let i = format_ident!("__i{depth}");
        let n = format_ident!("__n{depth}");
        let body = check_of(inner, quote!(#v), quote!(&#n), b, depth + 1)?;
        return Ok(quote!(for (#i, #v) in (#access).iter().enumerate() {
            let #n = ::std::format!("{}[{}]", #name, #i);
            #body
        }));
    }
    if is_integer(ty) {
        let usize_field = last_ident(ty).as_deref() == Some("usize");
        // the usize checks of sizes keep their messages
        match b {
            Bound::Width if usize_field => return Ok(quote!(#c::width(#name, *#access)?;)),
            Bound::Size(lo, hi) if usize_field => {
                return Ok(quote!(#c::size(#name, *#access, #lo, #hi)?;));
            }
            Bound::AtLeastOne if usize_field => {
                return Ok(quote!(#c::at_least_one(#name, *#access)?;));
            }
            _ => {}
        }
        let Some((lo, hi)) = ends(b) else {
            return Err(syn::Error::new_spanned(
                ty,
                "`finite` on an integer field: a whole number is always finite; remove it",
            ));
        };
        for e in lo.iter().chain(hi.iter()) {
            if is_float_literal(&e.value) {
                return Err(syn::Error::new_spanned(
                    &e.value,
                    "a fractional bound on an integer field: give a whole number \
                     (`range(> 0)` rather than `range(> 0.0)`)",
                ));
            }
        }
        let lo = limit(lo.as_ref(), quote!(i128));
        let hi = limit(hi.as_ref(), quote!(i128));
        return Ok(quote!(#c::whole(#name, (*#access) as i128, #lo, #hi)?;));
    }
    Ok(match b {
        Bound::Finite => quote!(#c::finite(#name, *#access)?;),
        Bound::Positive => quote!(#c::positive(#name, *#access)?;),
        Bound::NonNegative => quote!(#c::non_negative(#name, *#access)?;),
        Bound::Range(lo, hi) => quote!(#c::in_range(#name, *#access, #lo, #hi)?;),
        Bound::Between(lo, hi) => {
            let lo = limit(lo.as_ref(), quote!(f64));
            let hi = limit(hi.as_ref(), quote!(f64));
            quote!(#c::between(#name, *#access, #lo, #hi)?;)
        }
        Bound::Width => quote!(#c::width(#name, *#access)?;),
        Bound::Size(lo, hi) => quote!(#c::size(#name, *#access, #lo, #hi)?;),
        Bound::AtLeastOne => quote!(#c::at_least_one(#name, *#access)?;),
        Bound::Len(..) | Bound::Increasing => unreachable!("list bounds are taken above"),
    })
}

/// Code adding a bound to a schema `s` (a `Value` variable) and its text to `t`.
fn schema_bound(b: &Bound) -> TokenStream2 {
    let d = quote!(::nanomotion_core::doc::__derive);
    match b {
        Bound::Finite => quote!(),
        Bound::Between(lo, hi) => {
            let lo = limit(lo.as_ref(), quote!(f64));
            let hi = limit(hi.as_ref(), quote!(f64));
            quote!(#d::limits(&mut __s, &mut __b, #lo, #hi);)
        }
        Bound::Positive => {
            quote!(#d::bound(&mut __s, &mut __b, ::core::option::Option::Some(0.0), true, ::core::option::Option::None);)
        }
        Bound::NonNegative => {
            quote!(#d::bound(&mut __s, &mut __b, ::core::option::Option::Some(0.0), false, ::core::option::Option::None);)
        }
        Bound::Range(lo, hi) => {
            quote!(#d::bound(&mut __s, &mut __b, ::core::option::Option::Some((#lo) as f64), false, ::core::option::Option::Some((#hi) as f64));)
        }
        Bound::Width => {
            quote!(#d::bound(&mut __s, &mut __b, ::core::option::Option::Some(1.0), false, ::core::option::Option::Some(::nanomotion_core::block::MAX_WIDTH as f64));)
        }
        Bound::Size(lo, hi) => {
            quote!(#d::bound(&mut __s, &mut __b, ::core::option::Option::Some((#lo) as f64), false, ::core::option::Option::Some((#hi) as f64));)
        }
        Bound::AtLeastOne => {
            quote!(#d::bound(&mut __s, &mut __b, ::core::option::Option::Some(1.0), false, ::core::option::Option::None);)
        }
        Bound::Len(lo, hi) => {
            let lo = limit(lo.as_ref(), quote!(i128));
            let hi = limit(hi.as_ref(), quote!(i128));
            quote!(#d::entries(&mut __s, &mut __b, #lo, #hi);)
        }
        Bound::Increasing => quote!(__b.push(::std::string::String::from("strictly increasing"));),
    }
}

fn rename(name: &str, rule: Option<&str>) -> String {
    let words: Vec<String> = {
        // Split a PascalCase variant or snake_case field into lower-case words.
        let mut w = Vec::new();
        let mut cur = String::new();
        for ch in name.chars() {
            if ch == '_' {
                if !cur.is_empty() {
                    w.push(std::mem::take(&mut cur));
                }
            } else if ch.is_uppercase() && !cur.is_empty() {
                w.push(std::mem::take(&mut cur));
                cur.extend(ch.to_lowercase());
            } else {
                cur.extend(ch.to_lowercase());
            }
        }
        if !cur.is_empty() {
            w.push(cur);
        }
        w
    };
    match rule {
        Some("snake_case") => words.join("_"),
        Some("kebab-case") => words.join("-"),
        Some("lowercase") => name.to_lowercase(),
        Some("UPPERCASE") => name.to_uppercase(),
        Some("SCREAMING_SNAKE_CASE") => words.join("_").to_uppercase(),
        _ => name.to_string(),
    }
}

/// One parameter: its YAML name, the code of its `ParamDoc`, and its checks.
struct FieldCode {
    doc: TokenStream2,
    check: TokenStream2,
    /// `at_most` checks, run after every field's own bounds.
    ordering: TokenStream2,
    /// `below_nyquist` checks, run by `check_at_rate(dt)`.
    rate: TokenStream2,
}

/// Where a field's value is read by its checks.
#[derive(Clone, Copy, PartialEq)]
enum Access {
    /// No checks (documentation only).
    None,
    /// A struct's field: `self.field`.
    SelfField,
    /// A field of an enum variant, bound by reference in a `match self` arm.
    Binding,
    /// The one field of a `#[serde(transparent)]` wrapper of a value: read as
    /// `self.field`, named in errors from the wrapper (empty name).
    Wrapped,
}

impl Access {
    /// An expression of type `&T` for the field `id`.
    fn place(self, id: &Ident) -> TokenStream2 {
        match self {
            Access::Binding => quote!(#id),
            _ => quote!(&self.#id),
        }
    }
    /// An expression of type `T` (a `Copy` value) for the field `id`.
    fn value(self, id: &Ident) -> TokenStream2 {
        match self {
            Access::Binding => quote!((*#id)),
            _ => quote!(self.#id),
        }
    }
}

fn field_code(
    f: &syn::Field,
    container: &SerdeContainer,
    access: Access,
) -> syn::Result<Option<FieldCode>> {
    let with_checks = access != Access::None;
    let d = quote!(::nanomotion_core::doc::__derive);
    let sf = serde_field(&f.attrs)?;
    let pa = param_attr(&f.attrs)?;
    if sf.skip {
        return Ok(None);
    }
    let ident = f
        .ident
        .as_ref()
        .ok_or_else(|| syn::Error::new_spanned(f, "#[derive(Params)] needs named fields"))?;
    let name = sf.rename.clone().unwrap_or_else(|| {
        let s = ident.to_string();
        s.strip_prefix("r#").unwrap_or(&s).to_string()
    });
    let ty = &f.ty;
    let doc = doc_text(&f.attrs);
    let is_option = generic_of(ty, "Option").is_some();
    let default_value = match (&sf.default, container.default, is_option) {
        (Some(DefaultKind::Path(p)), _, _) => quote!(#d::some_value(&#p())),
        (Some(DefaultKind::Trait), _, _) => {
            quote!(#d::some_value(&<#ty as ::core::default::Default>::default()))
        }
        (None, true, _) => {
            quote!(#d::some_value(&<Self as ::core::default::Default>::default().#ident))
        }
        (None, false, true) => quote!(::core::option::Option::Some(#d::Value::Null)),
        (None, false, false) => quote!(::core::option::Option::None),
    };
    let default_doc = match &pa.default_doc {
        Some(s) => quote!(::core::option::Option::Some(#s)),
        None => quote!(::core::option::Option::None),
    };
    let mut schema = match (&pa.schema, sf.custom, sf.flatten) {
        (Some(p), _, _) => quote!(#p()),
        (None, true, _) | (None, _, true) => quote!(#d::any()),
        (None, false, false) => schema_of(ty),
    };
    if pa.nested && pa.schema.is_none() {
        // nested parameter structs describe themselves
        schema = schema_of(ty);
    }
    let mut bounds: Vec<TokenStream2> = pa.bounds.iter().map(schema_bound).collect();
    if pa.nested {
        bounds.push(quote!(#d::nested_entries(&__s, &mut __b);));
    }
    if pa.below_nyquist {
        bounds.push(quote!(__b.push(::std::string::String::from("below Nyquist"));));
    }
    if let Some(other) = &pa.same_len {
        let words = format!("as many entries as {other}");
        bounds.push(quote!(__b.push(::std::string::String::from(#words));));
    }
    let aliases = &sf.aliases;
    let flatten = sf.flatten;
    let doc_code = quote!({
        let mut __s = #schema;
        let mut __b: ::std::vec::Vec<::std::string::String> = ::std::vec::Vec::new();
        #(#bounds)*
        #d::param(#name, #doc, #default_value, #default_doc, __s, __b, &[#(#aliases),*], #flatten)
    });
    let mut check = TokenStream2::new();
    let mut ordering = TokenStream2::new();
    let mut rate = TokenStream2::new();
    // the name errors give: a wrapper's value is named by whoever holds it
    let name = if access == Access::Wrapped {
        String::new()
    } else {
        name
    };
    if with_checks {
        let mut own = TokenStream2::new();
        for b in &pa.bounds {
            own.extend(check_of(ty, access.place(ident), quote!(#name), b, 0)?);
        }
        match &pa.hint {
            Some(h) if !own.is_empty() => check.extend(quote!(
                (|| -> ::core::result::Result<(), ::nanomotion_core::ParamError> {
                    #own
                    ::core::result::Result::Ok(())
                })()
                .map_err(|e| #d::hint(e, #h))?;
            )),
            Some(_) => {
                return Err(syn::Error::new_spanned(
                    ident,
                    "`hint` adds words to a bound's error: declare a bound on this field",
                ));
            }
            None => check.extend(own),
        }
        if let Some(other) = &pa.at_most {
            let other_name = other.to_string();
            let (this, that) = (access.value(ident), access.value(other));
            ordering.extend(quote!(::nanomotion_core::block::check::ordered(#name, (#this) as f64, #other_name, (#that) as f64)?;));
        }
        if let Some(other) = &pa.same_len {
            let other_name = other.to_string();
            let (this, that) = (access.value(ident), access.value(other));
            ordering.extend(quote!(::nanomotion_core::block::check::same_len(#name, (#this).len(), #other_name, (#that).len())?;));
        }
        if pa.below_nyquist {
            if access != Access::SelfField {
                return Err(syn::Error::new_spanned(
                    ident,
                    "`below_nyquist` is checked against a block's rate: declare it on a block's own field",
                ));
            }
            let c = quote!(::nanomotion_core::block::check);
            rate = match (
                last_ident(ty).as_deref(),
                generic_of(ty, "Option").and_then(last_ident).as_deref(),
            ) {
                (Some("f64"), _) => quote!(#c::below_nyquist(#name, self.#ident, dt)?;),
                (_, Some("f64")) => quote!(if let ::core::option::Option::Some(__f) = self.#ident {
                    #c::below_nyquist(#name, __f, dt)?;
                }),
                _ => {
                    return Err(syn::Error::new_spanned(
                        ty,
                        "`below_nyquist` is for a frequency in Hz: an f64 or Option<f64>",
                    ));
                }
            };
        }
        if pa.nested {
            let place = access.place(ident);
            if generic_of(ty, "Vec").is_some() {
                check.extend(quote!(for (__i, __v) in (#place).iter().enumerate() {
                    #d::nested(&::std::format!("{}[{}]", #name, __i), ::nanomotion_core::doc::Params::check_params(__v))?;
                }));
            } else if generic_of(ty, "Option").is_some() {
                check.extend(quote!(if let ::core::option::Option::Some(__v) = #place {
                    #d::nested(#name, ::nanomotion_core::doc::Params::check_params(__v))?;
                }));
            } else {
                check.extend(quote!(#d::nested(#name, ::nanomotion_core::doc::Params::check_params(#place))?;));
            }
        }
    }
    Ok(Some(FieldCode {
        doc: doc_code,
        check,
        ordering,
        rate,
    }))
}

fn expand(input: &DeriveInput) -> syn::Result<TokenStream2> {
    let d = quote!(::nanomotion_core::doc::__derive);
    let name = &input.ident;
    let (impl_g, ty_g, where_g) = input.generics.split_for_impl();
    let container = serde_container(&input.attrs)?;
    let block = block_attr(&input.attrs)?;
    let description = doc_text(&input.attrs);

    let registration = match block {
        Some(b) => {
            if !input.generics.params.is_empty() {
                return Err(syn::Error::new_spanned(
                    &input.generics,
                    "#[block] registers one concrete type: no generics",
                ));
            }
            let tag = b.type_name.unwrap_or_default();
            let role = b.role.expect("checked");
            let ports = b.ports.unwrap_or_default();
            let summary = summary_of(&input.attrs, &tag);
            let shown = ports::shown(&ports);
            let fields = match &input.data {
                Data::Struct(s) => ports::Fields {
                    names: s
                        .fields
                        .iter()
                        .filter_map(|f| f.ident.as_ref().map(|i| i.to_string()))
                        .collect(),
                    // transparent: the ports name the wrapped struct's fields
                    wrapped: if container.transparent {
                        s.fields
                            .iter()
                            .find(|f| serde_field(&f.attrs).is_ok_and(|s| !s.skip))
                            .and_then(|f| f.ident.as_ref().map(|i| i.to_string()))
                    } else {
                        None
                    },
                },
                _ => ports::Fields {
                    names: Vec::new(),
                    wrapped: None,
                },
            };
            let blk = quote!(::nanomotion_core::block);
            let live = b.live;
            if let Some(p) = live
                .iter()
                .find(|p| fields.wrapped.is_none() && !fields.names.iter().any(|n| n == *p))
            {
                return Err(syn::Error::new_spanned(
                    name,
                    format!(
                        "#[block] live: `{p}` is not a field of `{name}` (fix: name the parameters that may change while the graph runs, as spelled in the struct, comma-separated)"
                    ),
                ));
            }
            let declared_ports = match ports::declared(&ports, &fields) {
                Ok(Some(d)) => {
                    let (ins, outs) = (
                        ports::port_list(&d.inputs, &fields),
                        ports::port_list(&d.outputs, &fields),
                    );
                    quote!(impl #blk::DeclaredPorts for #name {
                        fn declared_inputs(&self) -> ::std::vec::Vec<::nanomotion_core::Port> {
                            #ins
                        }
                        fn declared_outputs(&self) -> ::std::vec::Vec<::nanomotion_core::Port> {
                            #outs
                        }
                    })
                }
                Ok(None) => quote!(),
                Err(e) => {
                    return Err(syn::Error::new_spanned(
                        name,
                        format!("#[block] ports: {e}"),
                    ));
                }
            };
            quote!(
                impl #blk::DeclaredBlock for #name {
                    const TYPE_NAME: &'static str = #tag;
                    const ROLE: ::nanomotion_core::Role = ::nanomotion_core::Role::#role;
                    const LIVE_PARAMS: &'static [&'static str] = &[#(#live),*];
                }
                #declared_ports
                ::nanomotion_core::__private::inventory::submit! {
                    ::nanomotion_core::BlockDoc {
                        type_name: #tag,
                        role: ::nanomotion_core::Role::#role,
                        summary: #summary,
                        ports: #shown,
                        params: <#name as ::nanomotion_core::doc::Params>::param_docs,
                        closed: <#name as ::nanomotion_core::doc::Params>::CLOSED,
                        live: <#name as #blk::DeclaredBlock>::LIVE_PARAMS,
                    }
                }
            )
        }
        None => quote!(),
    };

    let registration_placeholder = &registration;
    // `check_at_rate(dt)`, when a field is declared `below_nyquist`
    let mut rate_checks = TokenStream2::new();
    let (param_docs, checks, schema) = match &input.data {
        Data::Struct(s) => {
            let Fields::Named(named) = &s.fields else {
                return Err(syn::Error::new_spanned(
                    name,
                    "#[derive(Params)] needs a struct with named fields",
                ));
            };
            if container.transparent {
                // `#[serde(transparent)]`: the block is its one field's parameters
                let Some(inner) = named
                    .named
                    .iter()
                    .find(|f| serde_field(&f.attrs).map(|s| !s.skip).unwrap_or(false))
                else {
                    return Err(syn::Error::new_spanned(name, "transparent without a field"));
                };
                let ident = &inner.ident;
                let ty = &inner.ty;
                let p = quote!(::nanomotion_core::doc::Params);
                if is_value_type(ty) {
                    // a wrapper of a list, a map or a plain value: its schema is the
                    // field's (with the field's bounds), its checks the field's,
                    // named from the wrapper (`[1].x`, not `laws[1].x`)
                    let Some(fc) = field_code(inner, &container, Access::Wrapped)? else {
                        return Err(syn::Error::new_spanned(name, "transparent without a field"));
                    };
                    let (doc, check, ordering) = (fc.doc, fc.check, fc.ordering);
                    let describe = if description.is_empty() {
                        quote!()
                    } else {
                        quote!(__o.insert("description".into(), #d::Value::from(#description));)
                    };
                    let out = quote!(
                        impl #impl_g #p for #name #ty_g #where_g {
                            const CLOSED: bool = false;
                            fn param_docs() -> ::std::vec::Vec<::nanomotion_core::ParamDoc> {
                                ::std::vec::Vec::new()
                            }
                            #[allow(unused_variables, clippy::needless_borrow, clippy::unnecessary_cast)]
                            fn check_params(&self) -> ::core::result::Result<(), ::nanomotion_core::ParamError> {
                                #check
                                #ordering
                                ::core::result::Result::Ok(())
                            }
                        }
                        impl #impl_g ::nanomotion_core::doc::ParamSchema for #name #ty_g #where_g {
                            fn param_schema() -> #d::Value {
                                let mut __s = #doc.schema;
                                if let ::core::option::Option::Some(__o) = __s.as_object_mut() {
                                    __o.remove("description");
                                    #describe
                                }
                                __s
                            }
                        }
                    );
                    return Ok(quote!(#out #registration_placeholder));
                }
                let out = quote!(
                    impl #impl_g #p for #name #ty_g #where_g {
                        const CLOSED: bool = <#ty as #p>::CLOSED;
                        fn param_docs() -> ::std::vec::Vec<::nanomotion_core::ParamDoc> {
                            <#ty as #p>::param_docs()
                        }
                        fn check_params(&self) -> ::core::result::Result<(), ::nanomotion_core::ParamError> {
                            #p::check_params(&self.#ident)
                        }
                    }
                    impl #impl_g ::nanomotion_core::doc::ParamSchema for #name #ty_g #where_g {
                        fn param_schema() -> #d::Value {
                            <#ty as ::nanomotion_core::doc::ParamSchema>::param_schema()
                        }
                    }
                );
                return Ok(quote!(#out #registration_placeholder));
            }
            let mut docs = Vec::new();
            let mut checks = Vec::new();
            let mut orderings = Vec::new();
            let mut rates = TokenStream2::new();
            for f in &named.named {
                if let Some(fc) = field_code(f, &container, Access::SelfField)? {
                    docs.push(fc.doc);
                    checks.push(fc.check);
                    orderings.push(fc.ordering);
                    rates.extend(fc.rate);
                }
            }
            checks.extend(orderings);
            if !rates.is_empty() {
                rate_checks = quote!(
                    fn check_at_rate(&self, dt: f64) -> ::core::result::Result<(), ::nanomotion_core::ParamError> {
                        #rates
                        ::core::result::Result::Ok(())
                    }
                );
            }
            let closed = container.deny_unknown_fields;
            (
                quote!(::std::vec![#(#docs),*]),
                quote!(#(#checks)*),
                quote!(#d::object(#description, &<Self as ::nanomotion_core::doc::Params>::param_docs(), #closed)),
            )
        }
        Data::Enum(e) => {
            let rule = container.rename_all.as_deref();
            let mut variants = Vec::new();
            // `match self` arms checking the bounds declared on variant fields
            let mut arms = Vec::new();
            for v in &e.variants {
                let sf = serde_field(&v.attrs)?;
                if sf.skip {
                    continue;
                }
                let vname = sf
                    .rename
                    .clone()
                    .unwrap_or_else(|| rename(&v.ident.to_string(), rule));
                let mut names = vec![vname];
                names.extend(sf.aliases.iter().cloned());
                let vdoc = doc_text(&v.attrs);
                let content = match &v.fields {
                    Fields::Unit => quote!(::core::option::Option::None),
                    Fields::Unnamed(u) if u.unnamed.len() == 1 => {
                        let inner = schema_of(&u.unnamed[0].ty);
                        quote!(::core::option::Option::Some(#inner))
                    }
                    Fields::Unnamed(_) => quote!(::core::option::Option::Some(#d::any())),
                    Fields::Named(named) => {
                        let vcont = serde_container(&v.attrs)?;
                        let closed = vcont.deny_unknown_fields || container.deny_unknown_fields;
                        let mut docs = Vec::new();
                        let mut bound = Vec::new();
                        let mut checks = TokenStream2::new();
                        let mut orderings = TokenStream2::new();
                        for f in &named.named {
                            if let Some(fc) = field_code(f, &vcont, Access::Binding)? {
                                docs.push(fc.doc);
                                bound.extend(f.ident.clone());
                                checks.extend(fc.check);
                                orderings.extend(fc.ordering);
                            }
                        }
                        if !(checks.is_empty() && orderings.is_empty()) {
                            let vident = &v.ident;
                            arms.push(
                                quote!(Self::#vident { #(#bound,)* .. } => { #checks #orderings }),
                            );
                        }
                        quote!(::core::option::Option::Some(#d::object(#vdoc, &[#(#docs),*], #closed)))
                    }
                };
                for n in names {
                    variants.push(quote!(#d::Variant { name: #n, doc: #vdoc, content: #content }));
                }
            }
            let tagging = match (&container.tag, container.untagged) {
                (Some(t), _) => quote!(#d::Tagging::Internal(#t)),
                (None, true) => quote!(#d::Tagging::Untagged),
                (None, false) => quote!(#d::Tagging::External),
            };
            let closed = container.deny_unknown_fields;
            let checks = if arms.is_empty() {
                quote!()
            } else {
                quote!(
                    #[allow(unreachable_patterns)]
                    match self {
                        #(#arms)*
                        _ => {}
                    }
                )
            };
            (
                quote!(::std::vec::Vec::new()),
                checks,
                quote!(#d::enumeration(#description, #tagging, ::std::vec![#(#variants),*], #closed)),
            )
        }
        Data::Union(_) => {
            return Err(syn::Error::new_spanned(
                name,
                "#[derive(Params)] is for structs and enums",
            ));
        }
    };

    let closed = container.deny_unknown_fields;
    Ok(quote!(
        impl #impl_g ::nanomotion_core::doc::Params for #name #ty_g #where_g {
            const CLOSED: bool = #closed;
            fn param_docs() -> ::std::vec::Vec<::nanomotion_core::ParamDoc> {
                #param_docs
            }
            #[allow(unused_variables, clippy::needless_borrow, clippy::unnecessary_cast)]
            fn check_params(&self) -> ::core::result::Result<(), ::nanomotion_core::ParamError> {
                #checks
                ::core::result::Result::Ok(())
            }
            #rate_checks
        }
        impl #impl_g ::nanomotion_core::doc::ParamSchema for #name #ty_g #where_g {
            fn param_schema() -> #d::Value {
                #schema
            }
        }
        #registration
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use syn::parse_quote;

    fn bounds(attr: Attribute) -> syn::Result<Vec<Bound>> {
        param_attr(&[attr]).map(|p| p.bounds)
    }

    fn end(e: &Option<End>) -> Option<(String, bool)> {
        e.as_ref()
            .map(|e| (e.value.to_token_stream().to_string(), e.exclusive))
    }

    use quote::ToTokens;

    #[test]
    fn range_reads_every_form() {
        let b = bounds(parse_quote!(#[param(range(0.0, 46.0))])).unwrap();
        assert!(matches!(&b[..], [Bound::Range(..)]));
        type EndText = Option<(&'static str, bool)>;
        let cases: [(Attribute, EndText, EndText); 6] = [
            (parse_quote!(#[param(range(> 0))]), Some(("0", true)), None),
            (
                parse_quote!(#[param(range(>= 1))]),
                Some(("1", false)),
                None,
            ),
            (
                parse_quote!(#[param(range(<= 1))]),
                None,
                Some(("1", false)),
            ),
            (
                parse_quote!(#[param(range(< MAX))]),
                None,
                Some(("MAX", true)),
            ),
            (
                parse_quote!(#[param(range(> 0.25, < 1))]),
                Some(("0.25", true)),
                Some(("1", true)),
            ),
            (
                parse_quote!(#[param(range(<= - 1, >= - 5))]),
                Some(("- 5", false)),
                Some(("- 1", false)),
            ),
        ];
        for (attr, lo, hi) in cases {
            let b = bounds(attr).unwrap();
            let [Bound::Between(l, h)] = &b[..] else {
                panic!("not a Between");
            };
            let own = |x: Option<(&str, bool)>| x.map(|(s, e)| (s.to_string(), e));
            assert_eq!((end(l), end(h)), (own(lo), own(hi)));
        }
    }

    #[test]
    fn range_refuses_what_it_cannot_mean() {
        for attr in [
            parse_quote!(#[param(range(0, < 1))]),
            parse_quote!(#[param(range(> 0, > 1))]),
            parse_quote!(#[param(range(1))]),
            parse_quote!(#[param(range(1, 2, 3))]),
        ] {
            let attr: Attribute = attr;
            assert!(bounds(attr).is_err());
        }
        let e = match bounds(parse_quote!(#[param(range(> 0, >= 1))])) {
            Err(e) => e.to_string(),
            Ok(_) => panic!("two lower bounds accepted"),
        };
        assert!(e.contains("two lower bounds"), "{e}");
    }

    #[test]
    fn integer_fields_refuse_finite_and_fractional_bounds() {
        let u32_ty: Type = parse_quote!(u32);
        let opt: Type = parse_quote!(Option<i64>);
        assert!(check_of(&u32_ty, quote!(&self.n), quote!("n"), &Bound::Finite, 0).is_err());
        let b = bounds(parse_quote!(#[param(range(> 0.5))])).unwrap();
        assert!(check_of(&opt, quote!(&self.n), quote!("n"), &b[0], 0).is_err());
        let b = bounds(parse_quote!(#[param(range(1, 10))])).unwrap();
        let code = check_of(&u32_ty, quote!(&self.n), quote!("n"), &b[0], 0)
            .unwrap()
            .to_string();
        assert!(code.contains("check :: whole"), "{code}");
        // a usize's `width` keeps `check::width`
        let usize_ty: Type = parse_quote!(usize);
        let code = check_of(&usize_ty, quote!(&self.w), quote!("w"), &Bound::Width, 0)
            .unwrap()
            .to_string();
        assert!(code.contains("check :: width"), "{code}");
        // a float keeps the float checks
        let f: Type = parse_quote!(f64);
        let code = check_of(&f, quote!(&self.x), quote!("x"), &b[0], 0)
            .unwrap()
            .to_string();
        assert!(code.contains("check :: in_range"), "{code}");
    }

    #[test]
    fn list_bounds_need_a_list() {
        let b = bounds(parse_quote!(#[param(len(>= 1), increasing)])).unwrap();
        let f: Type = parse_quote!(f64);
        assert!(check_of(&f, quote!(&self.x), quote!("x"), &b[0], 0).is_err());
        let counts: Type = parse_quote!(Vec<u32>);
        assert!(check_of(&counts, quote!(&self.x), quote!("x"), &b[1], 0).is_err());
        let list: Type = parse_quote!(Option<Vec<f64>>);
        let code = check_of(&list, quote!(&self.x), quote!("x"), &b[0], 0)
            .unwrap()
            .to_string();
        assert!(code.contains("check :: entries"), "{code}");
        assert!(bounds(parse_quote!(#[param(len(0.5, 2))])).is_err());
    }

    #[test]
    fn hint_reads_and_needs_a_bound() {
        let p = param_attr(&[parse_quote!(#[param(range(1, 9), hint = "e.g. 3")])]).unwrap();
        assert_eq!(p.hint.as_deref(), Some("e.g. 3"));
        let f: syn::Field = parse_quote!(#[param(hint = "e.g. 3")] n: u32);
        assert!(field_code(&f, &SerdeContainer::default(), Access::SelfField).is_err());
    }
}
