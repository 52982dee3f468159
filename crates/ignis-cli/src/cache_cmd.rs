//! `ignis cache`: what `ignis loop`'s cache holds, and trimming it.
//!
//! The cache (`$XDG_CACHE_HOME/ignis`, `~/.cache/ignis` or `--cache DIR`) holds one entry
//! per clip and window `ignis loop` (and `ignis bench loops`, the demo) has seen — a
//! trained database with the window's metric frames, a few MB to a few hundred each — and
//! the loop times the looping generators keep (`volume-loop-times/`, `learned-loop-times/`:
//! a few KB each, one per scene, size, length and build of `ignis`). Nothing removes them
//! by itself, so the cache only grows. This command lists the entries (what each was made
//! of, its size, when it was last used) and removes them by age, by a size budget (least
//! recently used first) or all, as the disk caches of compositing tools are trimmed.
//!
//! Only Ignis's own entries are touched: directories named `<24 hex>-<12 hex>` with an
//! `entry.json`, and the JSON files in `*-loop-times` folders. Anything else in the
//! directory is counted and left alone. An entry is removed by renaming it to a hidden
//! temporary first ([`ignis_core::tempfiles::temp_name`]), so a run reading the cache at
//! that moment sees the whole entry or none (and builds it again), and a removal cut short
//! leaves a temporary the next trim or cache build clears. "Last used" is the time of the
//! entry's last read: `ignis loop` and the generators touch an entry when they use it.

use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use anyhow::{bail, Context, Result};

use crate::global::Global;

#[derive(clap::Args, Debug)]
#[command(
    after_help = "Examples:\n  ignis cache                         # what the cache holds, least recently used first\n  \
ignis cache --max-size 5G           # remove the least recently used entries until 5 GiB are left\n  \
ignis cache --older-than 30d        # remove what has not been used for 30 days\n  \
ignis cache --max-size 2G --dry-run # say what would go, remove nothing\n  \
ignis cache --clear\n  \
ignis cache --cache /tmp/ignis-cache --json\n\n\
The cache holds `ignis loop`'s clip databases (the first run on a clip trains one: a few MB to a few hundred) and the \
loop times of looping volume and learned renders (a few KB each). A removed clip database is \
trained again the next time that clip is looped. Files in the directory that are not Ignis's are \
never removed."
)]
pub struct Args {
    /// Cache directory (default $XDG_CACHE_HOME/ignis or ~/.cache/ignis).
    #[arg(long, value_name = "DIR")]
    pub cache: Option<PathBuf>,
    /// Remove the least recently used entries until the cache holds at most this much:
    /// 500M, 5G, 1.5T (binary units, as `du -h` prints them; a plain number is bytes).
    #[arg(long, value_parser = parse_bytes, value_name = "SIZE")]
    pub max_size: Option<u64>,
    /// Remove the entries not used for this long: 12h, 30d, 2w (also s, min).
    #[arg(long, value_parser = parse_age, value_name = "AGE")]
    pub older_than: Option<Duration>,
    /// Remove every entry.
    #[arg(long, conflicts_with_all = ["max_size", "older_than"])]
    pub clear: bool,
    /// Say what would be removed; remove nothing.
    #[arg(long)]
    pub dry_run: bool,
    /// Print the listing (and what was removed) as one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// `5.5G` → `(5.5, "G")`: the leading decimal number and the unit after it (spaces
/// around either trimmed); `None` when there is no number.
fn number_and_unit(s: &str) -> Option<(f64, &str)> {
    let t = s.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    Some((num.parse().ok()?, unit.trim()))
}

/// A cache size as people write it: `500M`, `5G`, `1.5T`, `5GB`, `5GiB`, `1048576`.
/// Binary units (K = 1024), as `du -h` and `ls -h` print them.
pub fn parse_bytes(s: &str) -> std::result::Result<u64, String> {
    let bad = || {
        format!("`{s}` is not a size: write it as 500M, 5G or 1.5T (binary units, K = 1024), or a number of bytes")
    };
    let (v, unit) = number_and_unit(s).ok_or_else(bad)?;
    let shift = match unit.to_ascii_uppercase().as_str() {
        "" | "B" => 0,
        "K" | "KB" | "KIB" => 10,
        "M" | "MB" | "MIB" => 20,
        "G" | "GB" | "GIB" => 30,
        "T" | "TB" | "TIB" => 40,
        _ => return Err(bad()),
    };
    let bytes = v * (1u64 << shift) as f64;
    if !bytes.is_finite() || bytes >= u64::MAX as f64 {
        return Err(bad());
    }
    Ok(bytes.round() as u64)
}

/// An age as people write it: `12h`, `30d`, `2w`, `90min`, `45s`.
pub fn parse_age(s: &str) -> std::result::Result<Duration, String> {
    let bad = || format!("`{s}` is not an age: write it as 12h, 30d or 2w (also s, min)");
    let (v, unit) = number_and_unit(s).ok_or_else(bad)?;
    let secs = match unit.to_ascii_lowercase().as_str() {
        "s" | "sec" => 1.0,
        "m" | "min" => 60.0,
        "h" => 3600.0,
        "d" => 86_400.0,
        "w" => 7.0 * 86_400.0,
        _ => return Err(bad()),
    };
    Duration::try_from_secs_f64(v * secs).map_err(|_| bad())
}

/// What one entry is (in `--json`: `"kind": "clip"` with `source`, `frames`, `fps`,
/// `source_size`, or `"kind": "loop-times"` with `generator`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum What {
    /// A clip's database (`ignis loop`): the source as recorded (`None`: built before
    /// sources were recorded), the window of source frames, the clip's rate and size.
    Clip {
        source: Option<String>,
        #[serde(rename = "frames")]
        window: Option<(u64, u64)>,
        fps: Option<f64>,
        #[serde(rename = "source_size")]
        size: Option<String>,
    },
    /// One loop's kept frame times (`volume`, `learned`).
    LoopTimes {
        #[serde(rename = "generator")]
        kind: String,
    },
}

/// One entry of the cache.
#[derive(Clone, Debug)]
pub struct Entry {
    pub path: PathBuf,
    pub what: What,
    /// Bytes on disk (the files' lengths).
    pub bytes: u64,
    /// When it was last used (its `entry.json`'s, or the file's, modification time).
    pub used: SystemTime,
}

/// What a cache directory holds.
#[derive(Debug, Default)]
pub struct Listing {
    /// Ignis's entries, least recently used first.
    pub entries: Vec<Entry>,
    /// Names in the directory that are not Ignis's (left alone), and their bytes.
    pub other: Vec<(String, u64)>,
    /// Temporaries of runs that were killed (removed by any trim).
    pub leftovers: usize,
    /// Temporaries of runs still going (entries being built or replaced; never removed).
    pub in_progress: usize,
}

impl Listing {
    /// Counts a temporary of the run `pid`: in progress while it runs, else a leftover.
    fn count_temporary(&mut self, pid: u32) {
        if ignis_core::tempfiles::pid_alive(pid) {
            self.in_progress += 1;
        } else {
            self.leftovers += 1;
        }
    }

    /// Bytes of Ignis's entries.
    pub fn bytes(&self) -> u64 {
        self.entries.iter().map(|e| e.bytes).sum()
    }
}

/// Whether `name` is a clip entry's directory name: 24 hex digits, `-`, 12 hex digits.
fn is_clip_entry_name(name: &str) -> bool {
    let hex = |s: &str, n: usize| {
        s.len() == n
            && s.bytes()
                .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
    };
    name.split_once('-')
        .is_some_and(|(a, b)| hex(a, 24) && hex(b, 12))
}

/// Bytes of the files under `p` (symbolic links counted as themselves, never followed).
fn bytes_under(p: &Path) -> u64 {
    let Ok(m) = std::fs::symlink_metadata(p) else {
        return 0;
    };
    if !m.is_dir() {
        return m.len();
    }
    std::fs::read_dir(p)
        .map(|rd| rd.flatten().map(|e| bytes_under(&e.path())).sum())
        .unwrap_or(0)
}

/// The modification time of `p`, or the epoch when it cannot be read (such an entry
/// counts as the least recently used).
fn modified(p: &Path) -> SystemTime {
    std::fs::metadata(p)
        .and_then(|m| m.modified())
        .unwrap_or(SystemTime::UNIX_EPOCH)
}

/// What the clip entry `dir` says of itself (its `entry.json`, read at most 1 MB).
fn clip_what(dir: &Path) -> What {
    let v: serde_json::Value = ignis_core::atomic::read_at_most(&dir.join("entry.json"), 1 << 20)
        .ok()
        .flatten()
        .and_then(|b| serde_json::from_slice(&b).ok())
        .unwrap_or_default();
    let s = &v["settings"];
    What::Clip {
        source: v["source"].as_str().map(str::to_owned),
        window: s["start"].as_u64().zip(s["end"].as_u64()),
        fps: v["fps"].as_f64(),
        size: v["source_size"].as_str().map(str::to_owned),
    }
}

/// Lists the cache directory `dir` (a missing directory is an empty cache).
pub fn list(dir: &Path) -> Result<Listing> {
    let mut out = Listing::default();
    let rd = match std::fs::read_dir(dir) {
        Ok(rd) => rd,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(out),
        Err(e) => {
            if dir.exists() && !dir.is_dir() {
                bail!(
                    "{} is not a directory; give --cache the cache directory (or leave it out for $XDG_CACHE_HOME/ignis or ~/.cache/ignis)",
                    dir.display()
                );
            }
            return Err(e)
                .with_context(|| format!("reading the cache directory {}", dir.display()));
        }
    };
    let mut names: Vec<(String, PathBuf)> = rd
        .flatten()
        .map(|e| (e.file_name().to_string_lossy().into_owned(), e.path()))
        .collect();
    names.sort();
    for (name, path) in names {
        let is_dir = std::fs::symlink_metadata(&path).is_ok_and(|m| m.is_dir());
        if let Some(pid) = ignis_core::tempfiles::owner(&name) {
            out.count_temporary(pid);
        } else if is_dir && is_clip_entry_name(&name) && path.join("entry.json").is_file() {
            out.entries.push(Entry {
                what: clip_what(&path),
                bytes: bytes_under(&path),
                used: modified(&path.join("entry.json")),
                path,
            });
        } else if let Some(kind) = name.strip_suffix("-loop-times").filter(|_| is_dir) {
            let mut files: Vec<PathBuf> = std::fs::read_dir(&path)
                .with_context(|| format!("reading {}", path.display()))?
                .flatten()
                .map(|e| e.path())
                .collect();
            files.sort();
            for f in files {
                let n = f.file_name().map(|n| n.to_string_lossy().into_owned());
                let Some(n) = n else { continue };
                if let Some(pid) = ignis_core::tempfiles::owner(&n) {
                    out.count_temporary(pid);
                } else if n.ends_with(".json") && f.is_file() {
                    out.entries.push(Entry {
                        what: What::LoopTimes {
                            kind: kind.to_string(),
                        },
                        bytes: bytes_under(&f),
                        used: modified(&f),
                        path: f,
                    });
                } else {
                    out.other.push((format!("{name}/{n}"), bytes_under(&f)));
                }
            }
        } else {
            out.other.push((name, bytes_under(&path)));
        }
    }
    out.entries
        .sort_by(|a, b| a.used.cmp(&b.used).then_with(|| a.path.cmp(&b.path)));
    Ok(out)
}

/// Which entries of `l` (indices, least recently used first) a trim removes: those unused
/// for longer than `older_than` at `now`, then the least recently used until at most
/// `max_size` bytes are left; with `clear`, all.
pub fn to_remove(
    l: &Listing,
    now: SystemTime,
    older_than: Option<Duration>,
    max_size: Option<u64>,
    clear: bool,
) -> Vec<usize> {
    if clear {
        return (0..l.entries.len()).collect();
    }
    let mut gone = vec![false; l.entries.len()];
    if let Some(age) = older_than {
        for (i, e) in l.entries.iter().enumerate() {
            if now.duration_since(e.used).unwrap_or_default() > age {
                gone[i] = true;
            }
        }
    }
    if let Some(max) = max_size {
        let mut left: u64 = l
            .entries
            .iter()
            .zip(&gone)
            .filter(|(_, g)| !**g)
            .map(|(e, _)| e.bytes)
            .sum();
        for (i, e) in l.entries.iter().enumerate() {
            if left <= max {
                break;
            }
            if !gone[i] {
                gone[i] = true;
                left -= e.bytes;
            }
        }
    }
    (0..l.entries.len()).filter(|&i| gone[i]).collect()
}

/// Removes one entry: renamed to a hidden temporary beside it first (a reader then sees it
/// whole or not at all), then deleted.
fn remove_entry(e: &Entry) -> Result<()> {
    let parent = e.path.parent().context("a cache entry has a directory")?;
    let name = e
        .path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = parent.join(ignis_core::tempfiles::temp_name(&name, "removing"));
    match std::fs::rename(&e.path, &tmp) {
        Ok(()) => {}
        // gone already (another trim, or a run that found it damaged)
        Err(err) if err.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(err) => {
            return Err(err).with_context(|| format!("removing {}", e.path.display()));
        }
    }
    let r = if std::fs::symlink_metadata(&tmp).is_ok_and(|m| m.is_dir()) {
        std::fs::remove_dir_all(&tmp)
    } else {
        std::fs::remove_file(&tmp)
    };
    r.with_context(|| format!("removing {} (now {})", e.path.display(), tmp.display()))
}

/// `1.5 GiB`, `340 KiB`, `12 B`.
pub fn bytes_text(b: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = b as f64;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < UNITS.len() {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{b} B")
    } else if v < 10.0 {
        format!("{v:.1} {}", UNITS[u])
    } else {
        format!("{v:.0} {}", UNITS[u])
    }
}

/// How long ago `t` was, as people say it: `just now`, `5 min ago`, `3 h ago`, `12 days ago`.
fn ago(now: SystemTime, t: SystemTime) -> String {
    if t == SystemTime::UNIX_EPOCH {
        return "unknown".into();
    }
    let s = now.duration_since(t).unwrap_or_default().as_secs();
    match s {
        0..60 => "just now".into(),
        60..3600 => format!("{} min ago", s / 60),
        3600..86_400 => format!("{} h ago", s / 3600),
        _ => format!("{} days ago", s / 86_400),
    }
}

/// One line about an entry.
fn describe(e: &Entry) -> String {
    match &e.what {
        What::Clip {
            source,
            window,
            fps,
            size,
        } => {
            let mut s = format!(
                "clip database: {}",
                source
                    .as_deref()
                    .unwrap_or("(source not recorded: made by an older ignis)")
            );
            if let Some((a, b)) = window {
                s.push_str(&format!(", frames {a}..{b}"));
            }
            if let Some(f) = fps {
                s.push_str(&format!(" at {}", crate::args::fps_text(*f)));
                s.push_str(" fps");
            }
            if let Some(z) = size {
                s.push_str(&format!(", {z}"));
            }
            s
        }
        What::LoopTimes { kind } => format!("{kind} loop times"),
    }
}

fn entry_json(e: &Entry, removed: bool) -> serde_json::Value {
    let unix = e
        .used
        .duration_since(SystemTime::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .ok()
        .filter(|&s| s > 0);
    let mut v = serde_json::to_value(&e.what).unwrap_or_default();
    v["path"] = e.path.display().to_string().into();
    v["bytes"] = e.bytes.into();
    v["last_used_unix"] = unix.into();
    v["removed"] = removed.into();
    v
}

pub fn run(a: &Args, g: &Global) -> Result<()> {
    let dir = match &a.cache {
        Some(d) => d.clone(),
        None => crate::eigen::loop_cmd::default_cache_dir()?,
    };
    let listing = list(&dir)?;
    let now = SystemTime::now();
    let trimming = a.clear || a.max_size.is_some() || a.older_than.is_some();
    let gone = if trimming {
        to_remove(&listing, now, a.older_than, a.max_size, a.clear)
    } else {
        Vec::new()
    };
    let mut removed = vec![false; listing.entries.len()];
    let mut freed = 0u64;
    let mut leftovers_removed = 0;
    if trimming && !a.dry_run {
        leftovers_removed = ignis_core::tempfiles::remove_stale(&dir);
        for sub in listing
            .entries
            .iter()
            .filter_map(|e| e.path.parent())
            .filter(|p| *p != dir)
            .collect::<std::collections::BTreeSet<_>>()
        {
            leftovers_removed += ignis_core::tempfiles::remove_stale(sub);
        }
        for &i in &gone {
            remove_entry(&listing.entries[i])?;
            removed[i] = true;
            freed += listing.entries[i].bytes;
        }
        // a loop-times folder left empty goes too (remove_dir removes only an empty one)
        for e in &listing.entries {
            if let (What::LoopTimes { .. }, Some(p)) = (&e.what, e.path.parent()) {
                let _ = std::fs::remove_dir(p);
            }
        }
    } else {
        freed = gone.iter().map(|&i| listing.entries[i].bytes).sum();
    }
    let total = listing.bytes();
    if a.json {
        let entries: Vec<serde_json::Value> = listing
            .entries
            .iter()
            .enumerate()
            .map(|(i, e)| entry_json(e, removed[i]))
            .collect();
        let v = serde_json::json!({
            "cache": dir.display().to_string(),
            "bytes": total,
            "bytes_left": if a.dry_run { total } else { total - freed },
            "entries": entries,
            "other": listing.other.iter().map(|(n, b)| serde_json::json!({"name": n, "bytes": b})).collect::<Vec<_>>(),
            "dry_run": a.dry_run,
            "would_remove": if a.dry_run { gone.len() } else { 0 },
            "removed": removed.iter().filter(|r| **r).count(),
            "freed_bytes": if a.dry_run { 0 } else { freed },
            "leftovers_removed": leftovers_removed,
        });
        outln!("{}", serde_json::to_string_pretty(&v)?)?;
        return Ok(());
    }
    if listing.entries.is_empty() {
        outln!(
            "cache: {} holds no entries{}",
            dir.display(),
            if dir.exists() {
                ""
            } else {
                " (it does not exist yet)"
            }
        )?;
    } else {
        let n = listing.entries.len();
        outln!(
            "cache: {} ({} in {n} entr{}; least recently used first)",
            dir.display(),
            bytes_text(total),
            if n == 1 { "y" } else { "ies" }
        )?;
        // Loop-times files are many and tiny: one line per kind and state.
        let mut times: Vec<(String, bool, usize, u64, SystemTime)> = Vec::new();
        for (i, e) in listing.entries.iter().enumerate() {
            let mark = gone.contains(&i);
            if let What::LoopTimes { kind } = &e.what {
                match times.iter_mut().find(|t| t.0 == *kind && t.1 == mark) {
                    Some(t) => {
                        t.2 += 1;
                        t.3 += e.bytes;
                        t.4 = t.4.max(e.used);
                    }
                    None => times.push((kind.clone(), mark, 1, e.bytes, e.used)),
                }
                continue;
            }
            outln!(
                "  {:<14} {:>9}  {}{}",
                ago(now, e.used),
                bytes_text(e.bytes),
                describe(e),
                state(mark, a.dry_run)
            )?;
        }
        for (kind, mark, n, bytes, used) in times {
            outln!(
                "  {:<14} {:>9}  {kind} loop times: {n} file(s), last used {}{}",
                "",
                bytes_text(bytes),
                ago(now, used),
                state(mark, a.dry_run)
            )?;
        }
    }
    if !listing.other.is_empty() {
        let b: u64 = listing.other.iter().map(|o| o.1).sum();
        outln!(
            "  not Ignis's, left alone: {} ({})",
            listing
                .other
                .iter()
                .map(|o| o.0.as_str())
                .take(5)
                .collect::<Vec<_>>()
                .join(", ")
                + if listing.other.len() > 5 { ", …" } else { "" },
            bytes_text(b)
        )?;
    }
    if trimming {
        let n = gone.len();
        if a.dry_run {
            outln!(
                "would remove {n} entr{} ({}), leaving {}; run it again without --dry-run to remove them",
                if n == 1 { "y" } else { "ies" },
                bytes_text(freed),
                bytes_text(total - freed)
            )?;
        } else {
            outln!(
                "removed {n} entr{} ({}), {} left{}",
                if n == 1 { "y" } else { "ies" },
                bytes_text(freed),
                bytes_text(total - freed),
                if leftovers_removed > 0 {
                    format!("; and {leftovers_removed} leftover(s) of killed runs")
                } else {
                    String::new()
                }
            )?;
        }
    }
    if listing.in_progress > 0 {
        g.say(format!(
            "{} entr{} being written by a running ignis (left alone)",
            listing.in_progress,
            if listing.in_progress == 1 { "y" } else { "ies" }
        ));
    }
    if !trimming && listing.leftovers > 0 {
        g.say(format!(
            "{} leftover(s) of killed runs; any trim (e.g. --older-than 30d) removes them",
            listing.leftovers
        ));
    }
    Ok(())
}

fn state(marked: bool, dry_run: bool) -> &'static str {
    match (marked, dry_run) {
        (false, _) => "",
        (true, true) => "  [would remove]",
        (true, false) => "  [removed]",
    }
}

/// Marks a cache entry (its `entry.json`, or a loop-times file) as used now, so a trim by
/// age or size keeps it over those used longer ago. A failure (a read-only cache) is
/// ignored: the entry only looks older.
pub fn touch(path: &Path) {
    if let Ok(f) = std::fs::File::options().write(true).open(path) {
        let _ = f.set_modified(SystemTime::now());
    }
}

/// Above this many bytes of Ignis's entries, a run that adds an entry says how to trim.
pub const NOTE_BYTES: u64 = 10 << 30;

/// After an entry was added to `dir`: a note when Ignis's entries there add up to more
/// than [`NOTE_BYTES`], naming the command that trims them.
pub fn note_if_large(dir: &Path, g: &Global) {
    let Ok(l) = list(dir) else { return };
    let b = l.bytes();
    if b > NOTE_BYTES {
        g.say(format!(
            "note: the cache {} holds {} in {} entries; `ignis cache --max-size 5G` removes the least recently used (`ignis cache` lists them)",
            dir.display(),
            bytes_text(b),
            l.entries.len()
        ));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_and_ages_as_people_write_them() {
        assert_eq!(parse_bytes("500M"), Ok(500 << 20));
        assert_eq!(parse_bytes("5G"), Ok(5 << 30));
        assert_eq!(parse_bytes("5GB"), Ok(5 << 30));
        assert_eq!(parse_bytes("5 GiB"), Ok(5 << 30));
        assert_eq!(parse_bytes("1.5T"), Ok(3 << 39));
        assert_eq!(parse_bytes("1048576"), Ok(1 << 20));
        assert_eq!(parse_bytes("0"), Ok(0));
        for bad in ["", "G", "5Q", "-1G", "1e99T", "5.5.5M", "NaN"] {
            let e = parse_bytes(bad).unwrap_err();
            assert!(e.contains("500M, 5G or 1.5T"), "{bad}: {e}");
        }
        assert_eq!(parse_age("30d"), Ok(Duration::from_secs(30 * 86_400)));
        assert_eq!(parse_age("12h"), Ok(Duration::from_secs(12 * 3600)));
        assert_eq!(parse_age("2w"), Ok(Duration::from_secs(14 * 86_400)));
        assert_eq!(parse_age("90min"), Ok(Duration::from_secs(5400)));
        assert_eq!(parse_age("1.5h"), Ok(Duration::from_secs(5400)));
        for bad in ["", "30", "d", "30y", "-1d", "1e300w"] {
            let e = parse_age(bad).unwrap_err();
            assert!(e.contains("12h, 30d or 2w"), "{bad}: {e}");
        }
        assert_eq!(bytes_text(12), "12 B");
        assert_eq!(bytes_text(1536), "1.5 KiB");
        assert_eq!(bytes_text(200 << 20), "200 MiB");
    }

    fn entry(path: &str, bytes: u64, used_s: u64) -> Entry {
        Entry {
            path: PathBuf::from(path),
            what: What::LoopTimes { kind: "t".into() },
            bytes,
            used: SystemTime::UNIX_EPOCH + Duration::from_secs(used_s),
        }
    }

    #[test]
    fn trims_take_the_least_recently_used_first() {
        let l = Listing {
            entries: vec![
                entry("a", 100, 1_000),
                entry("b", 50, 2_000),
                entry("c", 10, 3_000),
                entry("d", 40, 4_000),
            ],
            ..Listing::default()
        };
        let now = SystemTime::UNIX_EPOCH + Duration::from_secs(5_000);
        assert_eq!(to_remove(&l, now, None, None, false), Vec::<usize>::new());
        assert_eq!(to_remove(&l, now, None, None, true), vec![0, 1, 2, 3]);
        // 200 bytes: down to at most 100 takes a (100); 60 takes a and b
        assert_eq!(to_remove(&l, now, None, Some(100), false), vec![0]);
        assert_eq!(to_remove(&l, now, None, Some(60), false), vec![0, 1]);
        assert_eq!(
            to_remove(&l, now, None, Some(200), false),
            Vec::<usize>::new()
        );
        assert_eq!(to_remove(&l, now, None, Some(0), false), vec![0, 1, 2, 3]);
        let age = Some(Duration::from_secs(2_500));
        assert_eq!(to_remove(&l, now, age, None, false), vec![0, 1]);
        // by age first (a, b), then by size from what is left (c before d)
        assert_eq!(to_remove(&l, now, age, Some(40), false), vec![0, 1, 2]);
    }

    #[test]
    fn only_ignis_entries_are_listed_and_removed() {
        let t = tempfile::tempdir().unwrap();
        let d = t.path();
        let clip = d.join("0123456789abcdef01234567-0123456789ab");
        std::fs::create_dir_all(clip.join("fire.db")).unwrap();
        std::fs::write(
            clip.join("entry.json"),
            r#"{"source":"/footage/fire.mp4","settings":{"start":0,"end":90},"fps":24.0,"source_size":"640x360"}"#,
        )
        .unwrap();
        std::fs::write(clip.join("metric.f32"), vec![0u8; 4000]).unwrap();
        std::fs::write(clip.join("fire.db").join("x"), vec![0u8; 1000]).unwrap();
        std::fs::create_dir(d.join("volume-loop-times")).unwrap();
        std::fs::write(d.join("volume-loop-times").join("ab.json"), b"{}").unwrap();
        std::fs::write(d.join("volume-loop-times").join("notes.txt"), b"mine").unwrap();
        std::fs::write(d.join("my-notes.txt"), b"keep me").unwrap();
        // named like an entry, but no entry.json: not Ignis's
        std::fs::create_dir(d.join("0123456789abcdef01234567-ffffffffffff")).unwrap();
        // temporaries: of a run that has exited, and of this (running) one
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let dead = child.id();
        child.wait().unwrap();
        std::fs::create_dir(d.join(format!(".e.ignis-tmp-{dead}.0.dir"))).unwrap();
        let live = ignis_core::tempfiles::temp_name("f", "0.dir");
        std::fs::create_dir(d.join(&live)).unwrap();
        let l = list(d).unwrap();
        assert_eq!((l.leftovers, l.in_progress), (1, 1), "{l:?}");
        assert_eq!(ignis_core::tempfiles::remove_stale(d), 1);
        assert!(d.join(&live).is_dir());
        std::fs::remove_dir(d.join(&live)).unwrap();
        let l = list(d).unwrap();
        assert_eq!(l.entries.len(), 2, "{l:?}");
        let c = l.entries.iter().find(|e| e.path == clip).unwrap();
        let json_len = std::fs::metadata(clip.join("entry.json")).unwrap().len();
        assert_eq!(c.bytes, 5000 + json_len);
        assert_eq!(
            c.what,
            What::Clip {
                source: Some("/footage/fire.mp4".into()),
                window: Some((0, 90)),
                fps: Some(24.0),
                size: Some("640x360".into()),
            }
        );
        assert!(describe(c).contains("/footage/fire.mp4, frames 0..90 at 24 fps, 640x360"));
        let mut other: Vec<&str> = l.other.iter().map(|o| o.0.as_str()).collect();
        other.sort();
        assert_eq!(
            other,
            [
                "0123456789abcdef01234567-ffffffffffff",
                "my-notes.txt",
                "volume-loop-times/notes.txt"
            ]
        );
        for e in &l.entries {
            remove_entry(e).unwrap();
        }
        // removing what is already gone is not an error
        remove_entry(&l.entries[0]).unwrap();
        let after = list(d).unwrap();
        assert!(after.entries.is_empty());
        assert_eq!(after.other.len(), 3);
        assert_eq!((after.leftovers, after.in_progress), (0, 0));
        assert!(d.join("my-notes.txt").is_file());
        // a missing cache is empty; a file given as the cache is refused
        assert!(list(&d.join("nothing")).unwrap().entries.is_empty());
        let e = list(&d.join("my-notes.txt")).unwrap_err();
        assert!(format!("{e:#}").contains("is not a directory"), "{e:#}");
    }
}
