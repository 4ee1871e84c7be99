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

/// The live parameters have one declaration, each block's `#[block(live =
/// "…")]`: docs/realtime.md lists what it declares, word for word, and every
/// block's `live_params` is its declaration.
#[test]
fn the_live_parameters_the_docs_list_are_the_declared_ones() {
    nanomotion::link_plugins();
    let declared = nanomotion::core::doc::live_params_by_type();
    assert!(
        declared.contains("`low_pass` `cutoff_hz`") && declared.contains("`pi` `kp`, `zero_hz`"),
        "{declared}"
    );
    let words = |s: &str| s.split_whitespace().collect::<Vec<_>>().join(" ");
    let doc =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/realtime.md")).unwrap();
    assert!(
        words(&doc).contains(&format!("declare any: {declared} (")),
        "docs/realtime.md, \"What can change\", must list the declared live parameters: {declared}"
    );
    // Built, each block reports what its type declares, in slot order.
    let yaml = "base_rate_hz: 1000\nduration_s: 0.01\nblocks:\n  - { name: g, type: gain, k: 2.0 }\n  - { name: lp, type: low_pass, cutoff_hz: 50.0, order: 2 }\n  - { name: c, type: pi, kp: 1.0, zero_hz: 5.0 }\n  - { name: s, type: saturation, lower: -1.0, upper: 1.0 }\n  - { name: z, type: constant, value: 0.0 }\nconnections:\n  - { from: z.y, to: g.u }\n  - { from: g.y, to: lp.u }\n  - { from: lp.y, to: c.e }\n  - { from: c.u, to: s.u }\n";
    let (sched, _) = nanomotion::core::GraphSpec::from_yaml(yaml, "live.yaml")
        .unwrap()
        .build()
        .unwrap();
    let docs = block_docs();
    for (i, name) in sched.block_names().iter().enumerate() {
        let b = sched.block_at(i).unwrap();
        let d = docs
            .iter()
            .find(|d| d.type_name == b.typetag_name())
            .unwrap();
        assert_eq!(b.live_params(), d.live, "block `{name}`");
    }
}
