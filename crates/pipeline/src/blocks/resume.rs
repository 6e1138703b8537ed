//! Resuming a run on a cluster, and keeping a killed run's tasks out of the
//! next one.
//!
//! A run whose passes go to tasks is started with a key (its settings, its
//! input's files and how its slabs are cut, hashed: [`resume_key`]) in its
//! staging folder. A driver killed mid-run (`kill -9`, a lost node, a job's
//! time limit) leaves that folder behind; the next run of the same key takes
//! it over ([`mdtf_volume::OutputFolder::begin_resumable`]), keeps what the
//! tasks wrote (the channel store with the tasks' partials, the pack's
//! texture files: [`keep_task_outputs`]) and writes the rest again. Each
//! task records in its partial which pass it ran (the job's digest, see
//! [`job_digest`]) and a hash of every byte range it wrote (XXH3-128: it
//! finds damage or a write that never happened, at memory speed)
//! ([`WrittenPiece`]); a task that finds its partial with the same job and
//! every range still hashing the same does nothing ([`already_done`]).
//!
//! Each driver writes a new run token into the store ([`new_token`]); a
//! task checks it before it starts and before it publishes its partial
//! ([`check_token`]), so a task a killed driver left running on a worker
//! can no longer publish into the run that took over (what it wrote before
//! is the same bytes the new run's task writes).

use super::partials::SlabPartial;
use super::remote::{SlabJob, SlabPass};
use super::{SlabSize, store};
use crate::run::{RunError, fail};
use crate::settings::Settings;
use mdtf_volume::output::remove_any;
use serde::{Deserialize, Serialize};
use std::io::{Read, Seek, SeekFrom};
use std::ops::Range;
use std::path::{Path, PathBuf};
use twox_hash::XxHash3_128;

/// The file in the channel store holding the current driver's run token.
const TOKEN_FILE: &str = "run.token";

/// Bytes read at a time when hashing what a task wrote.
const HASH_CHUNK: usize = 1 << 22;

/// A byte range of one file a task wrote, and its hash.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct WrittenPiece {
    /// The file.
    pub file: PathBuf,
    /// The byte range written.
    pub bytes: Range<u64>,
    /// XXH3-128 of those bytes, hex.
    pub xxh3: String,
}

/// The key of a run of `s` cut by `size`: mdtf's version, the
/// run's settings with every default filled in, the input's files (names,
/// lengths and modification times: an input rewritten since is another
/// input) and the slab size, hashed (XXH3-128, hex). Two runs of one key
/// make the same tasks with the same outputs.
pub(super) fn resume_key(s: &Settings, size: SlabSize) -> Result<String, RunError> {
    let settings = s.to_table().map_err(fail("plan"))?;
    let mut h = XxHash3_128::new();
    h.write(format!("mdtf {}\n{settings}\n{size:?}\n", env!("CARGO_PKG_VERSION")).as_bytes());
    if let Some(input) = s.input.file() {
        let input = std::path::absolute(input).unwrap_or_else(|_| input.to_path_buf());
        h.write(format!("input {}\n", input.display()).as_bytes());
        for (name, len, modified) in files_of(&input) {
            h.write(format!("{name} {len} {modified}\n").as_bytes());
        }
    }
    Ok(format!("{:032x}", h.finish_128()))
}

/// The files under `path` (itself, when it is a file): each name relative
/// to it, length in bytes and modification time (ns since the epoch), sorted.
fn files_of(path: &Path) -> Vec<(String, u64, u128)> {
    let stamp = |m: &std::fs::Metadata| {
        let modified = m.modified().ok().and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok());
        (m.len(), modified.map_or(0, |d| d.as_nanos()))
    };
    let mut out = Vec::new();
    let mut pending = vec![path.to_path_buf()];
    while let Some(p) = pending.pop() {
        let Ok(meta) = std::fs::metadata(&p) else { continue };
        if meta.is_dir() {
            pending.extend(std::fs::read_dir(&p).into_iter().flatten().flatten().map(|e| e.path()));
        } else {
            let (len, modified) = stamp(&meta);
            let name = p.strip_prefix(path).unwrap_or(&p).to_string_lossy().into_owned();
            out.push((name, len, modified));
        }
    }
    out.sort();
    out
}

/// Empties the staging folder `dir` of a resumed run but for what its
/// tasks wrote (the channel store, with their partials, and the pack's
/// texture data files) and the resume key: the run writes everything else
/// again.
pub(super) fn keep_task_outputs(dir: &Path) -> Result<(), RunError> {
    let io = |p: &Path| {
        let p = p.to_path_buf();
        move |e: std::io::Error| fail("output")(format!("resuming in {}: {e}", p.display()))
    };
    for entry in std::fs::read_dir(dir).map_err(io(dir))? {
        let path = entry.map_err(io(dir))?.path();
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        if name == store::STORE_DIR || name == mdtf_volume::output::RESUME_NAME {
            continue;
        }
        if name == "pack" && std::fs::symlink_metadata(&path).is_ok_and(|m| m.is_dir()) {
            for texture in std::fs::read_dir(&path).map_err(io(&path))? {
                let file = texture.map_err(io(&path))?.path();
                if file.extension().is_none_or(|e| e != "raw") {
                    remove_any(&file).map_err(io(&file))?;
                }
            }
            continue;
        }
        remove_any(&path).map_err(io(&path))?;
    }
    Ok(())
}

/// `error`, which stopped a resumable run in `out`, with the run's partial
/// folder kept for a rerun to resume (and the error saying where).
pub(super) fn kept(out: mdtf_volume::OutputFolder, error: RunError) -> RunError {
    let RunError { stage, error } = error;
    let folder = out.keep_for_resume();
    RunError { stage, error: Box::new(crate::error::StageError::Kept { error, folder }) }
}

/// Whether a task of the run in the staging folder `dir` has finished (left its partial).
pub(super) fn some_task_done(dir: &Path) -> bool {
    let partial = |e: std::fs::DirEntry| e.path().extension().is_some_and(|x| x == "partial");
    std::fs::read_dir(dir.join(store::STORE_DIR)).is_ok_and(|mut d| d.any(|e| e.is_ok_and(partial)))
}

/// A new run token, written into the channel store folder `store` (for
/// [`check_token`]): this process's id, the time and a random hash.
pub(super) fn new_token(store: &Path) -> Result<String, RunError> {
    use std::hash::{BuildHasher, Hasher};
    let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos());
    let mut random = std::collections::hash_map::RandomState::new().build_hasher();
    random.write_u128(nanos);
    let token = format!("{}-{nanos}-{:016x}", std::process::id(), random.finish());
    let path = store.join(TOKEN_FILE);
    mdtf_volume::write_file_atomically(&path, |w| w.write_all(token.as_bytes())).map_err(crate::run::at("output"))?;
    Ok(token)
}

/// Whether `job` still belongs to the run in its store: its token is the
/// one there (the store gone, or a later driver's token, ends the task).
pub(super) fn check_token(job: &SlabJob) -> Result<(), RunError> {
    let stage = job.pass.stage();
    let path = job.store.join(TOKEN_FILE);
    match std::fs::read_to_string(&path) {
        Ok(t) if t == job.token => Ok(()),
        Ok(_) => Err(fail(stage)(format!(
            "this task's run was taken over by a later run of the same output (in {}): its work is dropped",
            job.store.display()
        ))),
        Err(e) if job.store.is_dir() => {
            Err(fail(stage)(format!("this task's run has ended ({}: {e}): its work is dropped", path.display())))
        }
        Err(e) => Err(fail(stage)(format!(
            "the run's channel store {} cannot be read here ({e}): it must be on a file system every worker \
             sees, and the run still going",
            job.store.display()
        ))),
    }
}

/// XXH3-128 (hex) of `job` as its tasks run it, but for its run token: the
/// same pass of a resumed run has the same digest.
pub(super) fn job_digest(job: &SlabJob) -> Result<String, RunError> {
    let job = SlabJob { token: String::new(), ..job.clone() };
    let json = serde_json::to_vec(&job).map_err(|e| fail(job.pass.stage())(format!("a task's job: {e}")))?;
    Ok(format!("{:032x}", XxHash3_128::oneshot(&json)))
}

/// The byte ranges of files the task of `job` on planes `z` writes.
pub(super) fn written_ranges(job: &SlabJob, z: &Range<usize>) -> Vec<(PathBuf, Range<u64>)> {
    let plane = (job.geometry.dims[0] * job.geometry.dims[1]) as u64;
    let planes = |bytes_per_plane: u64| bytes_per_plane * z.start as u64..bytes_per_plane * z.end as u64;
    match &job.pass {
        SlabPass::Pack { textures, .. } => {
            textures.iter().map(|t| (t.file.clone(), planes(t.plane_bytes() as u64))).collect()
        }
        // compressed: each part is the whole of its file, as long as it is
        SlabPass::Keep { channels, parts, .. } => channels
            .iter()
            .map(|&c| super::remote::kept_part(parts, c, z.start))
            .map(|file| {
                let len = std::fs::metadata(&file).map_or(0, |m| m.len());
                (file, 0..len)
            })
            .collect(),
        pass => pass
            .outputs()
            .iter()
            .map(|&c| (job.store.join(store::file_name(c)), planes(plane * store::stored_type(c).size() as u64)))
            .collect(),
    }
}

/// The hashes of what a task wrote, taken from its bytes as it wrote them:
/// per file, one range written in order from its start (a file written
/// out of order, as a tracing strip by strip writes, is read back instead).
#[derive(Default)]
pub(super) struct WriteHashes(Vec<(PathBuf, Range<u64>, XxHash3_128)>);

impl WriteHashes {
    /// Takes in `bytes` written at offset `at` of `file`.
    pub(super) fn add(&mut self, file: &Path, at: u64, bytes: &[u8]) {
        let end = at + bytes.len() as u64;
        match self.0.iter_mut().find(|(f, ..)| f == file) {
            Some((_, range, h)) if range.end == at => {
                h.write(bytes);
                range.end = end;
            }
            Some(_) => self.unordered(file),
            None => {
                let mut h = XxHash3_128::new();
                h.write(bytes);
                self.0.push((file.to_path_buf(), at..end, h));
            }
        }
    }

    /// Marks `file` written out of order (or in pieces): no range of it is
    /// taken from here, so it is read back for its hash.
    pub(super) fn unordered(&mut self, file: &Path) {
        self.0.retain(|(f, ..)| f != file);
        self.0.push((file.to_path_buf(), u64::MAX..u64::MAX, XxHash3_128::new()));
    }

    /// XXH3-128 (hex) of exactly `range` of `file`, if it was written so.
    fn of(&self, file: &Path, range: &Range<u64>) -> Option<String> {
        let (_, _, h) = self.0.iter().find(|(f, r, _)| f == file && r == range)?;
        Some(format!("{:032x}", h.finish_128()))
    }
}

/// The pieces the task of `job` on planes `z` wrote, each hashed: from
/// `hashed` where it hashed the piece as it wrote it, else as the file holds it now.
pub(super) fn hash_written(
    job: &SlabJob,
    z: &Range<usize>,
    hashed: &WriteHashes,
) -> Result<Vec<WrittenPiece>, RunError> {
    let stage = job.pass.stage();
    written_ranges(job, z)
        .into_iter()
        .map(|(file, bytes)| {
            let xxh3 = match hashed.of(&file, &bytes) {
                Some(h) => h,
                None => hash_range(&file, &bytes).map_err(|e| fail(stage)(format!("{}: {e}", file.display())))?,
            };
            Ok(WrittenPiece { file, bytes, xxh3 })
        })
        .collect()
}

/// Whether the task of `job` on planes `z` has run to its end already: its
/// partial is there, of the same job, and every range it wrote still holds
/// what it wrote.
pub(super) fn already_done(job: &SlabJob, z: &Range<usize>) -> bool {
    let Ok(partial) = SlabPartial::read(&job.store, job.pass.name(), z.start) else { return false };
    let Ok(digest) = job_digest(job) else { return false };
    let ranges = written_ranges(job, z);
    let same_job = partial.job == digest
        && partial.written.len() == ranges.len()
        && partial.written.iter().zip(&ranges).all(|(w, (file, bytes))| w.file == *file && w.bytes == *bytes);
    same_job && partial.written.iter().all(|w| hash_range(&w.file, &w.bytes).is_ok_and(|h| h == w.xxh3))
}

/// XXH3-128 (hex) of bytes `range` of `file` (an error if it holds fewer).
fn hash_range(file: &Path, range: &Range<u64>) -> std::io::Result<String> {
    let mut f = std::fs::File::open(file)?;
    f.seek(SeekFrom::Start(range.start))?;
    let mut h = XxHash3_128::new();
    let mut buf = vec![0u8; HASH_CHUNK];
    let mut left = range.end.saturating_sub(range.start);
    while left > 0 {
        let n = (left as usize).min(HASH_CHUNK);
        f.read_exact(&mut buf[..n])?;
        h.write(&buf[..n]);
        left -= n as u64;
    }
    Ok(format!("{:032x}", h.finish_128()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_range_hashes_as_xxh3_128_of_its_bytes_read_in_any_number_of_chunks() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("f");
        let bytes: Vec<u8> = (0..HASH_CHUNK * 2 + 12345).map(|i| (i * 7 % 251) as u8).collect();
        std::fs::write(&file, &bytes).unwrap();
        // xxHash's own test vector: XXH3_128 of no bytes, seed 0
        assert_eq!(hash_range(&file, &(5..5)).unwrap(), "99aa06d3014798d86001c324468d497f");
        let whole = format!("{:032x}", XxHash3_128::oneshot(&bytes[3..]));
        assert_eq!(hash_range(&file, &(3..bytes.len() as u64)).unwrap(), whole);
        let end = bytes.len() as u64;
        assert!(hash_range(&file, &(end - 4..end + 1)).is_err(), "a file too short is not a written range");
    }

    #[test]
    fn a_range_hashed_as_written_equals_the_files_and_one_written_out_of_order_is_not_taken() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("f");
        let bytes: Vec<u8> = (0..50_000).map(|i| (i * 13 % 251) as u8).collect();
        std::fs::write(&file, &bytes).unwrap();
        let mut hashed = WriteHashes::default();
        hashed.add(&file, 100, &bytes[100..7_000]);
        hashed.add(&file, 7_000, &bytes[7_000..40_000]);
        let range = 100..40_000;
        assert_eq!(hashed.of(&file, &range), Some(hash_range(&file, &range).unwrap()));
        assert_eq!(hashed.of(&file, &(100..7_000)), None, "only the whole range written");
        hashed.add(&file, 45_000, &bytes[45_000..]);
        assert_eq!(hashed.of(&file, &range), None, "a gap: the file is read back");
        let mut strips = WriteHashes::default();
        strips.add(&file, 0, &bytes[..100]);
        strips.unordered(&file);
        strips.add(&file, 100, &bytes[100..200]);
        assert_eq!(strips.of(&file, &(0..200)), None, "written in pieces: read back");
    }

    #[test]
    fn a_resumed_folder_keeps_the_store_and_the_texture_data_only() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        for sub in [store::STORE_DIR, "pack", "histogram", "volumes"] {
            std::fs::create_dir(d.join(sub)).unwrap();
        }
        for f in [".slabs/v.f32", "pack/a.raw", "pack/a.nhdr", "pack/manifest.json", "histogram/h.png", "report.html"] {
            std::fs::write(d.join(f), f).unwrap();
        }
        std::fs::write(d.join(mdtf_volume::output::RESUME_NAME), "key").unwrap();
        keep_task_outputs(d).unwrap();
        let mut left: Vec<String> = Vec::new();
        for e in walk(d) {
            left.push(e.strip_prefix(d).unwrap().to_string_lossy().into_owned());
        }
        left.sort();
        assert_eq!(left, [".mdtf-resume", ".slabs/v.f32", "pack/a.raw"]);
    }

    fn walk(d: &Path) -> Vec<PathBuf> {
        let mut out = Vec::new();
        for e in std::fs::read_dir(d).unwrap().flatten() {
            if e.path().is_dir() { out.extend(walk(&e.path())) } else { out.push(e.path()) }
        }
        out
    }
}
