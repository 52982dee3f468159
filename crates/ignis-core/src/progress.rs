//! Progress reporting for long work: the one progress type every Ignis library takes.
//!
//! A library reports stages (a name and a step count) and steps; the CLI draws them as
//! progress bars, tests and embedders pass [`NoProgress`]. Every method has a no-op default,
//! so an implementation overrides only what it shows.

/// Receives progress from long-running library calls.
pub trait Progress {
    /// A new stage of `len` steps (0 = unknown length).
    fn stage(&mut self, _name: &str, _len: u64) {}
    /// `n` more steps of the current stage are done.
    fn inc(&mut self, _n: u64) {}
    /// A line worth showing beside the bar (e.g. an iteration's log-likelihood).
    fn message(&mut self, _text: &str) {}
    /// A named figure of the step just reported (e.g. `"log-likelihood"` after an EM
    /// iteration), for callers that watch values rather than read lines.
    fn value(&mut self, _name: &str, _value: f64) {}
    /// The current stage is finished.
    fn finish_stage(&mut self) {}
}

/// No progress output.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoProgress;
impl Progress for NoProgress {}

/// Counts steps per stage; for tests and for callers that only want totals.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CountingProgress {
    /// `(stage name, announced length, steps reported)` in order.
    pub stages: Vec<(String, u64, u64)>,
    /// Messages in order.
    pub messages: Vec<String>,
    /// Named values in order.
    pub values: Vec<(String, f64)>,
}

impl Progress for CountingProgress {
    fn stage(&mut self, name: &str, len: u64) {
        self.stages.push((name.to_string(), len, 0));
    }
    fn inc(&mut self, n: u64) {
        if let Some(s) = self.stages.last_mut() {
            s.2 += n;
        }
    }
    fn message(&mut self, text: &str) {
        self.messages.push(text.to_string());
    }
    fn value(&mut self, name: &str, value: f64) {
        self.values.push((name.to_string(), value));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counting_progress_counts_per_stage() {
        let mut p = CountingProgress::default();
        let dynp: &mut dyn Progress = &mut p;
        dynp.stage("a", 3);
        dynp.inc(2);
        dynp.inc(1);
        dynp.stage("b", 0);
        dynp.message("hi");
        dynp.value("x", 2.5);
        dynp.finish_stage();
        assert_eq!(p.stages, vec![("a".into(), 3, 3), ("b".into(), 0, 0)]);
        assert_eq!(p.messages, vec!["hi".to_string()]);
        assert_eq!(p.values, vec![("x".to_string(), 2.5)]);
    }
}
