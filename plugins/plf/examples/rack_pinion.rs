//! Write the rack-and-pinion record (`../shared/data/friction_rack_pinion`) as
//! one CSV that `nanomotion diagnose` reads, joined as its author joins the two
//! loggers ([`nanomotion_plf::datasets::rack_pinion`]):
//!
//! ```text
//! cargo run --release -p nanomotion-plf --example rack_pinion -- ../shared/data/friction_rack_pinion /tmp/rack_pinion.csv
//! nanomotion diagnose examples/diagnose/rack_pinion_nominal.yaml /tmp/rack_pinion.csv
//! ```

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() != 2 {
        eprintln!("usage: rack_pinion DATASET_DIR OUT.csv");
        std::process::exit(2);
    }
    let data = match nanomotion_plf::datasets::rack_pinion(std::path::Path::new(&args[0])) {
        Ok(d) => d,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    };
    if let Err(e) = std::fs::write(&args[1], data.to_csv_string()) {
        eprintln!("error: cannot write {}: {e}", args[1]);
        std::process::exit(1);
    }
    println!(
        "wrote {} ({} samples at {} Hz)",
        args[1],
        data.len(),
        data.rate_hz()
    );
}
