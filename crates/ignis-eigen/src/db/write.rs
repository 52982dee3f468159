//! Writing a database: [`DbWriter`] fills a temporary directory beside the target (arrays,
//! packs, manifest and its checksum sidecar) and commits it in one directory exchange.

use super::{manifest_sum_text, sha256_hex, FileEntry, Manifest, PackEntry, MANIFEST_SUM};
use crate::error::{EigenError, Result};
use ignis_core::progress::Progress;
use ignis_core::Size;
use ignis_pca::npy::{self, Dtype, NpyWriter};
use std::path::{Path, PathBuf};

/// Writes a database: every file goes to a temporary directory beside the target
/// ([`temp_dir_for`]); [`DbWriter::finish`] writes the manifest and its checksum sidecar and
/// puts the directory in place ([`commit_dir`]). Dropped unfinished, the temporary
/// directory is removed and the target is untouched.
pub struct DbWriter {
    tmp: PathBuf,
    target: PathBuf,
    done: bool,
    /// The temporary directory, registered for removal on an interrupt until the commit
    /// ([`ignis_core::tempfiles::track`]).
    live: Option<ignis_core::tempfiles::Live>,
}

impl DbWriter {
    /// Starts a database that will replace `target` (see [`commit_dir`] for what may be
    /// replaced).
    pub fn create(target: &Path) -> Result<DbWriter> {
        let tmp = temp_dir_for(target)?;
        let live = Some(ignis_core::tempfiles::track(&tmp, true));
        Ok(DbWriter {
            tmp,
            target: target.to_path_buf(),
            done: false,
            live,
        })
    }

    /// The temporary directory (files written there are not listed until hashed with
    /// [`DbWriter::entry`]).
    pub fn dir(&self) -> &Path {
        &self.tmp
    }

    /// A streaming writer for the array `rel` (`frames/<clip>.npy`, scratch data).
    pub fn array(&self, rel: &str, dtype: Dtype, shape: &[usize]) -> Result<NpyWriter> {
        Ok(NpyWriter::create(&self.tmp.join(rel), dtype, shape)?)
    }

    /// Writes the f32 array `rel` of `shape` and returns its manifest entry.
    pub fn write_f32(&self, rel: &str, data: &[f32], shape: &[usize]) -> Result<FileEntry> {
        npy::write_f32(&self.tmp.join(rel), data, shape, false)?;
        self.entry(rel)
    }

    /// Writes the f64 array `rel` of `shape` and returns its manifest entry.
    pub fn write_f64(&self, rel: &str, data: &[f64], shape: &[usize]) -> Result<FileEntry> {
        npy::write_f64(&self.tmp.join(rel), data, shape, false)?;
        self.entry(rel)
    }

    /// Writes the bytes `rel` (e.g. `masks/<clip>.rle`) and returns its manifest entry.
    pub fn write_bytes(&self, rel: &str, bytes: &[u8]) -> Result<FileEntry> {
        let path = self.tmp.join(rel);
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).map_err(|e| EigenError::io(dir, e))?;
        }
        std::fs::write(&path, bytes).map_err(|e| EigenError::io(&path, e))?;
        self.entry(rel)
    }

    /// The manifest entry (size, SHA-256) of a finished file `rel`.
    pub fn entry(&self, rel: &str) -> Result<FileEntry> {
        file_entry(&self.tmp, rel)
    }

    /// Writes the Eigenfires (the columns of `components`, each a `size` image) as packs
    /// of `pack_size` (§4.8): `packs/pack_001.npy`, ... One progress step per pack.
    pub fn write_packs(
        &self,
        components: faer::MatRef<'_, f32>,
        pack_size: usize,
        size: Size,
        progress: &mut dyn Progress,
    ) -> Result<Vec<PackEntry>> {
        let (k, n) = (components.ncols(), components.nrows());
        let (h, w) = (size.height as usize, size.width as usize);
        let mut packs = Vec::new();
        for (pi, first) in (0..k).step_by(pack_size.max(1)).enumerate() {
            let count = pack_size.min(k - first);
            let rel = format!("packs/pack_{:03}.npy", pi + 1);
            let mut wr = self.array(&rel, Dtype::F32, &[count, h, w])?;
            for i in first..first + count {
                let col = components.col(i);
                let v: Vec<f32> = (0..n).map(|r| col[r]).collect();
                wr.write_f32(&v)?;
            }
            wr.finish()?;
            packs.push(PackEntry {
                entry: self.entry(&rel)?,
                first,
                count,
            });
            progress.inc(1);
        }
        Ok(packs)
    }

    /// Writes `manifest` and its checksum sidecar ([`MANIFEST_SUM`]) and replaces the
    /// target by the finished directory.
    pub fn finish(mut self, manifest: &Manifest) -> Result<PathBuf> {
        let text = serde_json::to_string_pretty(manifest).map_err(|e| EigenError::Database {
            db: self.target.clone(),
            file: "manifest.json".into(),
            reason: format!("cannot serialise: {e}"),
        })?;
        let write = |name: &str, bytes: &[u8]| {
            let p = self.tmp.join(name);
            ignis_core::atomic::write_bytes(&p, bytes).map_err(|e| EigenError::io(&p, e))
        };
        write("manifest.json", text.as_bytes())?;
        write(MANIFEST_SUM, manifest_sum_text(text.as_bytes()).as_bytes())?;
        self.live.take();
        commit_dir(&self.tmp, &self.target)?;
        self.done = true;
        Ok(self.target.clone())
    }
}

impl Drop for DbWriter {
    fn drop(&mut self) {
        if !self.done {
            let _ = std::fs::remove_dir_all(&self.tmp);
        }
    }
}

/// Hashes a file and returns its manifest entry.
pub fn file_entry(dir: &Path, rel: &str) -> Result<FileEntry> {
    let p = dir.join(rel);
    let bytes = std::fs::read(&p).map_err(|e| EigenError::io(&p, e))?;
    Ok(FileEntry {
        file: rel.into(),
        bytes: bytes.len() as u64,
        sha256: sha256_hex(&bytes),
    })
}

/// Atomically replaces `target` by the directory `tmp` (same parent): one
/// `renameat2(RENAME_EXCHANGE)` where available (the name always holds a complete
/// database), else two renames with recovery on the next run; see
/// [`ignis_core::tempfiles::replace_dir`]. Refuses to replace a non-empty directory that
/// is not an Eigenfire database, and anything that is not a directory.
pub fn commit_dir(tmp: &Path, target: &Path) -> Result<()> {
    check_replaceable(target)?;
    ignis_core::tempfiles::replace_dir(tmp, target).map_err(|e| EigenError::io(target, e))
}

/// Refuses a `target` that a database may not replace: a non-empty directory that is not
/// an Eigenfire database, or anything that is not a directory (footage named as the
/// output, say).
pub fn check_replaceable(target: &Path) -> Result<()> {
    if let Ok(md) = std::fs::symlink_metadata(target) {
        let not_db = !md.is_dir()
            || (!target.join("manifest.json").exists()
                && target
                    .read_dir()
                    .map(|mut d| d.next().is_some())
                    .unwrap_or(true));
        if not_db {
            return Err(EigenError::bad(
                "output",
                format!(
                    "{} exists and is not an Eigenfire database; refusing to replace it \
                     (choose another output name)",
                    target.display()
                ),
            ));
        }
    }
    Ok(())
}

/// A temporary directory beside `target` for an atomic write
/// (`.<name>.ignis-tmp-<pid>.dir`). Stale temporaries of killed runs in that directory are
/// removed first (and a database moved aside by an interrupted replacement is recovered).
pub fn temp_dir_for(target: &Path) -> Result<PathBuf> {
    let parent = match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&parent).map_err(|e| EigenError::io(&parent, e))?;
    ignis_core::tempfiles::recover_and_clean(&parent);
    let name = target
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "db".into());
    let tmp = parent.join(ignis_core::tempfiles::temp_name(&name, "dir"));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(|e| EigenError::io(&tmp, e))?;
    }
    std::fs::create_dir_all(tmp.join("packs")).map_err(|e| EigenError::io(&tmp, e))?;
    std::fs::create_dir_all(tmp.join("frames")).map_err(|e| EigenError::io(&tmp, e))?;
    Ok(tmp)
}
