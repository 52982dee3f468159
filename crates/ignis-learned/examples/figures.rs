//! Prints the headline benchmark figures: `cargo run --release -p ignis-learned --example figures`.
fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    match ignis_learned::bench::figures(quick) {
        Ok(v) => println!("{}", serde_json::to_string_pretty(&v).expect("json")),
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    }
}
