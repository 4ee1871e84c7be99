//! `nanomotion reproduce`: run the thesis experiments (`nanomotion::thesis`), print a
//! table and write `fidelity.md`, `fidelity.json` (deterministic) and `timings.json`.

use indicatif::{ProgressBar, ProgressStyle};
use nanomotion::output::{Manifest, OutputFolder};
use nanomotion::thesis::{self, Mode};
use std::path::Path;
use std::time::Instant;

/// The arguments of `nanomotion reproduce`.
pub struct Args<'a> {
    pub names: &'a [String],
    pub quick: bool,
    pub out: &'a Path,
    pub list: bool,
    pub force: bool,
}

/// Run it; `Ok(false)` when an experiment could not run (exit status non-zero).
pub fn run(args: Args<'_>) -> Result<bool, String> {
    if args.list {
        say!("{:<12} {:<6} title", "id", "quick");
        for e in thesis::experiments() {
            say!(
                "{:<12} {:<6} {}",
                e.id,
                if e.in_quick { "yes" } else { "no" },
                e.title
            );
        }
        return Ok(true);
    }
    let chosen = thesis::select(args.names, args.quick)?;
    if chosen.is_empty() {
        return Err(
            "no experiment selected (fix: drop --quick, or name experiments that are in the quick set; `nanomotion reproduce --list`)".into(),
        );
    }
    // Checked before the experiments run; the files appear when all are written.
    let folder = OutputFolder::prepare(args.out, args.force).map_err(|e| e.to_string())?;
    let mode = if args.quick { Mode::Quick } else { Mode::Full };
    let bar = ProgressBar::new(chosen.len() as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} reproducing [{bar:30}] {pos}/{len} {msg} ({elapsed})",
        )
        .expect("static template")
        .progress_chars("=> "),
    );
    let mut walls = Vec::new();
    let mut last = Instant::now();
    let outcomes = thesis::run_all(&chosen, mode, |i, id| {
        if i > 0 {
            walls.push(last.elapsed().as_secs_f64());
        }
        last = Instant::now();
        bar.set_position(i as u64);
        bar.set_message(id.to_string());
    });
    walls.push(last.elapsed().as_secs_f64());
    bar.finish_and_clear();
    let command = command_line(args.names, args.quick);
    let md = thesis::fidelity_markdown(&outcomes, mode, &command);
    let json = thesis::fidelity_json(&outcomes);
    let timings: Vec<serde_json::Value> = outcomes
        .iter()
        .zip(&walls)
        .map(|(o, w)| serde_json::json!({ "id": o.id, "wall_s": (w * 1e3).round() / 1e3 }))
        .collect();
    for (name, text) in [
        ("fidelity.md", md),
        ("fidelity.json", json),
        (
            "timings.json",
            serde_json::to_string_pretty(&timings).unwrap_or_default() + "\n",
        ),
    ] {
        let path = folder.dir().join(name);
        std::fs::write(&path, text)
            .map_err(|e| format!("cannot write `{}`: {e}", path.display()))?;
    }
    folder
        .commit(Some(&Manifest {
            command: "reproduce",
            graph: "",
            title: &Some(command.clone()),
            stability_gate: &[],
        }))
        .map_err(|e| e.to_string())?;
    say!(
        "{:<10} {:<48} {:>10} {:>12} {:>10}",
        "id",
        "quantity",
        "verdict",
        "thesis",
        "ours"
    );
    for o in &outcomes {
        match &o.report {
            Some(r) => {
                for row in &r.rows {
                    say!(
                        "{:<10} {:<48} {:>10} {:>12} {:>10}",
                        o.id,
                        clip(&row.quantity, 48),
                        row.verdict.as_str(),
                        clip(&row.thesis, 12),
                        clip(&row.ours, 24)
                    );
                }
            }
            None => say!(
                "{:<10} {:<48} {:>10} {}",
                o.id,
                clip(&o.title, 48),
                "error",
                o.error.as_deref().unwrap_or("")
            ),
        }
    }
    let [m, s, d, e] = thesis::tally(&outcomes);
    let total: f64 = walls.iter().sum();
    say!(
        "{} experiments in {total:.1} s: {m} matches, {s} shape, {d} deviates, {e} error(s); wrote fidelity.md, fidelity.json, timings.json to {}",
        outcomes.len(),
        args.out.display()
    );
    Ok(e == 0)
}

/// `s` cut to `n` characters (with … when cut).
fn clip(s: &str, n: usize) -> String {
    if s.chars().count() <= n {
        s.to_string()
    } else {
        s.chars().take(n - 1).chain(std::iter::once('…')).collect()
    }
}

/// The command as written in fidelity.md (no paths: `--out` is left out).
fn command_line(names: &[String], quick: bool) -> String {
    let mut c = String::from("nanomotion reproduce");
    for n in names {
        c.push(' ');
        c.push_str(n);
    }
    if quick {
        c.push_str(" --quick");
    }
    c
}
