//! Atomic file writes: the one way every Ignis writer puts a file in place.
//!
//! A file is written to a hidden temporary beside its target (named by
//! [`crate::tempfiles::temp_name`], so a killed run's leftovers are removed by the next run),
//! flushed, synced, and renamed over the target. Readers see the old file or the new one,
//! never a half-written one. This module knows no file formats: callers fill the bytes.

use std::collections::{HashMap, HashSet};
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

/// A temporary file beside its target, renamed into place by [`AtomicFile::commit`] and
/// deleted on drop otherwise.
pub struct AtomicFile {
    tmp: PathBuf,
    target: PathBuf,
    file: Option<BufWriter<File>>,
    /// Registered for removal on an interrupt until the rename ([`crate::tempfiles::track`]).
    live: Option<crate::tempfiles::Live>,
}

impl AtomicFile {
    /// Creates the temporary for `target` (its directory must exist). Refuses a target that
    /// exists and is not a regular file ([`check_regular_target`]).
    pub fn create(target: &Path) -> io::Result<AtomicFile> {
        check_regular_target(target)?;
        let dir = parent_dir(target);
        crate::tempfiles::recover_and_clean(&dir);
        let name = target
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .ok_or_else(|| {
                io::Error::new(
                    io::ErrorKind::InvalidInput,
                    format!("{} has no file name", target.display()),
                )
            })?;
        static NEXT: AtomicU64 = AtomicU64::new(0);
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let tmp = dir.join(crate::tempfiles::temp_name(&name, &format!("{n}.partial")));
        let live = crate::tempfiles::track(&tmp, false);
        let file = File::create(&tmp)?;
        Ok(AtomicFile {
            tmp,
            target: target.to_path_buf(),
            file: Some(BufWriter::with_capacity(1 << 20, file)),
            live: Some(live),
        })
    }

    /// The temporary's path (for tools that must write by name).
    pub fn temp_path(&self) -> &Path {
        &self.tmp
    }

    /// The target the temporary will be renamed to.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// The writer over the temporary.
    pub fn writer(&mut self) -> &mut BufWriter<File> {
        self.file.as_mut().expect("AtomicFile used after commit")
    }

    /// A second handle to the temporary (sharing its offset), for encoders that must own
    /// their writer. Flush what is written through it before [`AtomicFile::commit`].
    pub fn try_clone_file(&self) -> io::Result<File> {
        self.file
            .as_ref()
            .expect("AtomicFile used after commit")
            .get_ref()
            .try_clone()
    }

    /// Flushes and syncs the temporary, keeping it open.
    fn sync(&mut self) -> io::Result<()> {
        let w = self.writer();
        w.flush()?;
        w.get_ref().sync_all()
    }

    /// Flushes, syncs and renames the temporary over the target — unless the target is now
    /// a file the running command reads ([`check_not_an_input`]; a reader opened after the
    /// writer was made), when the temporary is removed instead.
    pub fn commit(mut self) -> io::Result<()> {
        check_not_an_input(&self.target)?;
        let w = self.file.take().expect("AtomicFile committed twice");
        let f = w.into_inner().map_err(|e| e.into_error())?;
        f.sync_all()?;
        drop(f);
        self.live.take();
        std::fs::rename(&self.tmp, &self.target)?;
        // Renamed away: nothing for drop to remove.
        self.tmp = PathBuf::new();
        Ok(())
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if !self.tmp.as_os_str().is_empty() {
            self.file.take();
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// Commits several finished files as one unit (e.g. a flipbook's sheet and its JSON): each
/// is flushed and synced, then [`crate::tempfiles::commit_files`] renames them all under a
/// journal, so an interrupted commit is completed by the next run. Every target must be in
/// the same directory. On an error the temporaries not yet renamed are removed.
pub fn commit_all(files: Vec<AtomicFile>) -> io::Result<()> {
    let Some(first) = files.first() else {
        return Ok(());
    };
    let first = first.target.clone();
    let dir = parent_dir(&first);
    let mut files = files;
    let mut pairs = Vec::with_capacity(files.len());
    for f in &mut files {
        if parent_dir(&f.target) != dir {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!(
                    "{} and {} are in different directories; files committed together must \
                     share one",
                    first.display(),
                    f.target.display()
                ),
            ));
        }
        check_not_an_input(&f.target)?;
        f.sync()?;
        let name = |p: &Path| p.file_name().map(|n| n.to_string_lossy().into_owned());
        let (Some(t), Some(n)) = (name(&f.tmp), name(&f.target)) else {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("{} has no file name", f.target.display()),
            ));
        };
        pairs.push((t, n));
    }
    for f in &mut files {
        f.file.take();
        f.live.take();
    }
    crate::tempfiles::commit_files(&dir, &pairs)?;
    for f in &mut files {
        // Renamed away: nothing for drop to remove.
        f.tmp = PathBuf::new();
    }
    Ok(())
}

/// A fresh hidden directory beside a target directory, for outputs written as a whole
/// directory (frame sequences, a run's plots): named like every temporary
/// (`.<name>.ignis-tmp-<pid>.<n>.dir`, removed by the next run if this one is killed) and
/// removed with its contents on drop unless the caller has renamed it away.
pub struct StagingDir {
    path: PathBuf,
    /// Registered for removal on an interrupt ([`crate::tempfiles::track`]); see
    /// [`StagingDir::into_place`].
    live: Option<crate::tempfiles::Live>,
}

impl StagingDir {
    /// Creates the staging directory beside `target`, creating `target`'s parent if needed
    /// and cleaning the parent of stale temporaries first.
    pub fn create(target: &Path) -> io::Result<StagingDir> {
        let parent = parent_dir(target);
        std::fs::create_dir_all(&parent)?;
        crate::tempfiles::recover_and_clean(&parent);
        let name = target
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "out".into());
        static NEXT: AtomicU64 = AtomicU64::new(0);
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let path = parent.join(crate::tempfiles::temp_name(&name, &format!("{n}.dir")));
        let live = crate::tempfiles::track(&path, true);
        std::fs::create_dir(&path)?;
        Ok(StagingDir {
            path,
            live: Some(live),
        })
    }

    /// Stops tracking the directory for removal on an interrupt: call it just before
    /// renaming the directory into place (the next run cleans or completes what an
    /// interrupt leaves of that rename).
    pub fn into_place(&mut self) {
        self.live.take();
    }

    /// Where to write the files.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for StagingDir {
    fn drop(&mut self) {
        // Gone already when the caller renamed it into place.
        let _ = std::fs::remove_dir_all(&self.path);
    }
}

/// Writes `target` atomically: `fill` writes the bytes into a buffered temporary beside it,
/// which is synced and renamed into place; on any error the temporary is removed and the
/// old target (if any) is untouched.
pub fn write_file(
    target: &Path,
    fill: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> io::Result<()> {
    let mut f = AtomicFile::create(target)?;
    fill(f.writer())?;
    f.commit()
}

/// [`write_file`] with the whole content at hand.
pub fn write_bytes(target: &Path, bytes: &[u8]) -> io::Result<()> {
    write_file(target, |w| w.write_all(bytes))
}

/// The bytes of the file at `path` when it holds at most `limit` of them, `None` when it
/// holds more (only `limit + 1` are read): what a cache or index reads before it trusts a
/// file it wrote, so a damaged or foreign one is never read whole.
pub fn read_at_most(path: &Path, limit: u64) -> io::Result<Option<Vec<u8>>> {
    use std::io::Read;
    let mut bytes = Vec::new();
    File::open(path)?
        .take(limit.saturating_add(1))
        .read_to_end(&mut bytes)?;
    Ok((bytes.len() as u64 <= limit).then_some(bytes))
}

/// The directory a path lives in (`.` for a bare file name).
pub fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Refuses an output path that exists and is not a regular file (a device, FIFO, socket
/// or directory): renaming over it would replace e.g. `/dev/null` rather than write to it.
/// While a command guards its inputs ([`guard_inputs`]), also refuses a file it reads
/// ([`check_not_an_input`]).
pub fn check_regular_target(path: &Path) -> io::Result<()> {
    let Ok(m) = std::fs::metadata(path) else {
        return Ok(());
    };
    if m.is_file() {
        return check_not_an_input_id(path, &m);
    }
    let ft = m.file_type();
    let kind = {
        #[cfg(unix)]
        {
            use std::os::unix::fs::FileTypeExt;
            if ft.is_char_device() || ft.is_block_device() {
                "a device"
            } else if ft.is_fifo() {
                "a FIFO"
            } else if ft.is_socket() {
                "a socket"
            } else if ft.is_dir() {
                "a directory"
            } else {
                "not a regular file"
            }
        }
        #[cfg(not(unix))]
        {
            let _ = ft;
            "not a regular file"
        }
    };
    Err(io::Error::new(
        io::ErrorKind::InvalidInput,
        format!(
            "{} is {kind}; outputs are written as regular files and this one would be \
             replaced, not written through. Choose a regular file path (to stream, write a \
             file and copy it)",
            path.display()
        ),
    ))
}

/// A file's identity: the same for every path that leads to it (hard links, symbolic
/// links, `./` and `..` spellings).
#[cfg(unix)]
type FileId = (u64, u64);
#[cfg(not(unix))]
type FileId = PathBuf;

#[cfg(unix)]
fn file_id(_path: &Path, m: &std::fs::Metadata) -> Option<FileId> {
    use std::os::unix::fs::MetadataExt;
    Some((m.dev(), m.ino()))
}

#[cfg(not(unix))]
fn file_id(path: &Path, _m: &std::fs::Metadata) -> Option<FileId> {
    std::fs::canonicalize(path).ok()
}

/// The files a command reads, by identity, with the path each was read by.
#[derive(Default)]
struct Inputs {
    /// Paths already recorded (a clip is probed several times; a sequence is thousands of
    /// files): each file is looked at once.
    seen: HashSet<PathBuf>,
    ids: HashMap<FileId, PathBuf>,
}

impl Inputs {
    /// Records the file at `path` (`m`: its metadata, when the reader has it); a path that
    /// is missing or not a regular file is not recorded.
    fn record(&mut self, path: &Path, m: Option<&std::fs::Metadata>) {
        if self.seen.contains(path) {
            return;
        }
        let read;
        let m = match m {
            Some(m) => m,
            None => match std::fs::metadata(path) {
                Ok(found) => {
                    read = found;
                    &read
                }
                Err(_) => return,
            },
        };
        if let Some(id) = m.is_file().then(|| file_id(path, m)).flatten() {
            self.ids.entry(id).or_insert_with(|| path.to_path_buf());
            self.seen.insert(path.to_path_buf());
        }
    }

    /// The path by which the file `target` (whose metadata is `m`) was read, if it was.
    fn read_as(&self, target: &Path, m: &std::fs::Metadata) -> Option<&PathBuf> {
        file_id(target, m).and_then(|id| self.ids.get(&id))
    }
}

/// The inputs of the running command while it guards them: how many guards are alive,
/// and what they have recorded (`None` when none is).
struct Guarded {
    depth: usize,
    inputs: Option<Inputs>,
}

static READING: Mutex<Guarded> = Mutex::new(Guarded {
    depth: 0,
    inputs: None,
});

fn reading() -> std::sync::MutexGuard<'static, Guarded> {
    READING.lock().unwrap_or_else(|e| e.into_inner())
}

/// While alive, the files recorded by [`record_input`] (the footage, models, settings a
/// command reads) are refused as outputs by every writer ([`check_regular_target`], so
/// [`AtomicFile::create`] and the output checks): `ignis convert clip.mp4 -o clip.mp4`,
/// a loop written over the clip it loops, frames written over the sequence they are read
/// from, or a render over a database's source video would replace the user's footage.
/// An application turns it on for a command that takes paths from a user; a library
/// (and its tests, which may read a file and then rewrite it on purpose) leaves it off.
/// Dropping the last guard forgets the inputs.
#[must_use = "inputs are guarded only while the guard is alive"]
pub struct InputGuard(());

/// Starts guarding the running command's inputs ([`InputGuard`]).
pub fn guard_inputs() -> InputGuard {
    let mut r = reading();
    r.depth += 1;
    r.inputs.get_or_insert_with(Inputs::default);
    InputGuard(())
}

impl Drop for InputGuard {
    fn drop(&mut self) {
        let mut r = reading();
        r.depth -= 1;
        if r.depth == 0 {
            r.inputs = None;
        }
    }
}

/// Records `path` as a file the running command reads, while it guards its inputs
/// ([`guard_inputs`]; otherwise nothing is done). Paths that are not regular files
/// (directories, missing paths) are ignored.
pub fn record_input(path: &Path) {
    if let Some(inputs) = reading().inputs.as_mut() {
        inputs.record(path, None);
    }
}

/// [`record_input`] for a file whose metadata the reader already has.
pub fn record_input_with(path: &Path, m: &std::fs::Metadata) {
    if let Some(inputs) = reading().inputs.as_mut() {
        inputs.record(path, Some(m));
    }
}

/// The path by which the running command read the file at `target` (by identity: hard
/// and symbolic links too; [`record_input`]), if it did. `None` while inputs are not
/// guarded, or when `target` is not an existing file.
pub fn input_at(target: &Path) -> Option<PathBuf> {
    let m = std::fs::metadata(target).ok().filter(|m| m.is_file())?;
    read_as(target, &m)
}

fn read_as(target: &Path, m: &std::fs::Metadata) -> Option<PathBuf> {
    reading().inputs.as_ref()?.read_as(target, m).cloned()
}

/// Refuses `target` when it is a file the running command reads ([`input_at`]): writing
/// it would replace the input.
pub fn check_not_an_input(target: &Path) -> io::Result<()> {
    match input_at(target) {
        None => Ok(()),
        Some(input) => Err(input_error(target, &input)),
    }
}

fn check_not_an_input_id(target: &Path, m: &std::fs::Metadata) -> io::Result<()> {
    match read_as(target, m) {
        None => Ok(()),
        Some(input) => Err(input_error(target, &input)),
    }
}

fn input_error(target: &Path, input: &Path) -> io::Error {
    let what = if input == target {
        "a file this command reads".to_string()
    } else {
        format!(
            "the same file as {}, which this command reads",
            input.display()
        )
    };
    io::Error::new(
        io::ErrorKind::InvalidInput,
        format!(
            "{} is {what}: the output would replace it. Choose another output path",
            target.display()
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A recorded input is found by any path that leads to it — as read, spelt another
    /// way, through a hard or a symbolic link — and nothing else is: another file, a new
    /// path, or a path recorded when it was missing or a directory.
    #[test]
    fn inputs_are_known_by_identity_not_by_name() {
        let d = tempfile::tempdir().unwrap();
        let p = |s: &str| d.path().join(s);
        for f in ["clip.mp4", "other.mp4"] {
            std::fs::write(p(f), b"frames").unwrap();
        }
        std::fs::create_dir(p("frames")).unwrap();
        let mut inputs = Inputs::default();
        for f in ["clip.mp4", "frames", "later.mp4"] {
            inputs.record(&p(f), None);
        }
        std::fs::write(p("later.mp4"), b"made after it was read").unwrap();
        std::fs::hard_link(p("clip.mp4"), p("hard.mp4")).unwrap();
        #[cfg(unix)]
        std::os::unix::fs::symlink(p("clip.mp4"), p("soft.mp4")).unwrap();
        let read_as = |t: PathBuf| {
            let m = std::fs::metadata(&t).unwrap();
            inputs.read_as(&t, &m).cloned()
        };
        let mut same = vec![p("clip.mp4"), p("frames/../clip.mp4"), p("hard.mp4")];
        if cfg!(unix) {
            same.push(p("soft.mp4"));
        }
        for t in same {
            assert_eq!(read_as(t.clone()), Some(p("clip.mp4")), "{}", t.display());
        }
        for t in ["other.mp4", "later.mp4", "frames"] {
            assert_eq!(read_as(p(t)), None, "{t}");
        }
        let e = input_error(&p("hard.mp4"), &p("clip.mp4")).to_string();
        assert!(
            e.contains("the same file as") && e.contains("another output path"),
            "{e}"
        );
        let e = input_error(&p("clip.mp4"), &p("clip.mp4")).to_string();
        assert!(e.contains("is a file this command reads"), "{e}");
    }

    #[test]
    fn read_at_most_reads_up_to_its_limit_only() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("f");
        std::fs::write(&p, b"12345").unwrap();
        assert_eq!(read_at_most(&p, 5).unwrap().as_deref(), Some(&b"12345"[..]));
        assert_eq!(read_at_most(&p, 9).unwrap().as_deref(), Some(&b"12345"[..]));
        assert_eq!(read_at_most(&p, 4).unwrap(), None);
        assert_eq!(read_at_most(&p, 0).unwrap(), None);
        assert!(read_at_most(&d.path().join("missing"), 5).is_err());
    }

    /// What an interrupt would remove: a temporary while it is written, not once it is
    /// renamed into place (nor while several are committed together), and a staging
    /// directory until the caller puts it in place.
    #[test]
    fn temporaries_are_live_until_they_are_put_in_place() {
        let d = tempfile::tempdir().unwrap();
        let f = AtomicFile::create(&d.path().join("a.bin")).unwrap();
        let tmp = f.temp_path().to_path_buf();
        assert!(crate::tempfiles::is_live(&tmp));
        f.commit().unwrap();
        assert!(!crate::tempfiles::is_live(&tmp));
        let (a, b) = (
            AtomicFile::create(&d.path().join("s.png")).unwrap(),
            AtomicFile::create(&d.path().join("s.json")).unwrap(),
        );
        let tmps = [a.temp_path().to_path_buf(), b.temp_path().to_path_buf()];
        assert!(tmps.iter().all(|t| crate::tempfiles::is_live(t)));
        commit_all(vec![a, b]).unwrap();
        assert!(!tmps.iter().any(|t| crate::tempfiles::is_live(t)));
        let dropped = AtomicFile::create(&d.path().join("c.bin")).unwrap();
        let tmp = dropped.temp_path().to_path_buf();
        drop(dropped);
        assert!(!crate::tempfiles::is_live(&tmp) && !tmp.exists());
        let mut s = StagingDir::create(&d.path().join("seq")).unwrap();
        assert!(crate::tempfiles::is_live(s.path()));
        s.into_place();
        assert!(!crate::tempfiles::is_live(s.path()));
    }

    #[test]
    fn writes_and_replaces_whole_files() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("a.bin");
        write_bytes(&p, b"one").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"one");
        write_bytes(&p, b"two, longer").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two, longer");
        // Only the target is left.
        assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), 1);
    }

    #[test]
    fn a_failed_fill_leaves_the_old_file_and_no_temporary() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("a.bin");
        write_bytes(&p, b"old").unwrap();
        let r = write_file(&p, |w| {
            w.write_all(b"half")?;
            Err(io::Error::other("disk full"))
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), 1);
    }

    #[test]
    fn a_dropped_file_is_removed() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("a.bin");
        {
            let mut f = AtomicFile::create(&p).unwrap();
            f.writer().write_all(b"x").unwrap();
        }
        assert!(!p.exists());
        assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), 0);
    }

    #[test]
    fn files_committed_together_all_appear() {
        let d = tempfile::tempdir().unwrap();
        let (a, b) = (d.path().join("a.png"), d.path().join("a.json"));
        write_bytes(&a, b"old").unwrap();
        let mut fa = AtomicFile::create(&a).unwrap();
        fa.writer().write_all(b"sheet").unwrap();
        let mut fb = AtomicFile::create(&b).unwrap();
        fb.writer().write_all(b"{}").unwrap();
        // nothing visible before the commit
        assert_eq!(std::fs::read(&a).unwrap(), b"old");
        assert!(!b.exists());
        commit_all(vec![fa, fb]).unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), b"sheet");
        assert_eq!(std::fs::read(&b).unwrap(), b"{}");
        assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), 2);
    }

    #[test]
    fn files_in_different_directories_are_refused_and_removed() {
        let d = tempfile::tempdir().unwrap();
        std::fs::create_dir(d.path().join("sub")).unwrap();
        let fa = AtomicFile::create(&d.path().join("a")).unwrap();
        let fb = AtomicFile::create(&d.path().join("sub/b")).unwrap();
        let e = commit_all(vec![fa, fb]).unwrap_err();
        assert!(e.to_string().contains("different directories"), "{e}");
        assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), 1); // only sub/
        assert_eq!(std::fs::read_dir(d.path().join("sub")).unwrap().count(), 0);
    }

    #[test]
    fn a_cloned_handle_writes_into_the_temporary() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("a.bin");
        let f = AtomicFile::create(&p).unwrap();
        let mut h = f.try_clone_file().unwrap();
        h.write_all(b"through the clone").unwrap();
        drop(h);
        f.commit().unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"through the clone");
    }

    #[test]
    fn a_staging_dir_is_beside_its_target_and_removed_on_drop() {
        let d = tempfile::tempdir().unwrap();
        let target = d.path().join("new/frames");
        let s = StagingDir::create(&target).unwrap();
        assert_eq!(s.path().parent(), Some(d.path().join("new").as_path()));
        assert!(
            crate::tempfiles::owner(&s.path().file_name().unwrap().to_string_lossy()).is_some()
        );
        std::fs::write(s.path().join("0000.png"), b"x").unwrap();
        let kept = d.path().join("new/kept");
        let s2 = StagingDir::create(&kept).unwrap();
        std::fs::rename(s2.path(), &kept).unwrap();
        drop(s2);
        assert!(kept.is_dir());
        drop(s);
        assert_eq!(std::fs::read_dir(d.path().join("new")).unwrap().count(), 1);
    }

    #[cfg(unix)]
    #[test]
    fn devices_and_directories_are_refused() {
        let e = write_bytes(Path::new("/dev/null"), b"x").unwrap_err();
        assert!(e.to_string().contains("a device"), "{e}");
        let d = tempfile::tempdir().unwrap();
        let e = write_bytes(d.path(), b"x").unwrap_err();
        assert!(e.to_string().contains("a directory"), "{e}");
    }
}
