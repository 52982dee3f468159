//! Names of the hidden temporary files and directories every Ignis writer creates beside
//! its output, and the clean-up of those left behind by a killed run (issue 18, defect 14).
//!
//! A temporary name is `.<target>.ignis-tmp-<pid>.<tag>`: hidden, next to the target (so
//! the final rename stays on one file system), and carrying the owner's process id. A later
//! run that writes into the same directory calls [`remove_stale`], which deletes every such
//! entry whose owner is no longer running (checked with `kill(pid, 0)`), and nothing else.
//!
//! This is the one place `ignis-core` touches the file system: naming and removing its own
//! temporaries, so every crate cleans up the same way.

use std::path::Path;

/// The marker between the target's name and the owner's pid.
const MARKER: &str = ".ignis-tmp-";

/// `.<target>.ignis-tmp-<pid>.<tag>` for the current process. `tag` tells the kinds apart
/// (`partial`, `dir`, `old`, …) and may carry a counter for uniqueness.
pub fn temp_name(target: &str, tag: &str) -> String {
    format!(".{target}{MARKER}{}.{tag}", std::process::id())
}

/// The owner pid of a temporary name made by [`temp_name`], `None` for any other name.
pub fn owner(file_name: &str) -> Option<u32> {
    if !file_name.starts_with('.') {
        return None;
    }
    let at = file_name.rfind(MARKER)?;
    let rest = &file_name[at + MARKER.len()..];
    let digits = rest.split('.').next()?;
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) || digits.len() > 10 {
        return None;
    }
    if rest.len() == digits.len() {
        return None; // no tag: not ours
    }
    digits.parse().ok()
}

/// The target name a temporary name stands for (`.<target>.ignis-tmp-<pid>.<tag>` →
/// `<target>`), `None` for any other name.
pub fn target_of(file_name: &str) -> Option<&str> {
    owner(file_name)?;
    let at = file_name.rfind(MARKER)?;
    Some(&file_name[1..at])
}

/// Whether process `pid` is running (on Unix; elsewhere always `true`, so nothing is
/// removed).
pub fn pid_alive(pid: u32) -> bool {
    #[cfg(unix)]
    {
        if pid == 0 || pid > i32::MAX as u32 {
            return false;
        }
        if pid == std::process::id() {
            return true;
        }
        // SAFETY: signal 0 performs only the permission and existence checks.
        let r = unsafe { libc::kill(pid as libc::pid_t, 0) };
        r == 0 || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
    }
    #[cfg(not(unix))]
    {
        let _ = pid;
        true
    }
}

/// Removes the temporaries in `dir` whose owner is no longer running; returns how many
/// were removed. Errors reading `dir` count as nothing to clean. `keep` is called with each
/// stale name first: returning `true` leaves that entry for the caller (to recover it).
pub fn remove_stale_with(dir: &Path, mut keep: impl FnMut(&str) -> bool) -> usize {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return 0;
    };
    let mut n = 0;
    for e in rd.flatten() {
        let name = e.file_name();
        let Some(name) = name.to_str() else { continue };
        let Some(pid) = owner(name) else { continue };
        if pid_alive(pid) || keep(name) {
            continue;
        }
        let p = e.path();
        let gone = match e.file_type() {
            Ok(t) if t.is_dir() => std::fs::remove_dir_all(&p).is_ok(),
            Ok(_) => std::fs::remove_file(&p).is_ok(),
            Err(_) => false,
        };
        n += gone as usize;
    }
    n
}

/// [`remove_stale_with`] keeping nothing.
pub fn remove_stale(dir: &Path) -> usize {
    remove_stale_with(dir, |_| false)
}

/// Temporaries being written, for [`remove_live`] when the process is interrupted: their
/// paths, and whether each is a directory.
pub struct LiveSet {
    list: std::sync::Mutex<Vec<(u64, std::path::PathBuf, bool)>>,
}

/// The process's temporaries ([`track`], [`remove_live`]).
static LIVE: LiveSet = LiveSet::new();

/// A temporary registered by [`LiveSet::track`]: unregistered when dropped.
#[derive(Debug)]
pub struct Live {
    id: u64,
    set: &'static LiveSet,
}

impl std::fmt::Debug for LiveSet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveSet").finish_non_exhaustive()
    }
}

impl LiveSet {
    /// An empty set.
    pub const fn new() -> LiveSet {
        LiveSet {
            list: std::sync::Mutex::new(Vec::new()),
        }
    }

    /// The list, usable even if a thread panicked while holding it.
    fn list(&self) -> std::sync::MutexGuard<'_, Vec<(u64, std::path::PathBuf, bool)>> {
        self.list.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Registers `path` (a temporary file, or a directory when `dir`) until the returned
    /// [`Live`] is dropped.
    pub fn track(&'static self, path: &Path, dir: bool) -> Live {
        use std::sync::atomic::{AtomicU64, Ordering};
        static NEXT: AtomicU64 = AtomicU64::new(0);
        let id = NEXT.fetch_add(1, Ordering::Relaxed);
        self.list().push((id, path.to_path_buf(), dir));
        Live { id, set: self }
    }

    /// Removes every registered temporary (files, and directories with their contents)
    /// and empties the set; returns the paths removed. The set stays locked meanwhile, so
    /// none is unregistered (renamed into place) half-way.
    pub fn remove_all(&self) -> Vec<std::path::PathBuf> {
        let mut list = self.list();
        let mut removed = Vec::new();
        for (_, p, dir) in list.drain(..) {
            let gone = if dir {
                std::fs::remove_dir_all(&p).is_ok()
            } else {
                std::fs::remove_file(&p).is_ok()
            };
            if gone {
                removed.push(p);
            }
        }
        removed
    }

    /// Whether `path` is registered.
    pub fn contains(&self, path: &Path) -> bool {
        self.list().iter().any(|(_, p, _)| p == path)
    }
}

impl Default for LiveSet {
    fn default() -> LiveSet {
        LiveSet::new()
    }
}

impl Drop for Live {
    fn drop(&mut self) {
        self.set.list().retain(|(id, _, _)| *id != self.id);
    }
}

/// Registers `path` (a temporary file, or a directory when `dir`) as being written by
/// this process, until the returned [`Live`] is dropped: an interrupted run removes it
/// ([`remove_live`]) instead of leaving it for the next run to clean. Drop the `Live`
/// before renaming the temporary into place (a rename under way is left alone: the next
/// run completes or cleans it).
pub fn track(path: &Path, dir: bool) -> Live {
    LIVE.track(path, dir)
}

/// Whether `path` is a temporary this process is writing ([`track`]).
pub fn is_live(path: &Path) -> bool {
    LIVE.contains(path)
}

/// Removes every temporary this process registered by [`track`] and is still writing
/// (for a process about to exit on an interrupt: Ctrl-C, a render farm's stop); returns
/// the paths removed.
pub fn remove_live() -> Vec<std::path::PathBuf> {
    LIVE.remove_all()
}

/// Moves several complete temporary files into place as one unit (e.g. a flipbook's PNG
/// and its JSON): a journal `.<first target>.ignis-tmp-<pid>.commit` listing every
/// (temporary, target) pair is written and synced first, then the renames are done, then
/// the journal is removed. If the process dies in between, [`recover_and_clean`] (run by
/// the next writer or reader in that directory) finishes the renames from the journal, so
/// the files are either all old or all new once anything looks at them again.
/// Every path must be in the same directory `dir`, named by plain file names.
pub fn commit_files(dir: &Path, pairs: &[(String, String)]) -> std::io::Result<()> {
    use std::io::Write;
    let Some((_, first)) = pairs.first() else {
        return Ok(());
    };
    for (t, f) in pairs {
        if [t, f]
            .iter()
            .any(|n| n.contains(['/', '\t', '\n']) || n.is_empty())
        {
            return Err(std::io::Error::other(format!(
                "commit_files: `{t}` → `{f}` are not plain file names"
            )));
        }
    }
    let text: String = pairs.iter().map(|(t, f)| format!("{t}\t{f}\n")).collect();
    let journal = dir.join(temp_name(first, "commit"));
    let partial = dir.join(temp_name(first, "commit-partial"));
    {
        let mut j = std::fs::File::create(&partial)?;
        j.write_all(text.as_bytes())?;
        j.sync_all()?;
    }
    std::fs::rename(&partial, &journal)?;
    sync_dir(dir);
    for (t, f) in pairs {
        // Nothing renamed yet can be undone safely only for the first pair; on failure leave
        // the journal so the next run completes or cleans it.
        std::fs::rename(dir.join(t), dir.join(f))?;
    }
    sync_dir(dir);
    std::fs::remove_file(&journal)?;
    Ok(())
}

fn sync_dir(dir: &Path) {
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
}

/// Finishes the interrupted [`commit_files`] of dead owners in `dir`; returns how many
/// journals were completed.
fn roll_forward(dir: &Path) -> usize {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return 0;
    };
    let mut n = 0;
    for e in rd.flatten() {
        let name = e.file_name();
        let Some(name) = name.to_str() else { continue };
        if !name.ends_with(".commit") || owner(name).is_none_or(pid_alive) {
            continue;
        }
        let p = e.path();
        // A journal is a few lines; anything large is not ours.
        let text = match std::fs::metadata(&p) {
            Ok(m) if m.is_file() && m.len() < 1 << 16 => {
                std::fs::read_to_string(&p).unwrap_or_default()
            }
            _ => continue,
        };
        for line in text.lines() {
            let Some((t, f)) = line.split_once('\t') else {
                continue;
            };
            // Only our own temporaries are renamed, only to plain names in `dir`.
            if owner(t).is_none() || f.contains('/') || f.is_empty() {
                continue;
            }
            if std::fs::symlink_metadata(dir.join(t)).is_ok() {
                let _ = std::fs::rename(dir.join(t), dir.join(f));
            }
        }
        let _ = std::fs::remove_file(&p);
        n += 1;
    }
    n
}

/// Cleans `dir` after killed runs: interrupted [`commit_files`] are completed first; a
/// stale `.<name>.ignis-tmp-<pid>.old` (a previous output moved aside by
/// [`replace_dir`]'s fallback) is renamed back to `<name>` when nothing has that name any
/// more (recovery); every other stale temporary is removed. Returns how many entries were
/// completed, removed or recovered.
pub fn recover_and_clean(dir: &Path) -> usize {
    let mut recovered = roll_forward(dir);
    let n = remove_stale_with(dir, |name| {
        if !name.ends_with(".old") {
            return false;
        }
        let Some(target) = target_of(name) else {
            return false;
        };
        let t = dir.join(target);
        if std::fs::symlink_metadata(&t).is_err() && std::fs::rename(dir.join(name), &t).is_ok() {
            recovered += 1;
            return true;
        }
        false
    });
    n + recovered
}

/// Swaps the names of `a` and `b` in one step (Linux `renameat2(RENAME_EXCHANGE)`).
/// `Ok(false)` when the system or file system cannot do that (the caller falls back).
pub fn exchange(a: &Path, b: &Path) -> std::io::Result<bool> {
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::ffi::OsStrExt;
        let ca = std::ffi::CString::new(a.as_os_str().as_bytes())
            .map_err(|_| std::io::Error::other("path contains NUL"))?;
        let cb = std::ffi::CString::new(b.as_os_str().as_bytes())
            .map_err(|_| std::io::Error::other("path contains NUL"))?;
        const RENAME_EXCHANGE: libc::c_uint = 2;
        // SAFETY: both paths are valid NUL-terminated strings for the duration of the call.
        let r = unsafe {
            libc::syscall(
                libc::SYS_renameat2,
                libc::AT_FDCWD,
                ca.as_ptr(),
                libc::AT_FDCWD,
                cb.as_ptr(),
                RENAME_EXCHANGE,
            )
        };
        if r == 0 {
            return Ok(true);
        }
        let e = std::io::Error::last_os_error();
        match e.raw_os_error() {
            Some(libc::ENOSYS) | Some(libc::EINVAL) | Some(libc::ENOTSUP) => Ok(false),
            _ => Err(e),
        }
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = (a, b);
        Ok(false)
    }
}

/// Replaces the directory `target` by the complete directory `tmp` (same parent). With an
/// existing target this is one atomic exchange where the system offers it (readers see
/// the old or the new directory, never none), then the old one is deleted. The fallback
/// (two renames) moves the old directory to `.<target>.ignis-tmp-<pid>.old` first, which
/// [`recover_and_clean`] renames back if the process dies between the two renames.
pub fn replace_dir(tmp: &Path, target: &Path) -> std::io::Result<()> {
    if std::fs::symlink_metadata(target).is_err() {
        return std::fs::rename(tmp, target);
    }
    if exchange(tmp, target)? {
        // `tmp` now holds the previous directory.
        let _ = std::fs::remove_dir_all(tmp);
        return Ok(());
    }
    let name = target
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let aside = target.with_file_name(temp_name(&name, "old"));
    std::fs::rename(target, &aside)?;
    if let Err(e) = std::fs::rename(tmp, target) {
        let _ = std::fs::rename(&aside, target);
        return Err(e);
    }
    let _ = std::fs::remove_dir_all(&aside);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_interrupt_removes_the_live_temporaries_only() {
        static SET: LiveSet = LiveSet::new();
        let t = tempfile::tempdir().unwrap();
        let (file, dir, done) = (
            t.path().join(temp_name("a.mp4", "0.partial")),
            t.path().join(temp_name("seq", "0.dir")),
            t.path().join(temp_name("b.gif", "1.partial")),
        );
        std::fs::write(&file, b"half").unwrap();
        std::fs::create_dir(&dir).unwrap();
        std::fs::write(dir.join("0001.png"), b"x").unwrap();
        std::fs::write(&done, b"whole").unwrap();
        let (_a, _b) = (SET.track(&file, false), SET.track(&dir, true));
        let c = SET.track(&done, false);
        assert!(SET.contains(&done));
        drop(c); // renamed into place: no longer the interrupt's to remove
        assert!(!SET.contains(&done));
        let mut removed = SET.remove_all();
        removed.sort();
        let mut want = vec![file.clone(), dir.clone()];
        want.sort();
        assert_eq!(removed, want);
        assert!(!file.exists() && !dir.exists() && done.exists());
        assert!(!SET.contains(&file) && SET.remove_all().is_empty());
    }

    #[test]
    fn names_round_trip() {
        let n = temp_name("fire.mp4", "partial");
        assert_eq!(owner(&n), Some(std::process::id()));
        assert_eq!(target_of(&n), Some("fire.mp4"));
        assert_eq!(owner("fire.mp4"), None);
        assert_eq!(owner(".fire.mp4"), None);
        assert_eq!(owner(".a.ignis-tmp-12"), None);
        assert_eq!(owner(".a.ignis-tmp-x1.partial"), None);
        assert_eq!(owner(".a.ignis-tmp-12.dir"), Some(12));
    }

    /// Issue 18 defect 14: a dead owner's temporaries go, a live one's and other files stay.
    #[test]
    fn stale_temporaries_of_dead_owners_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        // A child that has exited: its pid is not running (reused pids are improbable
        // within the test).
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let dead = child.id();
        child.wait().unwrap();
        let d = dir.path();
        std::fs::write(d.join(format!(".a.png.ignis-tmp-{dead}.partial")), b"x").unwrap();
        std::fs::create_dir(d.join(format!(".db.ignis-tmp-{dead}.dir"))).unwrap();
        std::fs::write(d.join(format!(".db.ignis-tmp-{dead}.dir/f")), b"x").unwrap();
        std::fs::write(d.join(format!(".b.png.ignis-tmp-{dead}.old")), b"x").unwrap();
        let mine = temp_name("c.png", "partial");
        std::fs::write(d.join(&mine), b"x").unwrap();
        std::fs::write(d.join("user.png"), b"x").unwrap();
        std::fs::write(d.join(".hidden"), b"x").unwrap();
        let n = remove_stale_with(d, |name| name.ends_with(".old"));
        assert_eq!(n, 2);
        let mut left: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        left.sort();
        let mut want = vec![
            format!(".b.png.ignis-tmp-{dead}.old"),
            mine,
            "user.png".to_string(),
            ".hidden".to_string(),
        ];
        want.sort();
        assert_eq!(left, want);
        // Recovery: the target is gone, so the stale `.old` comes back under its name.
        assert_eq!(recover_and_clean(d), 1);
        assert!(d.join("b.png").exists());
    }

    /// Issue 18 defect 6: a multi-file commit interrupted after its journal is completed by
    /// the next run; a completed one leaves nothing behind.
    #[test]
    fn interrupted_commit_is_rolled_forward() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        std::fs::write(d.join("f.png"), b"old png").unwrap();
        std::fs::write(d.join("f.json"), b"old json").unwrap();
        let (tp, tj) = (
            temp_name("f.png", "partial"),
            temp_name("f.json", "partial"),
        );
        std::fs::write(d.join(&tp), b"new png").unwrap();
        std::fs::write(d.join(&tj), b"new json").unwrap();
        commit_files(d, &[(tp, "f.png".into()), (tj, "f.json".into())]).unwrap();
        assert_eq!(std::fs::read(d.join("f.json")).unwrap(), b"new json");
        assert_eq!(std::fs::read_dir(d).unwrap().count(), 2);
        // A dead writer's state: journal written, the PNG renamed, the JSON not yet.
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let dead = child.id();
        child.wait().unwrap();
        let tj = format!(".f.json.ignis-tmp-{dead}.partial");
        let tp = format!(".f.png.ignis-tmp-{dead}.partial");
        std::fs::write(d.join("f.png"), b"newer png").unwrap();
        std::fs::write(d.join(&tj), b"newer json").unwrap();
        std::fs::write(
            d.join(format!(".f.png.ignis-tmp-{dead}.commit")),
            format!("{tp}\tf.png\n{tj}\tf.json\n"),
        )
        .unwrap();
        recover_and_clean(d);
        assert_eq!(std::fs::read(d.join("f.json")).unwrap(), b"newer json");
        assert_eq!(std::fs::read(d.join("f.png")).unwrap(), b"newer png");
        assert_eq!(std::fs::read_dir(d).unwrap().count(), 2);
    }

    /// Issue 18 defect 6: replacing a directory is one exchange; nothing is left beside it.
    #[test]
    fn replace_dir_swaps_in_one_step() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let target = d.join("out");
        let tmp = d.join(temp_name("out", "dir"));
        std::fs::create_dir(&tmp).unwrap();
        std::fs::write(tmp.join("f"), b"new1").unwrap();
        replace_dir(&tmp, &target).unwrap();
        std::fs::create_dir(&tmp).unwrap();
        std::fs::write(tmp.join("f"), b"new2").unwrap();
        replace_dir(&tmp, &target).unwrap();
        assert_eq!(std::fs::read(target.join("f")).unwrap(), b"new2");
        assert_eq!(std::fs::read_dir(d).unwrap().count(), 1);
    }
}
