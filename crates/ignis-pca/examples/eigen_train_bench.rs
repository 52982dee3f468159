//! Prints `ignis_pca::bench_figures` as JSON.
//! Full run (thesis size, ~2.5 GB RAM): `cargo run --release -p ignis-pca --example eigen_train_bench`
//! Quick run: `cargo run --release -p ignis-pca --example eigen_train_bench -- --quick`
fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let v = ignis_pca::bench_figures(quick);
    println!("{}", serde_json::to_string_pretty(&v).expect("json"));
}
