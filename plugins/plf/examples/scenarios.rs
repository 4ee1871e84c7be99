//! The workflow judged on records it was not built against: the held-out
//! families of [`nanomotion_plf::scenario`] (never used for tuning), with precision and recall per effect, the rate of records named
//! correctly, padding and false alarms, broken down by family. docs/plf.md
//! quotes its output:
//!
//! ```text
//! cargo run --release -p nanomotion-plf --example scenarios -- [COUNT] [--from SEED] [--tune] [--hidden EFFECT] [--csv FILE] [--reports DIR] [--visibility-only | --labels-only]
//! ```
//!
//! COUNT held-out records (default 300) from seed 0 on (`--from SEED`: from
//! that seed on — records no change has been looked at yet, once the first
//! ones have been scored and studied); `--tune` takes the
//! tuning split instead (the only records the workflow may be tuned on).
//! `--csv` writes one row per record. `--visibility-only` runs no diagnosis:
//! it prints `seed,visibility,held_out_visibility,calibrated_visibility,calibrated_per_effect`
//! of the same records ([`scenario::visibility`]: what the hidden effects change
//! over the noise, over the whole record, over the part `diagnose` holds out,
//! there beyond what the nominal calibration takes, and that last for each
//! hidden effect alone as `effect:value` pairs), for
//! `tools/scenario_table.py --visibility`. `--hidden EFFECT` keeps only records
//! hiding that effect (`none`: the effect-free ones); `--labels-only` prints
//! `seed,hidden,family` of the records and diagnoses nothing.
//!
//! Scoring: a record is *named correctly* when every hidden effect is named and
//! nothing else (an effect-free record: nothing named); *padding* is a named
//! effect that is not hidden (on records with something hidden); a *false
//! alarm* is any name on an effect-free record. Precision of an effect: of the
//! records it was named on, the share where it was hidden; recall: of the
//! records it was hidden in, the share where it was named.

use nanomotion_core::graph::GraphSpec;
use nanomotion_plf::diagnose::{Options, diagnose};
use nanomotion_plf::scenario;
use std::collections::BTreeMap;
use std::io::Write as _;
use std::time::Instant;

/// The usage line of the module doc, printed for `--help` and an unknown option.
const USAGE: &str = "usage: scenarios [COUNT] [--from SEED] [--tune] [--hidden EFFECT] [--csv FILE] [--reports DIR] [--visibility-only | --labels-only]
  COUNT         records to diagnose (default 300), held-out families unless --tune
  --from SEED   start at this seed (records no change has been looked at yet)
  --tune        the tuning split instead (the only records the workflow may be tuned on)
  --hidden E    only records hiding effect E (`none`: the effect-free ones)
  --csv FILE    one row per record
  --reports DIR each record's labels and diagnosis report as DIR/seed_SEED.json
  --visibility-only, --labels-only   diagnose nothing: print the visibilities (see the doc) or seed,hidden,family";

#[derive(Default)]
struct Tally {
    records: usize,
    correct: usize,
}

fn main() {
    let _ = std::any::type_name::<nanomotion_plf::effects::Effect>();
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.iter().any(|a| a == "--help" || a == "-h") {
        println!("{USAGE}");
        return;
    }
    let known = [
        "--tune",
        "--visibility-only",
        "--labels-only",
        "--hidden",
        "--csv",
        "--from",
        "--reports",
    ];
    if let Some(a) = args
        .iter()
        .find(|a| a.starts_with('-') && !known.contains(&a.as_str()))
    {
        eprintln!("unknown option `{a}`\n{USAGE}");
        std::process::exit(2);
    }
    let tune = args.iter().any(|a| a == "--tune");
    let visibility_only = args.iter().any(|a| a == "--visibility-only");
    let labels_only = args.iter().any(|a| a == "--labels-only");
    let hidden_only = args
        .iter()
        .position(|a| a == "--hidden")
        .and_then(|i| args.get(i + 1).cloned());
    let csv_path = args
        .iter()
        .position(|a| a == "--csv")
        .and_then(|i| args.get(i + 1).cloned());
    let reports_dir = args
        .iter()
        .position(|a| a == "--reports")
        .and_then(|i| args.get(i + 1).map(std::path::PathBuf::from));
    if let Some(d) = &reports_dir
        && let Err(e) = std::fs::create_dir_all(d)
    {
        eprintln!("--reports {}: {e}", d.display());
        std::process::exit(2);
    }
    let first_seed: u64 = args
        .iter()
        .position(|a| a == "--from")
        .and_then(|i| args.get(i + 1))
        .and_then(|a| a.parse().ok())
        .unwrap_or(0);
    let count: usize = args
        .iter()
        .enumerate()
        .find(|(i, _)| {
            *i == 0
                || !matches!(
                    args[i - 1].as_str(),
                    "--csv" | "--hidden" | "--from" | "--reports"
                )
        })
        .and_then(|(_, a)| a.parse().ok())
        .unwrap_or(300);
    let mut csv = String::from(
        "seed,plant,loop,excitation,noise,nominal,rate_hz,unit,hidden,found,correct,holdout_cut_percent,calibrated,seconds\n",
    );
    // Per effect: (hidden in, named on, named where hidden).
    let mut per_effect: BTreeMap<String, (usize, usize, usize)> = BTreeMap::new();
    let mut by_dim: BTreeMap<(String, String), Tally> = BTreeMap::new();
    let (mut records, mut correct, mut with_effect, mut padded, mut clean, mut alarms, mut failed) =
        (0usize, 0usize, 0usize, 0usize, 0usize, 0usize, 0usize);
    let mut seconds = Vec::new();
    let (mut correct_cut, mut calibrations) = (0usize, 0usize);
    let start = Instant::now();
    let mut seed = first_seed;
    while records < count {
        let (hidden, family) = scenario::labels(seed);
        seed += 1;
        if (family.split() == scenario::Split::Tune) != tune {
            continue;
        }
        if let Some(h) = &hidden_only
            && !(hidden.contains(&h.as_str()) || (h == "none" && hidden.is_empty()))
        {
            continue;
        }
        if labels_only {
            println!("{},{},{family:?}", seed - 1, hidden.join("+"));
            records += 1;
            continue;
        }
        if visibility_only {
            // A seed that cannot be drawn is skipped, as below: the same records.
            match scenario::visibility(seed - 1) {
                Ok(v) => {
                    if records == 0 {
                        println!(
                            "seed,visibility,held_out_visibility,calibrated_visibility,calibrated_per_effect"
                        );
                    }
                    println!(
                        "{},{:.3},{:.3},{:.3},{}",
                        seed - 1,
                        v.whole,
                        v.held_out,
                        v.calibrated,
                        v.per_effect
                            .iter()
                            .map(|(e, x)| format!("{e}:{x:.3}"))
                            .collect::<Vec<_>>()
                            .join(" ")
                    );
                    records += 1;
                }
                Err(e) => eprintln!("seed {}: {e}", seed - 1),
            }
            continue;
        }
        let s = match scenario::draw(seed - 1) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("seed {}: {e}", seed - 1);
                continue;
            }
        };
        let t0 = Instant::now();
        let spec =
            GraphSpec::from_yaml(&s.record.nominal_yaml, "scenario.yaml").expect("nominal graph");
        let mut steps_text = String::new();
        let (found, cut, calibrated) = match diagnose(&spec, &s.record.data, &Options::default()) {
            Ok(r) => (
                {
                    if let Some(d) = &reports_dir {
                        write_report(d, seed - 1, &hidden, &format!("{family:?}"), &r);
                    }
                    for st in &r.steps {
                        steps_text += &format!(
                            " {}@{} {}{:.0}%{}",
                            st.effect,
                            st.site.split_whitespace().next().unwrap_or(""),
                            if st.cut_percent < 0.0 { "+" } else { "−" },
                            st.cut_percent.abs(),
                            if st.ambiguous_with.is_empty() {
                                String::new()
                            } else {
                                format!(
                                    "~{}",
                                    st.ambiguous_with
                                        .iter()
                                        .map(|a| a.effect.as_str())
                                        .collect::<Vec<_>>()
                                        .join("~")
                                )
                            }
                        );
                    }
                    r.found
                },
                r.holdout_cut_percent,
                r.calibration.is_some_and(|c| c.accepted),
            ),
            Err(e) => {
                eprintln!("seed {}: diagnose refused: {e}", seed - 1);
                failed += 1;
                (vec!["(refused)".to_string()], 0.0, false)
            }
        };
        calibrations += usize::from(calibrated);
        let secs = t0.elapsed().as_secs_f64();
        seconds.push(secs);
        records += 1;
        let hidden: Vec<String> = hidden.iter().map(|e| e.to_string()).collect();
        let ok = found.len() == hidden.len() && hidden.iter().all(|h| found.contains(h));
        correct += usize::from(ok);
        correct_cut += usize::from(ok && (hidden.is_empty() || cut >= 50.0));
        if hidden.is_empty() {
            clean += 1;
            alarms += usize::from(!found.is_empty());
        } else {
            with_effect += 1;
            padded += usize::from(found.iter().any(|f| !hidden.contains(f)));
        }
        for h in &hidden {
            let e = per_effect.entry(h.clone()).or_default();
            e.0 += 1;
            e.2 += usize::from(found.contains(h));
        }
        for f in &found {
            per_effect.entry(f.clone()).or_default().1 += 1;
        }
        let hidden_key = if hidden.is_empty() {
            "none".to_string()
        } else {
            hidden.join("+")
        };
        for (dim, value) in [
            ("plant", family.plant.to_string()),
            ("loop", family.loop_kind.to_string()),
            ("excitation", family.excitation.to_string()),
            ("noise", family.noise.to_string()),
            ("nominal", family.nominal.to_string()),
            ("rate", format!("{} Hz", family.rate_hz)),
            ("hidden", hidden_key.clone()),
        ] {
            let t = by_dim.entry((dim.to_string(), value)).or_default();
            t.records += 1;
            t.correct += usize::from(ok);
        }
        csv += &format!(
            "{},{},{},{},{},{},{},{},{},{},{},{:.1},{},{:.2}\n",
            seed - 1,
            family.plant,
            family.loop_kind,
            family.excitation,
            family.noise,
            family.nominal,
            family.rate_hz,
            family.unit,
            hidden_key,
            found.join("+"),
            ok,
            cut,
            calibrated,
            secs
        );
        eprintln!(
            "[{records}/{count}] seed {}: {:?} hidden {hidden:?} found {found:?} cut {cut:.0} %{} [{steps_text} ] ({secs:.1} s)",
            seed - 1,
            family,
            if calibrated { ", calibrated" } else { "" }
        );
        let _ = std::io::stderr().flush();
    }
    if visibility_only || labels_only {
        return;
    }
    let pct = |a: usize, b: usize| {
        if b == 0 {
            "—".to_string()
        } else {
            format!("{:.0} %", 100.0 * a as f64 / b as f64)
        }
    };
    seconds.sort_by(f64::total_cmp);
    println!(
        "{} records of the {} families (seeds {}–{}), {:.0} s in all",
        records,
        if tune { "tuning" } else { "held-out" },
        first_seed,
        seed - 1,
        start.elapsed().as_secs_f64()
    );
    println!();
    println!("| measure | value |\n|---|---|");
    println!(
        "| named correctly (exactly the hidden effects) | {} ({correct} of {records}) |",
        pct(correct, records)
    );
    println!(
        "| named correctly, and the held-out rms cut ≥ 50 % (effect-free: nothing named) | {} ({correct_cut} of {records}) |",
        pct(correct_cut, records)
    );
    println!(
        "| nominal calibration kept | {} ({calibrations} of {records}) |",
        pct(calibrations, records)
    );
    println!(
        "| padding (a name not hidden, records with an effect) | {} ({padded} of {with_effect}) |",
        pct(padded, with_effect)
    );
    println!(
        "| false alarms (a name on an effect-free record) | {} ({alarms} of {clean}) |",
        pct(alarms, clean)
    );
    println!("| refused by diagnose | {failed} |");
    println!(
        "| time per record (median / max) | {:.1} s / {:.1} s |",
        seconds.get(seconds.len() / 2).copied().unwrap_or(0.0),
        seconds.last().copied().unwrap_or(0.0)
    );
    println!();
    println!("| effect | hidden in | named on | precision | recall |\n|---|---|---|---|---|");
    for (e, (h, n, both)) in &per_effect {
        println!(
            "| {e} | {h} | {n} | {} | {} |",
            pct(*both, *n),
            pct(*both, *h)
        );
    }
    println!();
    println!("| family | value | records | named correctly |\n|---|---|---|---|");
    for ((dim, value), t) in &by_dim {
        println!(
            "| {dim} | {value} | {} | {} |",
            t.records,
            pct(t.correct, t.records)
        );
    }
    if let Some(p) = csv_path
        && let Err(e) = std::fs::write(&p, csv)
    {
        eprintln!("error: cannot write {p}: {e}");
        std::process::exit(1);
    }
}

/// `DIR/seed_SEED.json`: the record's labels and its whole diagnosis report
/// (the CLI's report.json), for looking at what decided each step; written
/// to a temporary file and renamed, so a file is whole or absent.
fn write_report(
    dir: &std::path::Path,
    seed: u64,
    hidden: &[&str],
    family: &str,
    report: &nanomotion_plf::diagnose::Report,
) {
    let path = dir.join(format!("seed_{seed}.json"));
    let tmp = dir.join(format!(".seed_{seed}.json.tmp"));
    let text =
        serde_json::json!({"seed": seed, "hidden": hidden, "family": family, "report": report});
    let done = serde_json::to_string_pretty(&text)
        .map_err(|e| e.to_string())
        .and_then(|t| std::fs::write(&tmp, t).map_err(|e| e.to_string()))
        .and_then(|()| std::fs::rename(&tmp, &path).map_err(|e| e.to_string()));
    if let Err(e) = done {
        eprintln!("seed {seed}: report not written to {}: {e}", path.display());
    }
}
