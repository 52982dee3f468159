//! Fingerprints of sources, so a cache or a database can tell when its footage changed.
//!
//! A file's fingerprint is its length and the SHA-256 of its content. An image sequence (a
//! directory or a printf pattern such as `frames/%04d.png`, as [`crate::open`] reads it)
//! is fingerprinted over its frame files in playing order, each as its name, its content
//! and its length, so renaming, reordering, adding, removing or editing any frame changes
//! the hash.

use std::io::Read;
use std::path::Path;

use sha2::{Digest, Sha256};

use crate::error::{MediaError, Result};

/// `(bytes, sha256 hex)` of the source at `path`: a file, or an image sequence's frames
/// (module doc). Fails as [`crate::source_files`] does, or when a file cannot be read.
pub fn source_fingerprint(path: &Path) -> Result<(u64, String)> {
    let files = crate::read::source_files(path)?;
    let sequence = files.len() != 1 || files[0] != path;
    let mut h = Sha256::new();
    let mut buf = vec![0u8; 1 << 20];
    let mut total = 0u64;
    for file in &files {
        let mut f = std::fs::File::open(file).map_err(|e| MediaError::io(file, e))?;
        if sequence {
            let name = file
                .file_name()
                .map(|n| n.to_string_lossy())
                .unwrap_or_default();
            h.update((name.len() as u64).to_le_bytes());
            h.update(name.as_bytes());
        }
        let mut len = 0u64;
        loop {
            let n = f.read(&mut buf).map_err(|e| MediaError::io(file, e))?;
            if n == 0 {
                break;
            }
            h.update(&buf[..n]);
            len += n as u64;
        }
        if sequence {
            h.update(len.to_le_bytes());
        }
        total += len;
    }
    let hex = h.finalize().iter().map(|b| format!("{b:02x}")).collect();
    Ok((total, hex))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A file hashes as its content; a sequence's hash changes with any frame's content,
    /// name or presence, and a directory and its pattern give the same fingerprint.
    #[test]
    fn sequences_hash_their_frames_in_order() {
        let t = tempfile::tempdir().unwrap();
        let size = ignis_core::Size::new(4, 3).unwrap();
        let frame = |v: f32| ignis_core::RgbaFrame::filled(size, [v, v, v, 1.0]);
        for (i, v) in [0.1, 0.5, 0.9].iter().enumerate() {
            crate::write_png(&t.path().join(format!("{i:04}.png")), &frame(*v)).unwrap();
        }
        let one = t.path().join("0000.png");
        let (n, sha) = source_fingerprint(&one).unwrap();
        let bytes = std::fs::read(&one).unwrap();
        assert_eq!(n, bytes.len() as u64);
        let want: String = Sha256::digest(&bytes)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        assert_eq!(sha, want);
        let pattern = t.path().join("%04d.png");
        let a = source_fingerprint(&pattern).unwrap();
        assert_eq!(a, source_fingerprint(t.path()).unwrap());
        // One frame's content changed (same length or not): a new hash.
        crate::write_png(&t.path().join("0001.png"), &frame(0.6)).unwrap();
        let b = source_fingerprint(&pattern).unwrap();
        assert_ne!(a.1, b.1);
        // A frame removed: a new hash; no frames at all: an error.
        std::fs::remove_file(t.path().join("0002.png")).unwrap();
        assert_ne!(b.1, source_fingerprint(&pattern).unwrap().1);
        assert!(source_fingerprint(&t.path().join("x%04d.png")).is_err());
    }
}
