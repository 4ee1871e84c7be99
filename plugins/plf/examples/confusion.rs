//! The confusion table of the discrepancy workflow over generated records: every
//! vocabulary effect hidden on the second-order stage (and the two-axis stage for
//! `axis_coupling`), several seeds each, plus noise-only records; then the six
//! effects of the walking-piezo records (fitted model (5.31) at 4 kHz, rows
//! `wp:EFFECT`). Prints a Markdown table (docs/plf.md quotes it):
//!
//! ```text
//! cargo run --release -p nanomotion-plf --example confusion [SEEDS] [EFFECT ...]
//! ```
//!
//! With effect names, only those rows (and each record's steps on stderr).

use nanomotion_core::graph::GraphSpec;
use nanomotion_plf::diagnose::{Options, diagnose, vocabulary};
use nanomotion_plf::generate;
use std::collections::BTreeMap;
use std::time::Instant;

use walking_piezo::records as wp;

fn main() {
    let _ = std::any::type_name::<nanomotion_plf::effects::Effect>();
    let seeds: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(5);
    let only: Vec<String> = std::env::args().skip(2).collect();
    let n = 12_000;
    // (hidden effect, what was named first with counts, first-step cuts, s per record)
    type Row = (String, BTreeMap<String, usize>, Vec<f64>, f64);
    let mut rows: Vec<Row> = Vec::new();
    let start = Instant::now();
    let rows_wanted: Vec<String> = vocabulary()
        .into_iter()
        .chain(["none"])
        .map(str::to_string)
        .chain(wp::EFFECTS.iter().map(|e| format!("wp:{e}")))
        .filter(|e| only.is_empty() || only.iter().any(|o| o == e))
        .collect();
    for row in &rows_wanted {
        let (walking, effect) = match row.strip_prefix("wp:") {
            Some(e) => (true, e),
            None => (false, row.as_str()),
        };
        let mut named: BTreeMap<String, usize> = BTreeMap::new();
        let mut cuts = Vec::new();
        let t0 = Instant::now();
        for seed in 1..=seeds {
            let (nominal_yaml, data, truth) = if walking {
                let (data, truth) = wp::record(effect, seed).expect("walking-piezo record");
                (wp::nominal_yaml(), data, truth)
            } else {
                let rec = if effect == "axis_coupling" {
                    generate::two_axis(effect, seed, n)
                } else {
                    generate::second_order(effect, seed, n, false)
                }
                .expect("generator");
                (rec.nominal_yaml, rec.data, rec.truth)
            };
            let spec =
                GraphSpec::from_yaml(&nominal_yaml, "generated.yaml").expect("nominal graph");
            let r = diagnose(&spec, &data, &Options::default()).expect("diagnose");
            if !only.is_empty() {
                eprintln!("  seed {seed}: {truth}");
                for st in &r.steps {
                    eprintln!(
                        "    {} {}: held-out rms {:.3e} -> {:.3e}",
                        st.effect, st.site, st.holdout_rms_before, st.holdout_rms_after
                    );
                }
                eprintln!("    stopped: {}", r.stopped_because);
            }
            let first = r.found.first().cloned().unwrap_or_else(|| "[]".into());
            *named.entry(first).or_default() += 1;
            if let Some(s) = r.steps.first() {
                cuts.push(100.0 * (1.0 - s.holdout_rms_after / s.holdout_rms_before));
            }
            if r.found.len() > 1 {
                *named
                    .entry(format!("(+{} more)", r.found.len() - 1))
                    .or_default() += 1;
            }
        }
        eprintln!("{row}: {named:?} in {:.1} s", t0.elapsed().as_secs_f64());
        rows.push((
            row.clone(),
            named,
            cuts,
            t0.elapsed().as_secs_f64() / seeds as f64,
        ));
    }
    let records = rows.len() as u64 * seeds;
    println!(
        "| hidden | named first (count of {seeds} seeds) | first step's held-out cut (min / median) | s per record |"
    );
    println!("|---|---|---|---|");
    for (effect, named, mut cuts, secs) in rows {
        cuts.sort_by(f64::total_cmp);
        let cut = if cuts.is_empty() {
            "—".to_string()
        } else {
            format!("{:.0} % / {:.0} %", cuts[0], cuts[cuts.len() / 2])
        };
        let names: Vec<String> = named.iter().map(|(k, v)| format!("{k} {v}")).collect();
        println!("| {effect} | {} | {cut} | {secs:.1} |", names.join(", "));
    }
    println!(
        "\n{} records (second-order: {n} samples at 2 kHz; walking piezo: {} at 4 kHz) in {:.0} s",
        records,
        wp::N,
        start.elapsed().as_secs_f64()
    );
}
