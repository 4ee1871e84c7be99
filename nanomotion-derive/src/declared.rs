//! `#[declared_block]` on an `impl Block for T`: the methods and the typetag
//! name that `T`'s `#[block(…)]` already declares.

use proc_macro2::TokenStream as TokenStream2;
use quote::quote;
use syn::{ImplItem, ItemImpl, parse_quote};

/// The names of the methods `item` writes itself.
fn written(item: &ItemImpl) -> Vec<String> {
    item.items
        .iter()
        .filter_map(|i| match i {
            ImplItem::Fn(f) => Some(f.sig.ident.to_string()),
            _ => None,
        })
        .collect()
}

pub(crate) fn expand(args: TokenStream2, mut item: ItemImpl) -> syn::Result<TokenStream2> {
    if !args.is_empty() {
        return Err(syn::Error::new_spanned(
            args,
            "#[declared_block] takes no arguments: the type name, role and ports are the #[block(…)] of the parameter struct",
        ));
    }
    let is_block = item
        .trait_
        .as_ref()
        .and_then(|(_, path, _)| path.segments.last())
        .is_some_and(|s| s.ident == "Block");
    if !is_block {
        return Err(syn::Error::new_spanned(
            &item.self_ty,
            "#[declared_block] goes on an `impl Block for T`",
        ));
    }
    if !item.generics.params.is_empty() {
        return Err(syn::Error::new_spanned(
            &item.generics,
            "#[declared_block] registers one concrete type: no generics",
        ));
    }
    if let Some(a) = item.attrs.iter().find(|a| {
        a.path()
            .segments
            .first()
            .is_some_and(|s| s.ident == "typetag")
    }) {
        return Err(syn::Error::new_spanned(
            a,
            "#[declared_block] registers the type with typetag under its declared type_name: remove this attribute",
        ));
    }
    let ty = item.self_ty.clone();
    let blk = quote!(::nanomotion_core::block);
    let has = written(&item);
    let has = |name: &str| has.iter().any(|n| n == name);
    // A macro invoked in the impl may write `output` (and `update`, …): it is
    // then its. The ports are the declaration's unless the impl names them.
    let macros = item.items.iter().any(|i| matches!(i, ImplItem::Macro(_)));
    if !has("inputs") && !has("outputs") {
        item.items.push(parse_quote!(
            fn inputs(&self) -> ::std::vec::Vec<::nanomotion_core::Port> {
                <Self as #blk::DeclaredPorts>::declared_inputs(self)
            }
        ));
        item.items.push(parse_quote!(
            fn outputs(&self) -> ::std::vec::Vec<::nanomotion_core::Port> {
                <Self as #blk::DeclaredPorts>::declared_outputs(self)
            }
        ));
    }
    if let Some(f) = item.items.iter().find_map(|i| match i {
        ImplItem::Fn(f) if f.sig.ident == "live_params" => Some(f),
        _ => None,
    }) {
        return Err(syn::Error::new_spanned(
            &f.sig,
            "#[declared_block] writes `live_params` from the #[block(live = \"…\")] of the parameter struct: declare the live parameters there and write only `set_live_param`",
        ));
    }
    item.items.push(parse_quote!(
        fn live_params(&self) -> &'static [&'static str] {
            <Self as #blk::DeclaredBlock>::LIVE_PARAMS
        }
    ));
    if !has("role") {
        item.items.push(parse_quote!(
            fn role(&self) -> ::nanomotion_core::Role {
                <Self as #blk::DeclaredBlock>::ROLE
            }
        ));
    }
    if !has("build") {
        item.items.push(parse_quote!(
            fn build(
                &mut self,
                ctx: &::nanomotion_core::BuildContext,
            ) -> ::core::result::Result<(), ::nanomotion_core::ParamError> {
                ::nanomotion_core::doc::Params::check_params(self)?;
                ::nanomotion_core::doc::Params::check_at_rate(self, ctx.dt)
            }
        ));
    }
    if !has("output") && !macros {
        // A block that writes no `output` is a source: it plays its `Source`.
        item.items.push(parse_quote!(
            fn output(&mut self, tick: ::nanomotion_core::Tick, _u: &[f64], y: &mut [f64]) {
                ::nanomotion_core::Source::sample(self, tick.t, y)
            }
        ));
    }
    Ok(quote!(
        #[::typetag::serde(name = <#ty as #blk::DeclaredBlock>::TYPE_NAME)]
        #item
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn methods(ts: &TokenStream2) -> String {
        ts.to_string()
    }

    #[test]
    fn the_left_out_methods_are_written_and_the_written_kept() {
        let item: ItemImpl = parse_quote!(
            impl Block for Step {
                fn output(&mut self, t: Tick, u: &[f64], y: &mut [f64]) {}
            }
        );
        let out = methods(&expand(TokenStream2::new(), item).unwrap());
        for m in [
            "fn inputs",
            "fn outputs",
            "fn live_params",
            "fn role",
            "fn build",
            "fn output",
        ] {
            assert!(out.contains(m), "{m} in {out}");
        }
        assert!(out.contains("DeclaredBlock > :: TYPE_NAME"), "{out}");
        assert!(!out.contains("Source :: sample"), "{out}");

        let item: ItemImpl = parse_quote!(
            impl Block for Sinusoid {}
        );
        let out = methods(&expand(TokenStream2::new(), item).unwrap());
        assert!(
            out.contains("Source :: sample (self , tick . t , y)"),
            "{out}"
        );

        let item: ItemImpl = parse_quote!(
            impl Block for Gain {
                fn outputs(&self) -> Vec<Port> { vec![] }
                fn role(&self) -> Role { Role::Math }
                fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> { Ok(()) }
                fn output(&mut self, t: Tick, u: &[f64], y: &mut [f64]) {}
            }
        );
        let out = methods(&expand(TokenStream2::new(), item).unwrap());
        assert!(!out.contains("DeclaredPorts"), "{out}");
        assert_eq!(out.matches("fn role").count(), 1);
        assert_eq!(out.matches("fn build").count(), 1);

        let item: ItemImpl = parse_quote!(
            impl Block for LowPass {
                core_steps!();
            }
        );
        let out = methods(&expand(TokenStream2::new(), item).unwrap());
        assert!(out.contains("DeclaredPorts"), "{out}");
        assert!(!out.contains("Source :: sample"), "{out}");
    }

    #[test]
    fn a_typetag_attribute_or_another_trait_is_refused() {
        let item: ItemImpl = parse_quote!(
            #[typetag::serde(name = "step")]
            impl Block for Step {}
        );
        assert!(expand(TokenStream2::new(), item).is_err());
        let item: ItemImpl = parse_quote!(
            impl Block for Gain {
                fn live_params(&self) -> &'static [&'static str] { &["k"] }
            }
        );
        let e = expand(TokenStream2::new(), item).unwrap_err().to_string();
        assert!(e.contains("#[block(live"), "{e}");
        let item: ItemImpl = parse_quote!(
            impl Source for Step {}
        );
        assert!(expand(TokenStream2::new(), item).is_err());
    }
}
