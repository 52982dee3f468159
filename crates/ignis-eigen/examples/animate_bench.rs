//! Prints the `ignis bench eigen-animate` figures (see `ignis_eigen::bench`).
//!
//! `cargo run --release -p ignis-eigen --example animate_bench -- [--quick] [--db DIR]`
//! (`--db` keeps the trained database in DIR and reuses it on later runs).

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let quick = args.iter().any(|a| a == "--quick");
    let db = args
        .iter()
        .position(|a| a == "--db")
        .and_then(|i| args.get(i + 1))
        .map(std::path::PathBuf::from);
    match ignis_eigen::bench::animate_figures(quick, db.as_deref()) {
        Ok(v) => println!("{}", serde_json::to_string_pretty(&v).expect("JSON")),
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    }
}
