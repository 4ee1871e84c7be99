//! Every block type linked into the facade is registered with typetag and
//! documented for `nanomotion blocks`, and the two registries agree.

use nanomotion::core::block::{block_docs, registered_types};

#[test]
fn every_registered_type_is_documented_and_vice_versa() {
    nanomotion::link_plugins();
    let types = registered_types();
    let docs = block_docs();
    assert!(
        types.len() >= 20,
        "expected the standard library at least, got {types:?}"
    );
    for t in &types {
        assert!(
            docs.iter().any(|d| d.type_name == t),
            "type `{t}` has no BlockDoc"
        );
    }
    for d in &docs {
        assert!(
            types.iter().any(|t| t == d.type_name),
            "doc for `{}` but no such type",
            d.type_name
        );
        assert!(
            !d.summary.is_empty() && !d.ports.is_empty(),
            "`{}` doc is empty",
            d.type_name
        );
    }
    // Tags are unique (typetag would only fail when a duplicate is read).
    let mut sorted = types.clone();
    sorted.dedup();
    assert_eq!(sorted.len(), types.len());
}
