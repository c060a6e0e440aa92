//! Writing a log: appending records to one file (or to it and its copy),
//! and replacing a file whole so that a crash leaves the old one or the
//! new one.

use crate::error::Error;
use crate::format::{encode_record, header, HEADER_LEN, MAX_RECORD};
use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// A log open for appending: one file, or a file and its copy written
/// alike (read back with [`crate::read_copies`]).
pub struct Writer {
    kind: &'static str,
    files: Vec<(File, PathBuf)>,
    /// Bytes in each file.
    length: u64,
    /// Written since the last [`Writer::sync`].
    dirty: bool,
}

impl Writer {
    /// Writes `paths` anew — a header of `kind` at `generation`, then
    /// `payloads` as records — each to a file beside it, fsynced and
    /// renamed over it, one after the other; then opens them for
    /// appending.
    pub fn create<P: AsRef<[u8]>>(
        paths: &[&Path],
        kind: &'static str,
        generation: u64,
        payloads: &[P],
    ) -> Result<Writer, Error> {
        let mut writer = Writer {
            kind,
            files: Vec::new(),
            length: 0,
            dirty: false,
        };
        let paths: Vec<PathBuf> = paths.iter().map(|p| p.to_path_buf()).collect();
        writer.write_anew(&paths, generation, payloads)?;
        Ok(writer)
    }

    /// Opens `paths` (each read whole up to `end`, e.g.
    /// [`crate::Contents::end`]) for appending after byte `end`, cutting
    /// off what follows it.
    pub fn resume(paths: &[&Path], kind: &'static str, end: u64) -> Result<Writer, Error> {
        let mut files = Vec::new();
        for path in paths {
            let io = Error::io(path);
            let file = OpenOptions::new()
                .append(true)
                .open(path)
                .and_then(|file| {
                    if file.metadata()?.len() != end {
                        file.set_len(end)?;
                        file.sync_all()?;
                    }
                    Ok(file)
                })
                .map_err(io)?;
            files.push((file, path.to_path_buf()));
        }
        Ok(Writer {
            kind,
            files,
            length: end,
            dirty: false,
        })
    }

    /// Replaces the files by new ones holding `payloads` at `generation`
    /// (as [`Writer::create`]); appends go to them from then on.
    pub fn replace<P: AsRef<[u8]>>(
        &mut self,
        generation: u64,
        payloads: &[P],
    ) -> Result<(), Error> {
        let paths: Vec<PathBuf> = self.files.iter().map(|(_, p)| p.clone()).collect();
        self.write_anew(&paths, generation, payloads)
    }

    fn write_anew<P: AsRef<[u8]>>(
        &mut self,
        paths: &[PathBuf],
        generation: u64,
        payloads: &[P],
    ) -> Result<(), Error> {
        let Some(first) = paths.first() else {
            return Ok(());
        };
        let body = body(self.kind, generation, payloads, first)?;
        let mut files = Vec::with_capacity(paths.len());
        for path in paths {
            write_durably(path, &body).map_err(Error::io(path))?;
            let file = OpenOptions::new()
                .append(true)
                .open(path)
                .map_err(Error::io(path))?;
            files.push((file, path.clone()));
        }
        self.files = files;
        self.length = body.len() as u64;
        self.dirty = false;
        Ok(())
    }

    /// Appends one record whose payload is `parts` one after the other,
    /// written through to the file(s) (not fsynced: [`Writer::sync`]).
    pub fn append(&mut self, parts: &[&[u8]]) -> Result<(), Error> {
        let size: usize = parts.iter().map(|p| p.len()).sum();
        self.check_size(size)?;
        let mut bytes = Vec::with_capacity(crate::RECORD_HEAD + size);
        encode_record(parts, &mut bytes);
        self.write(&bytes)
    }

    /// Appends `payloads` as records, in one write per file.
    pub fn append_all<P: AsRef<[u8]>>(&mut self, payloads: &[P]) -> Result<(), Error> {
        let mut bytes = Vec::new();
        for payload in payloads {
            self.check_size(payload.as_ref().len())?;
            encode_record(&[payload.as_ref()], &mut bytes);
        }
        self.write(&bytes)
    }

    fn check_size(&self, size: usize) -> Result<(), Error> {
        if size > MAX_RECORD as usize {
            return Err(Error::TooLarge {
                path: self.path().to_path_buf(),
                bytes: size,
            });
        }
        Ok(())
    }

    fn write(&mut self, bytes: &[u8]) -> Result<(), Error> {
        if bytes.is_empty() {
            return Ok(());
        }
        for (file, path) in &mut self.files {
            file.write_all(bytes).map_err(Error::io(path))?;
        }
        self.length += bytes.len() as u64;
        self.dirty = true;
        Ok(())
    }

    /// fsyncs what was written since the last sync (every file).
    pub fn sync(&mut self) -> Result<(), Error> {
        if self.dirty {
            for (file, path) in &self.files {
                file.sync_data().map_err(Error::io(path))?;
                counted_fsync();
            }
            self.dirty = false;
        }
        Ok(())
    }

    /// Bytes in the file (each copy holds as many).
    pub fn len(&self) -> u64 {
        self.length
    }

    /// Whether it holds no record.
    pub fn is_empty(&self) -> bool {
        self.length <= HEADER_LEN as u64
    }

    /// The (first) file's path.
    pub(crate) fn path(&self) -> &Path {
        self.files.first().map_or(Path::new(""), |(_, p)| p)
    }
}

/// A whole file's bytes: the header and the records.
fn body<P: AsRef<[u8]>>(
    kind: &'static str,
    generation: u64,
    payloads: &[P],
    path: &Path,
) -> Result<Vec<u8>, Error> {
    let mut body = header(kind, generation).to_vec();
    for payload in payloads {
        let payload = payload.as_ref();
        if payload.len() > MAX_RECORD as usize {
            return Err(Error::TooLarge {
                path: path.to_path_buf(),
                bytes: payload.len(),
            });
        }
        encode_record(&[payload], &mut body);
    }
    Ok(body)
}

/// Removes the file at `path`; none there is no error (a role's file
/// forgotten whether or not it was ever written).
pub fn remove_file(path: &Path) -> Result<(), Error> {
    match std::fs::remove_file(path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(Error::io(path)(e)),
        _ => Ok(()),
    }
}

/// Writes `path` whole — a header of `kind` at `generation` and
/// `payloads` as records — so that a crash leaves the old file or the new
/// one; returns its size. A snapshot is one such file of one record.
pub fn write_file<P: AsRef<[u8]>>(
    path: &Path,
    kind: &'static str,
    generation: u64,
    payloads: &[P],
) -> Result<u64, Error> {
    let body = body(kind, generation, payloads, path)?;
    write_durably(path, &body).map_err(Error::io(path))?;
    Ok(body.len() as u64)
}

/// Writes `body` to `path` so that a crash leaves the old file or the new
/// one, whole: a temporary file beside it, fsynced, renamed over it, the
/// folder fsynced (the rename is durable once the folder is).
fn write_durably(path: &Path, body: &[u8]) -> std::io::Result<()> {
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty());
    if let Some(dir) = dir {
        std::fs::create_dir_all(dir)?;
    }
    let mut temporary = path.as_os_str().to_owned();
    temporary.push(".tmp");
    let temporary = PathBuf::from(temporary);
    let mut file = File::create(&temporary)?;
    file.write_all(body)?;
    file.sync_all()?;
    counted_fsync();
    std::fs::rename(&temporary, path)?;
    if let Some(dir) = dir {
        File::open(dir)?.sync_all()?;
        counted_fsync();
    }
    Ok(())
}

/// fsyncs this process made through this crate (files and their
/// folders), for the counters a deployment's cost is measured by.
static FSYNCS: AtomicU64 = AtomicU64::new(0);

fn counted_fsync() {
    FSYNCS.fetch_add(1, Ordering::Relaxed);
}

/// How many fsyncs this process has made through this crate so far.
pub fn fsyncs() -> u64 {
    FSYNCS.load(Ordering::Relaxed)
}
