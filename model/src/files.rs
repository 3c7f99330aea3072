//! Files as kinegen writes them: never half-written (a temporary in the same
//! directory, renamed into place; removed on a signal), and the spec files of a
//! directory. Used by every stage that writes (the generated crate, reports,
//! logs, specs), so it lives below them all.
use std::path::{Path, PathBuf};

/// A file that could not be written, named as the user asked for it.
#[derive(Debug, thiserror::Error)]
#[error("{}: {source}", path.display())]
pub struct WriteError {
    pub path: PathBuf,
    pub source: std::io::Error,
}

fn err(path: &Path) -> impl FnOnce(std::io::Error) -> WriteError + '_ {
    move |source| WriteError {
        path: path.to_path_buf(),
        source,
    }
}

/// The most bytes kinegen reads from one input file: a quarter of the
/// machine's memory (from /proc/meminfo), at least 1 GiB; 8 GiB where the
/// machine does not say; `KINEGEN_INPUT_LIMIT_MB` sets another. What is read is held in memory (a few times its
/// size once parsed), so an input past this would exhaust the machine.
pub fn input_limit() -> u64 {
    const GIB: u64 = 1 << 30;
    // a smaller limit for tests and shared machines
    if let Some(mb) = std::env::var("KINEGEN_INPUT_LIMIT_MB")
        .ok()
        .and_then(|v| v.parse::<u64>().ok())
    {
        return mb << 20;
    }
    let total_kib = std::fs::read_to_string("/proc/meminfo").ok().and_then(|m| {
        m.lines()
            .find(|l| l.starts_with("MemTotal:"))
            .and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
    });
    match total_kib {
        Some(k) => (k * 1024 / 4).max(GIB),
        None => 8 * GIB,
    }
}

/// A reader that fails, naming the limit, once more than `limit` bytes have
/// come through: a pipe or a device that never ends stops there.
pub struct Bounded<R> {
    inner: R,
    left: u64,
    limit: u64,
}

impl<R: std::io::Read> std::io::Read for Bounded<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        if n as u64 > self.left {
            return Err(std::io::Error::other(format!(
                "more than {} MiB: kinegen reads at most that from one input (a quarter of this machine's memory, or KINEGEN_INPUT_LIMIT_MB): is it a device or a pipe that never ends?",
                self.limit >> 20
            )));
        }
        self.left -= n as u64;
        Ok(n)
    }
}

/// `path` opened to be read through [`Bounded`]: a regular file larger than
/// [`input_limit`] is refused before any byte is read.
pub fn open_bounded(path: &Path) -> std::io::Result<Bounded<std::fs::File>> {
    let limit = input_limit();
    let file = std::fs::File::open(path)?;
    if let Ok(m) = file.metadata() {
        if m.is_file() && m.len() > limit {
            return Err(std::io::Error::other(format!(
                "{} MiB, more than the {} MiB kinegen reads from one input (a quarter of this machine's memory)",
                m.len() >> 20,
                limit >> 20
            )));
        }
    }
    Ok(Bounded {
        inner: file,
        left: limit,
        limit,
    })
}

/// A file's bytes, read through [`open_bounded`].
pub fn read_bounded(path: &Path) -> std::io::Result<Vec<u8>> {
    let mut bytes = Vec::new();
    std::io::Read::read_to_end(&mut open_bounded(path)?, &mut bytes)?;
    Ok(bytes)
}

/// A text file's contents. Err: (where the first byte that is not UTF-8 is,
/// as a 1-based line and column, if that is the trouble; the message).
pub fn read_text(path: &Path) -> Result<String, (Option<(usize, usize)>, String)> {
    let bytes = read_bounded(path).map_err(|e| (None, e.to_string()))?;
    String::from_utf8(bytes).map_err(|e| {
        let bytes = e.as_bytes();
        let ok = &bytes[..e.utf8_error().valid_up_to()];
        let line = ok.iter().filter(|&&b| b == b'\n').count() + 1;
        let start = ok.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
        let column = std::str::from_utf8(&ok[start..]).map_or(1, |s| s.chars().count() + 1);
        let byte = bytes[ok.len()];
        (
            Some((line, column)),
            format!("not UTF-8 text (byte 0x{byte:02x})"),
        )
    })
}

/// [`read_text`]'s error for people: "line L, column C: why" where it has a
/// place, else the reason alone.
pub fn unreadable((at, why): (Option<(usize, usize)>, String)) -> String {
    match at {
        Some((line, column)) => format!("line {line}, column {column}: {why}"),
        None => why,
    }
}

/// Spec files (`*.toml`) directly in `dir`, sorted.
pub fn spec_files(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    v.sort();
    Ok(v)
}

/// Temporary files being written now, so a signal handler can remove them
/// (`remove_temporaries`): a run interrupted while writing leaves nothing behind.
static TEMPORARIES: std::sync::Mutex<Vec<std::path::PathBuf>> = std::sync::Mutex::new(Vec::new());

fn temporaries() -> std::sync::MutexGuard<'static, Vec<std::path::PathBuf>> {
    // a panic elsewhere while holding the lock leaves the list itself intact
    TEMPORARIES.lock().unwrap_or_else(|e| e.into_inner())
}

/// `std::fs::write`, except that with `KINEGEN_TEST_WRITE_PAUSE_MS=N` in the
/// environment it writes half, pauses N ms, then writes the rest: the one way a
/// test can interrupt a write at a known moment (the cleanup on signals is
/// otherwise untestable, the window being microseconds wide).
fn write_slowly_if_asked(tmp: &Path, content: &str) -> std::io::Result<()> {
    use std::io::Write;
    let pause = std::env::var("KINEGEN_TEST_WRITE_PAUSE_MS")
        .ok()
        .and_then(|v| v.parse::<u64>().ok());
    let Some(ms) = pause else {
        return std::fs::write(tmp, content);
    };
    let mut f = std::fs::File::create(tmp)?;
    let half = content.len() / 2;
    f.write_all(&content.as_bytes()[..half])?;
    f.flush()?;
    std::thread::sleep(std::time::Duration::from_millis(ms));
    f.write_all(&content.as_bytes()[half..])
}

/// Remove every temporary file a `write_atomic` in this process is writing
/// (from the CLI's SIGINT/SIGTERM/SIGHUP handler).
pub fn remove_temporaries() {
    for p in temporaries().drain(..) {
        let _ = std::fs::remove_file(p);
    }
}

/// Where an output path leads, and so how it is written.
enum Target {
    /// A regular file, or none yet: written atomically at this path (a
    /// symbolic link's final target, so the link stays a link).
    File(PathBuf),
    /// A device, a pipe or a socket (/dev/null, /dev/stdout, a FIFO): written
    /// in place. Renaming a temporary over it would replace the device with a
    /// regular file.
    Stream,
}

/// Classify `path` for [`write_atomic`]; a regular file that is read-only
/// (no write permission bit) is refused even where the user could override
/// it (root): a read-only output is someone's decision not to have it
/// replaced.
fn target(path: &Path) -> Result<Target, WriteError> {
    let Ok(meta) = std::fs::metadata(path) else {
        // none yet, or a dangling link: written where the link points, if it
        // is one, else here
        return Ok(Target::File(
            std::fs::read_link(path).map_or_else(|_| path.to_path_buf(), |t| resolve(path, &t)),
        ));
    };
    if !meta.is_file() {
        return if meta.is_dir() {
            Err(err(path)(std::io::Error::new(
                std::io::ErrorKind::IsADirectory,
                "is a directory",
            )))
        } else {
            Ok(Target::Stream)
        };
    }
    if meta.permissions().readonly() {
        return Err(err(path)(std::io::Error::new(
            std::io::ErrorKind::PermissionDenied,
            "is read-only: kinegen does not replace it (make it writable, or choose another path)",
        )));
    }
    Ok(Target::File(
        std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf()),
    ))
}

/// Remove the temporaries of `path` that a process killed while writing it
/// left in `dir` (SIGKILL cannot be caught: `.index.html.PID-N.kinegen-tmp`
/// stayed behind in 3 of 5 tries). A temporary's name carries its writer's
/// process id; one whose process no longer runs is stale. Where /proc does
/// not tell (not Linux), nothing is removed.
fn sweep_stale(dir: &Path, path: &Path) {
    let proc = Path::new("/proc/self");
    if !proc.exists() {
        return;
    }
    let Some(name) = path.file_name().map(|n| n.to_string_lossy().to_string()) else {
        return;
    };
    let prefix = format!(".{name}.");
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let file = e.file_name().to_string_lossy().to_string();
        let Some(rest) = file
            .strip_prefix(&prefix)
            .and_then(|r| r.strip_suffix(".kinegen-tmp"))
        else {
            continue;
        };
        let Some(pid) = rest
            .split_once('-')
            .and_then(|(p, _)| p.parse::<u32>().ok())
        else {
            continue;
        };
        if pid != std::process::id() && !Path::new("/proc").join(pid.to_string()).exists() {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

/// A link target `t` read from `link`, relative to the link's directory.
fn resolve(link: &Path, t: &Path) -> PathBuf {
    link.parent().unwrap_or(Path::new(".")).join(t)
}

/// Write via a temporary file in the same directory and rename, so a reader never
/// sees a half-written file. Through a symbolic link the file it points to is
/// replaced (the link stays); a device or a pipe is written in place, and its
/// write errors (/dev/full) are reported; a read-only file is refused.
pub fn write_atomic(path: &Path, content: &str) -> Result<(), WriteError> {
    let asked = path;
    let path = match target(path)? {
        Target::File(p) => p,
        Target::Stream => {
            use std::io::Write;
            let mut f = std::fs::OpenOptions::new()
                .write(true)
                .open(path)
                .map_err(err(path))?;
            return f
                .write_all(content.as_bytes())
                .and_then(|()| f.flush())
                .map_err(err(path));
        }
    };
    let path = path.as_path();
    let dir = path.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(err(dir))?;
    // unique per writer, so concurrent writers of the same file never share a temp file
    static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = dir.join(format!(
        ".{}.{}-{n}.kinegen-tmp",
        path.file_name().unwrap().to_string_lossy(),
        std::process::id()
    ));
    sweep_stale(dir, path);
    temporaries().push(tmp.clone());
    // errors name the file the user asked for, not the temporary one
    let done = write_slowly_if_asked(&tmp, content).and_then(|()| std::fs::rename(&tmp, path));
    if done.is_err() {
        let _ = std::fs::remove_file(&tmp); // never leave a half-written temporary
    }
    temporaries().retain(|p| p != &tmp);
    done.map_err(err(asked))
}

#[cfg(test)]
mod bounded_tests {
    use super::*;
    use std::io::Read;

    #[test]
    fn a_reader_past_its_limit_fails_naming_it() {
        let mut r = Bounded {
            inner: std::io::repeat(b'x'),
            left: 1000,
            limit: 1000,
        };
        let mut out = Vec::new();
        let e = r.read_to_end(&mut out).unwrap_err();
        assert!(e.to_string().contains("more than"), "{e}");
        assert!(out.len() <= 1000);
    }
}
