//! `cargo run --release -p ignis-fuzz -- --minutes 10 [--seed N]`: fuzzes every reader
//! until the time is up (round-robin, fresh seeds each round) and prints a JSON summary;
//! exits 1 if anything panicked, hung or passed a checksum it should not have.

use std::time::{Duration, Instant};

use ignis_fuzz::{fuzz, target_seed, targets, CappedAlloc};

#[global_allocator]
static ALLOC: CappedAlloc = CappedAlloc;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut minutes = 10.0f64;
    let mut seed = 1u64;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--minutes" => {
                minutes = args
                    .next()
                    .and_then(|v| v.parse().ok())
                    .ok_or("--minutes needs a number, e.g. --minutes 10")?
            }
            "--seed" => {
                seed = args
                    .next()
                    .and_then(|v| v.parse().ok())
                    .ok_or("--seed needs a whole number")?
            }
            "-h" | "--help" => {
                println!("ignis-fuzz: fuzz every Ignis reader\n\nUsage: cargo run --release -p ignis-fuzz -- [--minutes 10] [--seed 1]\n\nExamples:\n  cargo run --release -p ignis-fuzz -- --minutes 10\n  cargo run --release -p ignis-fuzz -- --minutes 1 --seed 7");
                return Ok(());
            }
            other => {
                return Err(
                    format!("unknown argument `{other}`; use --minutes M and --seed N").into(),
                )
            }
        }
    }
    if !(minutes.is_finite() && minutes > 0.0 && minutes <= 24.0 * 60.0) {
        return Err("--minutes must be in (0, 1440]".into());
    }
    let start = Instant::now();
    let until = start + Duration::from_secs_f64(minutes * 60.0);
    let fx = targets::Fixtures::new()?;
    let all = targets::all(&fx);
    let mut totals: Vec<(String, usize, usize, usize)> = all
        .iter()
        .map(|t| (t.name().to_string(), 0, 0, 0))
        .collect();
    let mut findings = Vec::new();
    let mut round = 0u64;
    while Instant::now() < until {
        for (i, t) in all.iter().enumerate() {
            let st = fuzz(
                t,
                target_seed(seed.wrapping_add(round), t.name()),
                100,
                Some(until),
            );
            totals[i].1 += st.cases;
            totals[i].2 += st.accepted;
            totals[i].3 += st.refused;
            for f in st.findings {
                eprintln!(
                    "FINDING {} case {} ({}): {}",
                    f.target, f.case, f.kind, f.detail
                );
                eprintln!(
                    "  input: {:?}",
                    String::from_utf8_lossy(&f.input[..f.input.len().min(400)])
                );
                findings.push(f);
            }
        }
        round += 1;
    }
    let summary = serde_json::json!({
        "seconds": start.elapsed().as_secs_f64(),
        "seed": seed,
        "rounds": round,
        "targets": totals.iter().map(|(n, c, a, r)| serde_json::json!({"target": n, "cases": c, "accepted": a, "refused": r})).collect::<Vec<_>>(),
        "cases": totals.iter().map(|t| t.1).sum::<usize>(),
        "findings": findings.len(),
    });
    println!("{}", serde_json::to_string_pretty(&summary)?);
    if !findings.is_empty() {
        std::process::exit(1);
    }
    Ok(())
}
