//! Plain-against-looping timing shared by the benches that measure a loop's overhead
//! (`volume`, `learned`): alternating runs, wall clock and process CPU time.

use std::time::Instant;

/// Wall-clock and process CPU seconds (every thread, rayon's included) of repeated runs.
#[derive(Default)]
pub struct Runs {
    pub wall: Vec<f64>,
    pub cpu: Vec<f64>,
}

impl Runs {
    pub fn least_wall(&self) -> f64 {
        least(&self.wall)
    }

    /// Times `f` once, wall clock and process CPU.
    pub fn time<T>(&mut self, f: impl FnOnce() -> T) -> T {
        let c = super::flow::process_cpu_ms();
        let t = Instant::now();
        let out = f();
        self.wall.push(t.elapsed().as_secs_f64());
        if let (Some(a), Some(b)) = (c, super::flow::process_cpu_ms()) {
            self.cpu.push((b - a) / 1e3);
        }
        out
    }
}

/// Seconds (or a ratio) rounded to 3 decimals, as the benches print them.
pub fn round3(s: f64) -> f64 {
    (s * 1000.0).round() / 1000.0
}

pub fn least(v: &[f64]) -> f64 {
    v.iter().copied().fold(f64::INFINITY, f64::min)
}

pub fn median(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// `plain` against `looping` as JSON: least wall times and their overhead (what the goals
/// read), and the CPU times (least, and the overhead of the medians) where the platform
/// reports them.
pub fn overhead_json(plain: &Runs, looping: &Runs) -> serde_json::Value {
    let s3 = round3;
    let ratio = |a: f64, b: f64| round3(a / b - 1.0);
    let (p, l) = (plain.least_wall(), looping.least_wall());
    let mut out = serde_json::json!({
        "plain_s": s3(p),
        "looping_s": s3(l),
        "overhead": ratio(l, p),
        "timing": format!("least of {} alternating runs each, wall clock", plain.wall.len()),
    });
    let (pc, lc) = (&plain.cpu, &looping.cpu);
    if !pc.is_empty() && pc.len() == lc.len() {
        out["plain_cpu_s"] = s3(least(pc)).into();
        out["looping_cpu_s"] = s3(least(lc)).into();
        out["cpu_overhead"] = ratio(least(lc), least(pc)).into();
        out["cpu_median_overhead"] = ratio(median(lc), median(pc)).into();
        out["cpu_timing"] = "CPU time of the process (every thread, CLOCK_PROCESS_CPUTIME_ID) per run: least, and the overhead of the medians".into();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overhead_reads_the_least_runs() {
        let plain = Runs {
            wall: vec![2.0, 1.0, 3.0],
            cpu: vec![2.0, 2.0, 4.0],
        };
        let looping = Runs {
            wall: vec![1.5, 1.2, 9.0],
            cpu: vec![2.2, 3.0, 2.5],
        };
        let j = overhead_json(&plain, &looping);
        assert_eq!(j["overhead"], 0.2);
        assert_eq!(j["cpu_overhead"], 0.1);
        assert_eq!(j["cpu_median_overhead"], 0.25);
        assert_eq!(j["plain_s"], 1.0);
    }
}
