//! `cargo test -p ignis-fuzz`: CI_CASES mutated inputs per reader, fixed seed; fails on
//! any panic, hang (per-case timeout), allocation over the cap (process abort) or a
//! changed checksummed input that was accepted.

use ignis_fuzz::{fuzz, target_seed, targets, CappedAlloc, CI_CASES};

#[global_allocator]
static ALLOC: CappedAlloc = CappedAlloc;

#[test]
fn every_reader_survives_mutated_inputs() {
    let start = std::time::Instant::now();
    let fx = targets::Fixtures::new().expect("fixtures");
    let mut report = Vec::new();
    let mut findings = Vec::new();
    for t in targets::all(&fx) {
        let t0 = std::time::Instant::now();
        let st = fuzz(&t, target_seed(18, t.name()), CI_CASES, None);
        assert_eq!(st.cases, CI_CASES);
        // The mutations must reach past the parser for some cases, and be refused for
        // others: a target that accepts or refuses everything is not being tested.
        assert!(st.refused > 0, "{}: nothing refused", t.name());
        report.push(format!(
            "{}: {} cases, {} accepted, {} refused, {} findings, {:.1} s",
            t.name(),
            st.cases,
            st.accepted,
            st.refused,
            st.findings.len(),
            t0.elapsed().as_secs_f64()
        ));
        findings.extend(st.findings);
    }
    for r in &report {
        println!("{r}");
    }
    println!("total {:.1} s", start.elapsed().as_secs_f64());
    for f in &findings {
        println!(
            "FINDING {} case {} ({}): {}\n  input: {:?}",
            f.target,
            f.case,
            f.kind,
            f.detail,
            String::from_utf8_lossy(&f.input[..f.input.len().min(300)])
        );
    }
    assert!(findings.is_empty(), "{} findings", findings.len());
}
