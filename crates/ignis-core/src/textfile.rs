//! Reading the small text files a user names (fire files, scenarios, clip lists, settings):
//! bounded in size and never blocking, so that a device, a FIFO or a huge file named by
//! mistake (`/dev/zero`, a video given where a TOML was meant) is refused with a clear
//! error instead of filling memory or waiting for a writer that never comes.
//! (`std::fs::read_to_string` does neither.) [`explain_missing`] gives a missing path's
//! error its reader's own fix (footage, models and databases use it too).

use std::io::{Error, ErrorKind, Read};
use std::path::Path;

/// The largest text file [`read_text`] reads: far above any settings file (a scenario of
/// thousands of motions is a few hundred kB), far below what would strain memory.
pub const MAX_TEXT_BYTES: u64 = 16 << 20;

/// `e`, or, when it says a path is not there, the same kind of error saying `why` instead
/// (what the path should have been and how to get one): the readers of footage, models,
/// databases and text files each name their own fix this way.
pub fn explain_missing(e: Error, why: &str) -> Error {
    if e.kind() == ErrorKind::NotFound {
        Error::new(ErrorKind::NotFound, why.to_string())
    } else {
        e
    }
}

/// Reads the regular file `path` if it holds at most `limit` bytes, opened without
/// blocking. Refuses, with an error of the kind shown and a message that says why: a path
/// that is not there (`NotFound`), a directory (`IsADirectory`), a FIFO or a device
/// (`InvalidInput`), a larger file (`InvalidData`). The readers of the files a user names
/// (text, `.flame` models) share it.
pub fn read_bytes(path: &Path, limit: u64) -> std::io::Result<Vec<u8>> {
    let mut o = std::fs::OpenOptions::new();
    o.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        // Opening a FIFO for reading would wait for a writer; without blocking it opens at
        // once and is refused below as not a regular file.
        o.custom_flags(libc::O_NONBLOCK);
    }
    let file = o
        .open(path)
        .map_err(|e| explain_missing(e, "there is no such file"))?;
    let md = file.metadata()?;
    if md.is_dir() {
        return Err(Error::new(
            ErrorKind::IsADirectory,
            "this is a directory, not a file",
        ));
    }
    if !md.is_file() {
        return Err(Error::new(
            ErrorKind::InvalidInput,
            "not a regular file (a FIFO or a device)",
        ));
    }
    let too_big = |n: u64| {
        Error::new(
            ErrorKind::InvalidData,
            format!("{n} bytes is too large (at most {limit} here); is this the right file?"),
        )
    };
    if md.len() > limit {
        return Err(too_big(md.len()));
    }
    let mut bytes = Vec::with_capacity(md.len() as usize);
    // A file that grows while it is read stops at the bound all the same.
    file.take(limit.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(too_big(bytes.len() as u64));
    }
    Ok(bytes)
}

/// Reads `path` as UTF-8 text of at most [`MAX_TEXT_BYTES`] ([`read_bytes`], whose errors
/// it gives), refusing text that is not UTF-8 (`InvalidData`).
pub fn read_text(path: &Path) -> std::io::Result<String> {
    String::from_utf8(read_bytes(path, MAX_TEXT_BYTES)?).map_err(|e| {
        Error::new(
            ErrorKind::InvalidData,
            format!(
                "not UTF-8 text (an invalid byte at offset {}); is this the right file?",
                e.utf8_error().valid_up_to()
            ),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_text_and_refuses_what_is_not_a_small_text_file() {
        let t = tempfile::tempdir().unwrap();
        let ok = t.path().join("a.toml");
        std::fs::write(&ok, "size = 3\n").unwrap();
        assert_eq!(read_text(&ok).unwrap(), "size = 3\n");

        let kind = |p: &Path| read_text(p).unwrap_err().kind();
        let other = explain_missing(Error::from(ErrorKind::PermissionDenied), "x");
        assert_eq!(other.kind(), ErrorKind::PermissionDenied);
        assert_ne!(other.to_string(), "x");
        assert_eq!(kind(&t.path().join("missing.toml")), ErrorKind::NotFound);
        assert_eq!(kind(t.path()), ErrorKind::IsADirectory);

        let bin = t.path().join("b.toml");
        std::fs::write(&bin, [b'a', 0xff, 0xfe]).unwrap();
        let e = read_text(&bin).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::InvalidData);
        assert!(e.to_string().contains("offset 1"), "{e}");

        // A sparse file just over the bound: refused by its length, nothing read.
        let big = t.path().join("big.toml");
        let f = std::fs::File::create(&big).unwrap();
        f.set_len(MAX_TEXT_BYTES + 1).unwrap();
        let e = read_text(&big).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::InvalidData);
        assert!(e.to_string().contains("too large"), "{e}");
    }

    #[cfg(unix)]
    #[test]
    fn a_device_or_a_fifo_is_refused_at_once() {
        // /dev/zero never ends; a FIFO with no writer would block a plain open.
        assert_eq!(
            read_text(Path::new("/dev/zero")).unwrap_err().kind(),
            ErrorKind::InvalidInput
        );
        let t = tempfile::tempdir().unwrap();
        let fifo = t.path().join("fifo.toml");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        assert_eq!(
            read_text(&fifo).unwrap_err().kind(),
            ErrorKind::InvalidInput
        );
    }
}
