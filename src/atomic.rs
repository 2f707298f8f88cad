//! Durable file replacement: write into a temporary file in the target's directory, flush,
//! fsync, rename over the target, fsync the directory. A crash leaves either the old file or
//! the complete new one, never a partial file under the final name.
//!
//! Only a regular file is ever replaced. A device or a FIFO at the path (or at the end of its
//! symbolic links), or `-` for standard output, is written directly: `surfscan fit … -o
//! /dev/null` leaves `/dev/null` a device. A scan's own files go through
//! [`write_regular_atomically`], which refuses anything but a regular file there.
//!
//! A large file can be written through [`write_atomically_streamed`], which asks the kernel to
//! start writing each MiB to disk as soon as it is written (Linux `sync_file_range`
//! with `SYNC_FILE_RANGE_WRITE`; elsewhere nothing), so the disk works while the rest is
//! still being produced and the final fsync waits only for the tail. The durability is the
//! fsync's, as for every other file: starting writeback early changes only when the disk
//! works, never what is on it.
//!
//! [`write_hint`] turns a failed write into what to do about it (a full disk, a read-only
//! file system, a file where a directory must be).
//!
//! Layer 2 (I/O adapter): depends on std, `libc` (one advisory call on Linux, and the
//! error numbers the hints tell apart) and serde_json (the JSON files written whole).

use std::fs::{self, File};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

fn temp_path(path: &Path) -> io::Result<(PathBuf, PathBuf)> {
    let name = path.file_name().ok_or_else(|| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{} has no file name", path.display()),
        )
    })?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    tmp_name.push(format!(".tmp{}", std::process::id()));
    Ok((dir.join(tmp_name), dir))
}

/// A file under construction, as [`write_impl`] opens it for the body.
trait Target: Write + Sized {
    fn open(file: File) -> Self;
    fn into_file(self) -> File;
}

impl Target for File {
    fn open(file: File) -> Self {
        file
    }
    fn into_file(self) -> File {
        self
    }
}

/// Where a write goes.
enum Destination {
    /// A regular file, or nothing yet: replaced atomically (temporary file and rename).
    Replace(PathBuf),
    /// A device, a FIFO or standard output: written directly, never replaced. The body is
    /// spooled first (it may seek), then copied in one go.
    Stream(File),
}

/// Whether a path's symbolic links are followed to the file they name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Links {
    /// Followed (a user's output path); a device or FIFO at the end is written directly.
    Follow,
    /// Refused, with anything but a regular file (a scan's own files).
    Refuse,
}

/// What writing `path` means: `-` is standard output; a regular file or nothing is replaced;
/// a symbolic link is followed (or refused); a character or block device or a FIFO is
/// written directly (a FIFO without a reader is an error, not a wait); a directory or a
/// socket is refused.
fn destination(path: &Path, links: Links) -> io::Result<Destination> {
    use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
    if path == Path::new("-") && links == Links::Follow {
        let out = io::stdout();
        let fd = std::os::fd::AsFd::as_fd(&out).try_clone_to_owned()?;
        return Ok(Destination::Stream(File::from(fd)));
    }
    let refuse = |what: &str, p: &Path| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{} is {what}", p.display()),
        )
    };
    let mut p = path.to_path_buf();
    for _ in 0..40 {
        let meta = match fs::symlink_metadata(&p) {
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Destination::Replace(p)),
            Err(e) => return Err(e),
            Ok(m) => m,
        };
        let t = meta.file_type();
        if t.is_file() {
            return Ok(Destination::Replace(p));
        }
        if links == Links::Refuse {
            return Err(refuse(
                if t.is_symlink() {
                    "a symbolic link; a scan's files are never written through one"
                } else {
                    "not a regular file; a scan's files are only ever regular files"
                },
                &p,
            ));
        }
        if t.is_symlink() {
            let target = fs::read_link(&p)?;
            p = match p.parent() {
                Some(dir) if target.is_relative() => dir.join(target),
                _ => target,
            };
            continue;
        }
        if t.is_char_device() || t.is_block_device() {
            let f = fs::OpenOptions::new().write(true).open(&p)?;
            return Ok(Destination::Stream(f));
        }
        if t.is_fifo() {
            let f = fs::OpenOptions::new()
                .write(true)
                .custom_flags(libc::O_NONBLOCK)
                .open(&p)
                .map_err(|e| match e.raw_os_error() {
                    Some(libc::ENXIO) => io::Error::new(
                        io::ErrorKind::BrokenPipe,
                        format!(
                            "{} is a FIFO with no reader; start its reader first",
                            p.display()
                        ),
                    ),
                    _ => e,
                })?;
            // Blocking again: the reader takes the bytes at its own pace.
            let fd = std::os::fd::AsRawFd::as_raw_fd(&f);
            // SAFETY: fcntl on a descriptor `f` owns and keeps open for the call.
            unsafe {
                let flags = libc::fcntl(fd, libc::F_GETFL);
                if flags >= 0 {
                    libc::fcntl(fd, libc::F_SETFL, flags & !libc::O_NONBLOCK);
                }
            }
            return Ok(Destination::Stream(f));
        }
        if t.is_dir() {
            return Err(refuse("a directory; give a file's path", &p));
        }
        return Err(refuse("a socket; give a file's path", &p));
    }
    Err(refuse("a loop of symbolic links", path))
}

/// Creates the temporary file exclusively: never through a link planted at its name. A
/// leftover of an earlier process with this pid (a file or a link) is removed first.
fn create_temp(tmp: &Path) -> io::Result<File> {
    let create = || {
        fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(tmp)
    };
    match create() {
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {
            if fs::symlink_metadata(tmp).is_ok_and(|m| !m.is_dir()) {
                fs::remove_file(tmp)?;
            }
            create()
        }
        other => other,
    }
}

/// An unnamed temporary file the body of a direct write is spooled into.
fn spool() -> io::Result<File> {
    use std::os::unix::fs::OpenOptionsExt;
    let dir = std::env::temp_dir();
    match fs::OpenOptions::new()
        .read(true)
        .write(true)
        .custom_flags(libc::O_TMPFILE)
        .open(&dir)
    {
        Ok(f) => Ok(f),
        Err(_) => {
            // A file system without O_TMPFILE: a named file, removed at once.
            let p = dir.join(format!(".surfscan-spool.{}", std::process::id()));
            let f = fs::OpenOptions::new()
                .read(true)
                .write(true)
                .create_new(true)
                .open(&p)?;
            fs::remove_file(&p)?;
            Ok(f)
        }
    }
}

fn write_impl<W: Target, T>(
    path: &Path,
    sync: bool,
    links: Links,
    body: impl FnOnce(&mut BufWriter<W>) -> io::Result<T>,
) -> io::Result<T> {
    let path = match destination(path, links)? {
        Destination::Replace(p) => p,
        Destination::Stream(mut target) => {
            let mut w = BufWriter::with_capacity(1 << 20, W::open(spool()?));
            let value = body(&mut w)?;
            w.flush()?;
            let mut spooled = w.into_inner().map_err(|e| e.into_error())?.into_file();
            io::Seek::seek(&mut spooled, io::SeekFrom::Start(0))?;
            io::copy(&mut spooled, &mut target)?;
            target.flush()?;
            return Ok(value);
        }
    };
    let path = path.as_path();
    let (tmp, dir) = temp_path(path)?;
    let result = (|| {
        let mut w = BufWriter::with_capacity(1 << 20, W::open(create_temp(&tmp)?));
        let value = body(&mut w)?;
        w.flush()?;
        let file = w.into_inner().map_err(|e| e.into_error())?.into_file();
        if sync {
            file.sync_all()?;
        }
        drop(file);
        fs::rename(&tmp, path)?;
        if sync {
            File::open(&dir)?.sync_all()?;
        }
        Ok(value)
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// Writes `path` atomically and durably: `body` writes into a buffered temporary file next to
/// it, which is then flushed, fsynced and renamed over `path`, and the directory is fsynced.
/// On any error the temporary file is removed and `path` is untouched.
pub fn write_atomically<T>(
    path: &Path,
    body: impl FnOnce(&mut BufWriter<File>) -> io::Result<T>,
) -> io::Result<T> {
    write_impl(path, true, Links::Follow, body)
}

/// [`write_atomically`] of `value` as indented JSON ending in a line break.
pub fn write_json_atomically(path: &Path, value: &impl serde::Serialize) -> io::Result<()> {
    write_atomically(path, |w| {
        serde_json::to_writer_pretty(&mut *w, value).map_err(io::Error::other)?;
        w.write_all(b"\n")
    })
}

/// [`write_atomically`] for a scan's own files: the target must be a regular file or
/// nothing; a symbolic link, a device or a FIFO there is refused (a planted link never
/// redirects a scan's write).
pub fn write_regular_atomically<T>(
    path: &Path,
    body: impl FnOnce(&mut BufWriter<File>) -> io::Result<T>,
) -> io::Result<T> {
    write_impl(path, true, Links::Refuse, body)
}

/// Writeback is started once this many bytes have been written since the last start. The
/// final fsync waits for what was written after the last start, so a small step shortens it:
/// on a 21 MB IGES file (`surfscan fit` 31×8000) 1 MiB took the whole process from 45.8 to
/// 43.1 ms (medians of 25 alternating runs) against 8 MiB, and the 853 MB of the 1000×10000
/// fit took the same time within the disk's spread.
const WRITEBACK_BYTES: u64 = 1 << 20;

/// A file that starts writeback of every [`WRITEBACK_BYTES`] written (module docs).
pub struct StreamedFile {
    file: File,
    /// Position of the next write.
    pos: u64,
    /// Bytes before this offset have had their writeback started.
    started: u64,
}

impl StreamedFile {
    /// Starts writeback of `[started, pos)` once it is large enough.
    fn start_writeback(&mut self) {
        if self.pos < self.started + WRITEBACK_BYTES {
            return;
        }
        start_writeback(&self.file, self.started, self.pos - self.started);
        self.started = self.pos;
    }
}

/// Asks the kernel to start writing the dirty pages of `len` bytes at `offset` of `file` to
/// disk, without waiting. Advisory: a failure is ignored, since the fsync that ends every
/// write reports any real error.
#[cfg(target_os = "linux")]
fn start_writeback(file: &File, offset: u64, len: u64) {
    use std::os::fd::AsRawFd;
    let (Ok(offset), Ok(len)) = (i64::try_from(offset), i64::try_from(len)) else {
        return;
    };
    // SAFETY: the descriptor is open (borrowed from `file` for the call); sync_file_range
    // reads no memory of ours and only schedules I/O of pages the file already has.
    let _ = unsafe {
        libc::sync_file_range(file.as_raw_fd(), offset, len, libc::SYNC_FILE_RANGE_WRITE)
    };
}

/// Elsewhere writeback is left to the final fsync.
#[cfg(not(target_os = "linux"))]
fn start_writeback(_file: &File, _offset: u64, _len: u64) {}

impl Target for StreamedFile {
    fn open(file: File) -> Self {
        StreamedFile {
            file,
            pos: 0,
            started: 0,
        }
    }
    fn into_file(self) -> File {
        self.file
    }
}

impl Write for StreamedFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.file.write(buf)?;
        self.pos += n as u64;
        self.start_writeback();
        Ok(n)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.file.flush()
    }
}

impl io::Seek for StreamedFile {
    fn seek(&mut self, to: io::SeekFrom) -> io::Result<u64> {
        // A rewrite behind the started range (a header filled in at the end) is left to the
        // final fsync; writeback goes on from the furthest byte started.
        self.pos = self.file.seek(to)?;
        Ok(self.pos)
    }
}

/// [`write_atomically`] for a large file: the body writes (and may seek) in a
/// [`StreamedFile`], whose writeback starts while the body is still writing (module docs).
pub fn write_atomically_streamed<T>(
    path: &Path,
    body: impl FnOnce(&mut BufWriter<StreamedFile>) -> io::Result<T>,
) -> io::Result<T> {
    write_impl(path, true, Links::Follow, body)
}

/// Like [`write_atomically`] (temporary file and rename) but without the fsyncs: for output
/// that must never be seen half-written but can be made again (the figures, benchmarks).
pub fn write_atomically_without_sync<T>(
    path: &Path,
    body: impl FnOnce(&mut BufWriter<File>) -> io::Result<T>,
) -> io::Result<T> {
    write_impl(path, false, Links::Follow, body)
}

/// What the operator should do after writing `path` (or creating it as a directory) failed
/// with `e`: the cause named where it can be told from the error and the path, instead of a
/// list of everything it might be. A part of the path that is a file where a directory must
/// be is named.
pub fn write_hint(path: &Path, e: &io::Error) -> String {
    match e.raw_os_error() {
        Some(libc::ENOSPC) | Some(libc::EDQUOT) => {
            "the disk (or the quota) is full; free some space".to_string()
        }
        Some(libc::EROFS) => {
            "the file system is read-only; write to another one (for a station, its output.dir)"
                .to_string()
        }
        Some(libc::EACCES) | Some(libc::EPERM) => {
            "permission denied; check who may write the directory".to_string()
        }
        Some(libc::ENOTDIR) | Some(libc::EEXIST) => match not_a_directory(path) {
            Some(file) => format!(
                "{} is {}, not a directory; choose a path under a directory",
                file.display(),
                if file.is_symlink() && !file.exists() {
                    "a link to nothing"
                } else {
                    "a file"
                }
            ),
            None => "check the directory's permissions and free space".to_string(),
        },
        _ => "check the directory's permissions and free space".to_string(),
    }
}

/// The first ancestor of `path` (or `path` itself when a directory was to be made there) that
/// exists and is not a directory.
fn not_a_directory(path: &Path) -> Option<PathBuf> {
    path.ancestors()
        .filter(|p| !p.as_os_str().is_empty())
        .find(|p| p.symlink_metadata().is_ok())
        .filter(|p| !p.is_dir())
        .map(Path::to_path_buf)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_in_the_way_of_a_directory_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("afile");
        fs::write(&file, "x").unwrap();
        // As `fit -o afile/x.igs` meets it (create_dir_all: EEXIST), and a write below it
        // (ENOTDIR).
        let target = file.join("x.igs");
        for e in [
            fs::create_dir_all(&file).unwrap_err(),
            fs::write(&target, "y").unwrap_err(),
        ] {
            assert_eq!(
                write_hint(&target, &e),
                format!(
                    "{} is a file, not a directory; choose a path under a directory",
                    file.display()
                ),
                "{e}"
            );
        }
        let full = io::Error::from_raw_os_error(libc::ENOSPC);
        assert!(write_hint(&target, &full).contains("full"));
        let other = io::Error::from_raw_os_error(libc::EIO);
        assert!(write_hint(&target, &other).contains("permissions and free space"));
    }

    #[test]
    fn replaces_the_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.txt");
        fs::write(&path, "old").unwrap();
        let n = write_atomically(&path, |w| {
            w.write_all(b"new content")?;
            Ok(11)
        })
        .unwrap();
        assert_eq!(n, 11);
        assert_eq!(fs::read_to_string(&path).unwrap(), "new content");
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn a_streamed_file_holds_every_byte_written_and_rewritten_in_place() {
        // Several writeback starts (19 MB in pieces of odd sizes), then a rewrite
        // near the start after seeking back, as the IGES writer fills in its directory.
        use std::io::{Seek, SeekFrom};
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("big.bin");
        fs::write(&path, "old").unwrap();
        let piece: Vec<u8> = (0..1_000_003u32).map(|i| (i % 251) as u8).collect();
        let mut want = Vec::new();
        let len = write_atomically_streamed(&path, |w| {
            for _ in 0..19 {
                w.write_all(&piece)?;
                want.extend_from_slice(&piece);
            }
            w.seek(SeekFrom::Start(10))?;
            w.write_all(b"header")?;
            want[10..16].copy_from_slice(b"header");
            w.seek(SeekFrom::End(0))
        })
        .unwrap();
        assert_eq!(len, want.len() as u64);
        assert!(fs::read(&path).unwrap() == want);
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn a_failed_streamed_write_keeps_the_old_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("big.bin");
        fs::write(&path, "old").unwrap();
        let r: io::Result<()> = write_atomically_streamed(&path, |w| {
            w.write_all(&vec![7u8; 9 << 20])?;
            Err(io::Error::other("disk full"))
        });
        assert!(r.is_err());
        assert_eq!(fs::read_to_string(&path).unwrap(), "old");
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn a_link_is_followed_for_an_output_path_and_refused_for_a_scans_file() {
        use std::os::unix::fs::symlink;
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("real.txt");
        fs::write(&target, "old").unwrap();
        let link = dir.path().join("link.txt");
        symlink("real.txt", &link).unwrap();
        write_atomically(&link, |w| w.write_all(b"new")).unwrap();
        assert!(fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(fs::read_to_string(&target).unwrap(), "new");
        // A dangling link names the file to create; the link stays.
        let dangling = dir.path().join("dangling.txt");
        symlink(dir.path().join("made.txt"), &dangling).unwrap();
        write_atomically(&dangling, |w| w.write_all(b"made")).unwrap();
        assert!(fs::symlink_metadata(&dangling)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(
            fs::read_to_string(dir.path().join("made.txt")).unwrap(),
            "made"
        );
        // A scan's file is never written through a link, to anything.
        let e = write_regular_atomically(&link, |w| w.write_all(b"scan")).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
        assert!(e.to_string().contains("symbolic link"), "{e}");
        assert_eq!(fs::read_to_string(&target).unwrap(), "new");
        assert!(fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        // A directory is refused by name, and nothing is left behind.
        let e = write_atomically(dir.path(), |w| w.write_all(b"x")).unwrap_err();
        assert!(e.to_string().contains("a directory"), "{e}");
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 4);
    }

    #[test]
    fn a_fifo_is_written_into_and_stays_a_fifo() {
        use std::os::unix::fs::FileTypeExt;
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("pipe");
        let c = std::ffi::CString::new(fifo.as_os_str().as_encoded_bytes()).unwrap();
        // SAFETY: mkfifo on a NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        // Without a reader: an error naming what to do, at once (not a wait).
        let e = write_atomically(&fifo, |w| w.write_all(b"x")).unwrap_err();
        assert!(e.to_string().contains("no reader"), "{e}");
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || fs::read(fifo).unwrap())
        };
        // The reader opens the FIFO in its own time; retry until it has.
        let body: Vec<u8> = (0..300_000u32).map(|i| (i % 253) as u8).collect();
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        loop {
            match write_atomically_streamed(&fifo, |w| w.write_all(&body)) {
                Ok(()) => break,
                Err(e) if e.kind() == io::ErrorKind::BrokenPipe => {
                    assert!(std::time::Instant::now() < deadline, "no reader came");
                    std::thread::sleep(std::time::Duration::from_millis(10));
                }
                Err(e) => panic!("{e}"),
            }
        }
        assert!(reader.join().unwrap() == body);
        assert!(fs::symlink_metadata(&fifo).unwrap().file_type().is_fifo());
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn failure_keeps_the_old_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.txt");
        fs::write(&path, "old").unwrap();
        let r: io::Result<()> = write_atomically(&path, |w| {
            w.write_all(b"partial")?;
            Err(io::Error::other("disk full"))
        });
        assert!(r.is_err());
        assert_eq!(fs::read_to_string(&path).unwrap(), "old");
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}
