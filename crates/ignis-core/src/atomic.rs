//! Atomic file writes: the one way every Ignis writer puts a file in place.
//!
//! A file is written to a hidden temporary beside its target (named by
//! [`crate::tempfiles::temp_name`], so a killed run's leftovers are removed by the next run),
//! flushed, synced, and renamed over the target. Readers see the old file or the new one,
//! never a half-written one. This module knows no file formats: callers fill the bytes.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// A temporary file beside its target, renamed into place by [`AtomicFile::commit`] and
/// deleted on drop otherwise.
pub struct AtomicFile {
    tmp: PathBuf,
    target: PathBuf,
    file: Option<BufWriter<File>>,
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
        let file = File::create(&tmp)?;
        Ok(AtomicFile {
            tmp,
            target: target.to_path_buf(),
            file: Some(BufWriter::with_capacity(1 << 20, file)),
        })
    }

    /// The temporary's path (for tools that must write by name).
    pub fn temp_path(&self) -> &Path {
        &self.tmp
    }

    /// The writer over the temporary.
    pub fn writer(&mut self) -> &mut BufWriter<File> {
        self.file.as_mut().expect("AtomicFile used after commit")
    }

    /// Flushes, syncs and renames the temporary over the target.
    pub fn commit(mut self) -> io::Result<()> {
        let w = self.file.take().expect("AtomicFile committed twice");
        let f = w.into_inner().map_err(|e| e.into_error())?;
        f.sync_all()?;
        drop(f);
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

/// The directory a path lives in (`.` for a bare file name).
pub fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Refuses an output path that exists and is not a regular file (a device, FIFO, socket
/// or directory): renaming over it would replace e.g. `/dev/null` rather than write to it.
pub fn check_regular_target(path: &Path) -> io::Result<()> {
    let Ok(m) = std::fs::metadata(path) else {
        return Ok(());
    };
    if m.is_file() {
        return Ok(());
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

#[cfg(test)]
mod tests {
    use super::*;

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
