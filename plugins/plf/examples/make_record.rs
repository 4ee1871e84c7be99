//! Write a generated record with hidden effects and its nominal model, to try
//! `nanomotion diagnose` on data whose truth you know:
//!
//! ```text
//! cargo run --release -p nanomotion-plf --example make_record -- EFFECT[+EFFECT] SEED SAMPLES DIR
//! nanomotion diagnose DIR/model.yaml DIR/record.csv
//! ```
//!
//! EFFECT is a vocabulary name (or `none`); `axis_coupling` makes a two-axis record;
//! `scenario` writes record SEED of [`nanomotion_plf::scenario`] (SAMPLES ignored).

use nanomotion_plf::generate;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() != 4 {
        eprintln!(
            "usage: make_record EFFECT[+EFFECT] SEED SAMPLES DIR   (or: make_record scenario SEED 0 DIR)"
        );
        std::process::exit(2);
    }
    let (effect, dir) = (&args[0], std::path::PathBuf::from(&args[3]));
    let (Ok(seed), Ok(n)) = (args[1].parse::<u64>(), args[2].parse::<usize>()) else {
        eprintln!("error: SEED and SAMPLES must be whole numbers");
        std::process::exit(2);
    };
    let rec = if effect == "scenario" {
        // A record of the wider distribution (SAMPLES is ignored: the scenario
        // draws its own length).
        nanomotion_plf::scenario::draw(seed).map(|s| {
            eprintln!("scenario {seed}: {:?}", s.family);
            s.record
        })
    } else if effect == "axis_coupling" {
        generate::two_axis(effect, seed, n)
    } else {
        generate::second_order(effect, seed, n, false)
    };
    let rec = match rec {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    };
    let write = |name: &str, text: &str| {
        if let Err(e) =
            std::fs::create_dir_all(&dir).and_then(|_| std::fs::write(dir.join(name), text))
        {
            eprintln!("error: cannot write {}: {e}", dir.join(name).display());
            std::process::exit(1);
        }
    };
    write("model.yaml", &rec.nominal_yaml);
    write(
        "record.csv",
        &format!("# truth: {}\n{}", rec.truth, rec.data.to_csv_string()),
    );
    println!(
        "wrote {0}/model.yaml and {0}/record.csv — hidden: {1}",
        dir.display(),
        rec.truth
    );
}
