//! Structure-aware fuzzing of every Ignis reader (issue 18).
//!
//! Each [`Target`] has valid seed inputs (written by Ignis itself) and a reader to run on
//! mutated copies of them. The [`Mutator`] (fixed seed, [`ignis_core::Rng`]) flips bytes,
//! truncates, inserts and duplicates, and edits fields as text: numbers become 0, −1, huge,
//! NaN or infinite; strings become `..` paths, absolute paths or empty; values swap types.
//!
//! Every case runs on its own thread under a deadline ([`run_case`]): a panic is caught
//! and reported, a case still running after the deadline is reported as a hang, and the
//! process's global allocator ([`CappedAlloc`], installed by the test and the `ignis-fuzz`
//! binary) refuses any single allocation above [`ALLOC_CAP`] (the process aborts: an
//! unbounded allocation cannot pass). Targets whose input is covered by a checksum also
//! report a finding when a changed input is accepted.
//!
//! `cargo test -p ignis-fuzz` runs [`CI_CASES`] cases per target; `cargo run --release -p
//! ignis-fuzz -- --minutes 10` runs until the time is up (before a release).

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use ignis_core::Rng;

/// Cases per target in `cargo test`.
pub const CI_CASES: usize = 300;
/// Largest single allocation allowed while fuzzing (1 GiB).
pub const ALLOC_CAP: usize = 1 << 30;
/// Deadline of one case.
pub const CASE_TIMEOUT: Duration = Duration::from_secs(10);

/// A global allocator that refuses any single allocation over [`ALLOC_CAP`] (returns null,
/// which aborts the process with "memory allocation failed"): install it with
/// `#[global_allocator] static A: CappedAlloc = CappedAlloc;`.
pub struct CappedAlloc;

// SAFETY: forwards to the system allocator; refusing (null) is allowed by the contract.
unsafe impl GlobalAlloc for CappedAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if layout.size() > ALLOC_CAP {
            return std::ptr::null_mut();
        }
        // SAFETY: same layout contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from `System.alloc` with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if layout.size() > ALLOC_CAP {
            return std::ptr::null_mut();
        }
        // SAFETY: as above.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if new_size > ALLOC_CAP {
            return std::ptr::null_mut();
        }
        // SAFETY: as above.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

/// Fixed-seed mutations of bytes and of text fields.
pub struct Mutator {
    rng: Rng,
}

const NUMBERS: &[&str] = &[
    "0",
    "-1",
    "1e30",
    "-1e30",
    "1e308",
    "18446744073709551615",
    "4294967296",
    "1000000000",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "0.0",
    "1e-30",
    "65536",
    "3",
];
const STRINGS: &[&str] = &[
    "\"../../etc/passwd\"",
    "\"/etc/shadow\"",
    "\"..\"",
    "\"\"",
    "\"packs/../../x.npy\"",
    "\"/dev/zero\"",
    "\"http://127.0.0.1:1/x.mp4\"",
    "\"-report.mp4\"",
    "\"%65536d.png\"",
    "\"a\"",
];
const VALUES: &[&str] = &[
    "[]",
    "{}",
    "true",
    "null",
    "\"x\"",
    "[1, 2]",
    "{\"a\": 1}",
    "-1",
];

impl Mutator {
    pub fn new(seed: u64) -> Mutator {
        Mutator {
            rng: Rng::new(seed),
        }
    }

    fn pick<'a>(&mut self, v: &[&'a str]) -> &'a str {
        v[self.rng.below(v.len() as u32) as usize]
    }

    /// One to three mutations of `input`.
    pub fn mutate(&mut self, input: &[u8]) -> Vec<u8> {
        let mut out = input.to_vec();
        // Mostly one mutation, so more inputs get past the parser to the checks behind it.
        let n = [1, 1, 1, 2, 3][self.rng.below(5) as usize];
        for _ in 0..n {
            out = self.once(&out);
        }
        out
    }

    fn once(&mut self, b: &[u8]) -> Vec<u8> {
        let mut out = b.to_vec();
        let len = out.len().max(1) as u32;
        // Field edits (numbers, strings, types) twice as often as raw byte changes.
        match [0, 1, 2, 3, 4, 4, 4, 5, 5, 6, 7][self.rng.below(11) as usize] {
            0 if !out.is_empty() => {
                let i = self.rng.below(len) as usize % out.len();
                out[i] ^= 1 << self.rng.below(8);
            }
            1 => {
                out.truncate(self.rng.below(len) as usize);
            }
            2 if !out.is_empty() => {
                let i = self.rng.below(len) as usize % out.len();
                out[i] = self.rng.below(256) as u8;
            }
            3 => {
                let i = self.rng.below(len + 1) as usize % (out.len() + 1);
                let k = 1 + self.rng.below(16) as usize;
                let ins: Vec<u8> = (0..k).map(|_| self.rng.below(256) as u8).collect();
                out.splice(i..i, ins);
            }
            4 => return self.edit_number(b),
            5 => return self.edit_string(b),
            6 => return self.swap_value(b),
            _ => {
                // duplicate a slice (repeated keys, long arrays)
                if !out.is_empty() {
                    let a = self.rng.below(len) as usize % out.len();
                    let e = (a + 1 + self.rng.below(64) as usize).min(out.len());
                    let piece = out[a..e].to_vec();
                    out.splice(a..a, piece);
                }
            }
        }
        out
    }

    /// Spans `[start, end)` of `text` matching `pred` runs.
    fn spans(
        text: &[u8],
        is_start: impl Fn(u8) -> bool,
        is_cont: impl Fn(u8) -> bool,
    ) -> Vec<(usize, usize)> {
        let mut v = Vec::new();
        let mut i = 0;
        while i < text.len() {
            if is_start(text[i]) && (i == 0 || !is_cont(text[i - 1])) {
                let s = i;
                i += 1;
                while i < text.len() && is_cont(text[i]) {
                    i += 1;
                }
                v.push((s, i));
            } else {
                i += 1;
            }
        }
        v
    }

    fn replace(&mut self, b: &[u8], spans: &[(usize, usize)], with: &str) -> Vec<u8> {
        if spans.is_empty() {
            return b.to_vec();
        }
        let (s, e) = spans[self.rng.below(spans.len() as u32) as usize];
        let mut out = b[..s].to_vec();
        out.extend_from_slice(with.as_bytes());
        out.extend_from_slice(&b[e..]);
        out
    }

    /// A number in the text becomes 0, −1, huge, NaN, …
    pub fn edit_number(&mut self, b: &[u8]) -> Vec<u8> {
        let spans = Self::spans(
            b,
            |c| c.is_ascii_digit() || c == b'-',
            |c| c.is_ascii_digit() || b".eE+-".contains(&c),
        );
        let with = self.pick(NUMBERS);
        self.replace(b, &spans, with)
    }

    /// A quoted string becomes a `..` path, an absolute path, empty, …
    pub fn edit_string(&mut self, b: &[u8]) -> Vec<u8> {
        let mut spans = Vec::new();
        let mut open = None;
        for (i, &c) in b.iter().enumerate() {
            if c == b'"' && (i == 0 || b[i - 1] != b'\\') {
                match open.take() {
                    None => open = Some(i),
                    Some(s) => spans.push((s, i + 1)),
                }
            }
        }
        let with = self.pick(STRINGS);
        self.replace(b, &spans, with)
    }

    /// A number or string becomes a value of another type.
    pub fn swap_value(&mut self, b: &[u8]) -> Vec<u8> {
        let mut out = if self.rng.below(2) == 0 {
            self.edit_number(b)
        } else {
            self.edit_string(b)
        };
        // Then put another type where the replacement went (approximate: at a random
        // value position found again).
        let spans = Self::spans(
            &out,
            |c| c == b'"' || c.is_ascii_digit(),
            |c| c.is_ascii_alphanumeric() || c == b'.',
        );
        let with = self.pick(VALUES);
        out = self.replace(&out, &spans, with);
        out
    }
}

/// What a reader did with one input.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// Accepted.
    Ok,
    /// Refused with this error.
    Err(String),
}

/// A problem found.
#[derive(Debug, Clone)]
pub struct Finding {
    pub target: &'static str,
    pub case: usize,
    pub kind: &'static str,
    pub detail: String,
    /// The input, for reproduction.
    pub input: Vec<u8>,
}

/// One reader under test.
pub trait Target: Send + Sync {
    fn name(&self) -> &'static str;
    /// Valid inputs to mutate.
    fn seeds(&self) -> &[Vec<u8>];
    /// Runs the reader on `input` (and uses what it returns, to reach later panics).
    fn run(&self, input: &[u8], scratch: &Path) -> Outcome;
    /// Whether a changed input must be refused (the input is covered by a checksum).
    fn checksummed(&self) -> bool {
        false
    }
}

/// Runs `f` on a fresh thread with a deadline: `Ok(outcome)`, or `Err((kind, detail))`
/// for a panic or a hang (the hung thread is left running; the caller reports it).
pub fn run_case<F>(f: F, timeout: Duration) -> Result<Outcome, (&'static str, String)>
where
    F: FnOnce() -> Outcome + Send + 'static,
{
    let (tx, rx) = mpsc::channel();
    std::thread::Builder::new()
        .name("fuzz-case".into())
        .spawn(move || {
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
            let _ = tx.send(r);
        })
        .map_err(|e| ("spawn", e.to_string()))?;
    match rx.recv_timeout(timeout) {
        Ok(Ok(o)) => Ok(o),
        Ok(Err(p)) => {
            let msg = p
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "(non-string panic)".into());
            Err(("panic", msg))
        }
        Err(_) => Err(("hang", format!("still running after {timeout:?}"))),
    }
}

/// Counts of one target's run.
#[derive(Debug, Default, Clone)]
pub struct Stats {
    pub cases: usize,
    pub accepted: usize,
    pub refused: usize,
    pub findings: Vec<Finding>,
}

/// Runs `cases` mutated inputs of `target` (or until `until`), seed `seed`.
pub fn fuzz(
    target: &std::sync::Arc<dyn Target>,
    seed: u64,
    cases: usize,
    until: Option<Instant>,
) -> Stats {
    let mut m = Mutator::new(seed);
    let mut st = Stats::default();
    let scratch_root = tempfile::tempdir().expect("temporary directory");
    let seeds = target.seeds().len();
    for case in 0..cases {
        if until.is_some_and(|u| Instant::now() >= u) {
            break;
        }
        let orig = &target.seeds()[case % seeds];
        let input = m.mutate(orig);
        let changed = &input != orig;
        let scratch = scratch_root.path().join(format!("c{case}"));
        let t = target.clone();
        let inp = input.clone();
        let sc = scratch.clone();
        let r = run_case(
            move || {
                let _ = std::fs::create_dir_all(&sc);
                t.run(&inp, &sc)
            },
            CASE_TIMEOUT,
        );
        st.cases += 1;
        let mut finding = |kind: &'static str, detail: String| {
            st.findings.push(Finding {
                target: target.name(),
                case,
                kind,
                detail,
                input: input.clone(),
            })
        };
        match r {
            Ok(Outcome::Ok) => {
                st.accepted += 1;
                if changed && target.checksummed() {
                    finding("accepted", "a changed input passed the checksum".into());
                }
            }
            Ok(Outcome::Err(_)) => st.refused += 1,
            Err((kind, detail)) => finding(kind, detail),
        }
        let _ = std::fs::remove_dir_all(&scratch);
    }
    st
}

/// A per-target sub-seed, so targets do not share mutation streams.
pub fn target_seed(seed: u64, name: &str) -> u64 {
    name.bytes().fold(seed ^ 0x9e37_79b9_7f4a_7c15, |h, b| {
        h.rotate_left(5) ^ b as u64
    })
}

pub mod targets;

/// Writes `bytes` to `dir/name` and returns the path.
pub fn put(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    if let Some(d) = p.parent() {
        let _ = std::fs::create_dir_all(d);
    }
    std::fs::write(&p, bytes).expect("write fuzz input");
    p
}
