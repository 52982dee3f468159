//! Kept loop times: a looping generator times its frames on a preview of the whole loop
//! (volume: a 64-px render at two samples per frame; learned: previews, a walk and an
//! even-out), which every `--chunk` of a farm render would otherwise pay for the whole
//! loop. The first render keeps the times in a small JSON file (each `f64` stored exactly,
//! as its bits) under `--cache DIR` or `ignis loop`'s cache, keyed by everything they
//! depend on and by this build of `ignis`; a later render with the same key reads them and
//! writes the same bytes. The cache only saves time: a missing, unreadable or foreign entry
//! is timed anew, and one that cannot be written costs a note, never an error.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

use crate::global::Global;

/// Version of the entries' format.
const VERSION: u32 = 1;

/// One loop's entry (it may not exist yet).
pub struct KeptTimes {
    /// `None` when this build cannot be identified or there is no cache directory: nothing
    /// is read or kept.
    path: Option<PathBuf>,
    what: &'static str,
}

impl KeptTimes {
    /// The entry of a `kind` of loop (`volume`, `learned`; its folder is
    /// `{kind}-loop-times`) whose times depend on `key` (every input, as text) under `dir`,
    /// else `ignis loop`'s cache. `what`: what the times are, written into the entry.
    pub fn new(dir: Option<&Path>, kind: &str, key: &str, what: &'static str) -> KeptTimes {
        let dir = match dir {
            Some(d) => Some(d.to_path_buf()),
            None => crate::eigen::loop_cmd::default_cache_dir().ok(),
        };
        let path = dir.zip(digest(key)).map(|(d, k)| {
            d.join(format!("{kind}-loop-times"))
                .join(format!("{k}.json"))
        });
        KeptTimes { path, what }
    }

    /// The kept times of a loop of `n` frames, or `None` (no entry, not such a list, or a
    /// file larger than such a list's entry: nothing unbounded is read).
    pub fn read(&self, n: usize) -> Option<Vec<f64>> {
        let bytes = ignis_core::atomic::read_at_most(self.path.as_ref()?, entry_bytes_at_most(n))
            .ok()??;
        let v: serde_json::Value = serde_json::from_slice(&bytes).ok()?;
        if v["version"] != VERSION || v["frames"] != n {
            return None;
        }
        let bits = v["times_f64_bits"].as_array()?;
        if bits.len() != n {
            return None;
        }
        let times = bits
            .iter()
            .map(|b| Some(f64::from_bits(u64::from_str_radix(b.as_str()?, 16).ok()?)))
            .collect::<Option<Vec<f64>>>()?;
        // used now: `ignis cache` trims the least recently used first
        crate::cache_cmd::touch(self.path.as_ref()?);
        Some(times)
    }

    /// Keeps `times` (atomically); a failure is said, not returned.
    pub fn keep(&self, times: &[f64], g: &Global) {
        let Some(path) = &self.path else { return };
        if let Err(e) = write(path, self.what, times) {
            g.say(format!(
                "note: the loop's frame times were not kept ({e:#}); the next render of it times them again"
            ));
        }
    }
}

/// `key` and this build of `ignis` (its version, and its executable's size and time:
/// another build may time differently), hashed; `None` when the executable cannot be
/// identified.
fn digest(key: &str) -> Option<String> {
    use sha2::{Digest, Sha256};
    let exe = std::fs::metadata(std::env::current_exe().ok()?).ok()?;
    let built = exe
        .modified()
        .ok()?
        .duration_since(std::time::UNIX_EPOCH)
        .ok()?;
    let all = format!(
        "ignis {} {} {} v{VERSION} {key}",
        env!("CARGO_PKG_VERSION"),
        exe.len(),
        built.as_nanos()
    );
    let d = Sha256::digest(all.as_bytes());
    Some(d[..16].iter().map(|b| format!("{b:02x}")).collect())
}

/// The largest entry [`write`] makes for `n` times: each time as JSON (at most 24
/// characters) and as 16 hex digits (18 with the quotes), with separators, under 64 bytes,
/// and the header under 4 KB.
fn entry_bytes_at_most(n: usize) -> u64 {
    (n as u64).saturating_mul(64).saturating_add(4096)
}

fn write(path: &Path, what: &str, times: &[f64]) -> Result<()> {
    let dir = path.parent().context("a cache file has a directory")?;
    crate::eigen::loop_cmd::create_cache_dir(dir)?;
    let bits: Vec<String> = times
        .iter()
        .map(|t| format!("{:016x}", t.to_bits()))
        .collect();
    let v = serde_json::json!({
        "what": what,
        "version": VERSION,
        "frames": times.len(),
        "times": times,
        "times_f64_bits": bits,
    });
    ignis_core::atomic::write_bytes(path, serde_json::to_string(&v)?.as_bytes())
        .with_context(|| format!("writing {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kept_times_read_back_exactly_and_only_for_their_key_and_length() {
        let t = tempfile::tempdir().unwrap();
        let g = Global { quiet: true };
        let times = [0.0, 0.1 + 0.2, std::f64::consts::PI, 1e-300];
        let k = KeptTimes::new(Some(t.path()), "test", "scene A", "test times");
        assert_eq!(k.read(4), None);
        k.keep(&times, &g);
        let back = k.read(4).unwrap();
        assert!(back
            .iter()
            .zip(&times)
            .all(|(a, b)| a.to_bits() == b.to_bits()));
        assert_eq!(k.read(5), None);
        assert_eq!(
            KeptTimes::new(Some(t.path()), "test", "scene B", "").read(4),
            None
        );
        assert_eq!(
            KeptTimes::new(Some(t.path()), "other", "scene A", "").read(4),
            None
        );
        // The largest times write at most the bound.
        let wide = [
            -f64::MIN_POSITIVE * 3.0,
            -1.234_567_890_123_456_7e-300,
            f64::MAX,
        ];
        let w = KeptTimes::new(Some(t.path()), "test", "wide", "test times");
        w.keep(&wide, &g);
        let len = std::fs::metadata(w.path.as_ref().unwrap()).unwrap().len();
        assert!(len <= entry_bytes_at_most(3), "{len} bytes");
        assert!(w.read(3).is_some());
        // A valid entry padded past the bound is not read (nothing unbounded is).
        let path = k.path.as_ref().unwrap();
        let mut padded = std::fs::read(path).unwrap();
        padded.resize(entry_bytes_at_most(4) as usize + 1, b' ');
        std::fs::write(path, &padded).unwrap();
        assert!(serde_json::from_slice::<serde_json::Value>(&padded).is_ok());
        assert_eq!(k.read(4), None);
        padded.truncate(entry_bytes_at_most(4) as usize);
        std::fs::write(path, &padded).unwrap();
        assert!(k.read(4).is_some());
    }
}
