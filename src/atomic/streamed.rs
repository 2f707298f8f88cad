//! A large file written in 1 MiB chunks from an aligned buffer of its own, with `O_DIRECT`
//! where the file system takes it, so the bytes go from this buffer to the device without a
//! copy into the page cache, and the fsync that ends the file finds almost nothing left to
//! write. On this machine's disk 21 MiB in 1 MiB writes took 9.4 ms (5.4 ms CPU) then a
//! 10.5 ms fsync buffered, writeback started per MiB, and 10.0 ms (1.6 ms CPU: the rest is
//! waiting on the device) then a 2.3 ms fsync with `O_DIRECT` (medians of 21 alternating
//! runs, host load 1.5).
//!
//! `O_DIRECT` asks every write to start at a multiple of the device's logical block, to be a
//! multiple of it long, and to come from memory aligned to it. [`ALIGN`] = 4096 is used
//! rather than asking the device: it is a multiple of every common logical block (512 or
//! 4096 bytes) and the block of ext4 and XFS as made by default, so an extending write never
//! zeroes part of a file-system block either. A device that needs more refuses the first
//! write with `EINVAL`, and the file is written buffered (below). The buffer is a `Vec<u8>`
//! allocated [`ALIGN`] bytes larger than needed, used from its first aligned byte; it never
//! grows, so its address never moves.
//!
//! The file's bytes are exactly those written, wherever the writes go:
//! - bytes from the end of the last full chunk on stay in memory until the chunk fills or
//!   [`Write::flush`] writes it, padded with zeros to the next [`ALIGN`] multiple, and the
//!   file is then cut to its length (`set_len`: a change of the file's size, which the fsync
//!   that follows makes durable with the data; a second, buffered descriptor for the tail
//!   would do as well but adds a second path to the same bytes);
//! - a rewrite behind the chunk (the IGES writer fills in its directory at the end) reads
//!   each [`ALIGN`] block it touches, changes it and writes it back.
//!
//! A direct write returns only once the device has the bytes (about 0.4 ms a MiB here), so
//! from the second full chunk on, each is written by a thread of its own while the next one
//! fills the second buffer; the first is written in place, so that a refusal is seen before
//! anything else is in flight. Every synchronous write, rewrite and flush first waits for the
//! chunk in flight and reports its error. `surfscan fit` of a 31×8000 grid to this disk, 101
//! alternating runs of each binary, twice, host load 5.8: 48.9 → 45.7 and 47.5 → 42.9 ms
//! wall; with the chunks written in place instead of on the thread, the gain was within the
//! runs' spread (46.4 → 47.5 ms, 51 runs).
//!
//! Fallback: where `open` with `O_DIRECT` fails or the first direct write fails with
//! `EINVAL` (a file system or device that does not take it), `O_DIRECT` is cleared on the
//! same descriptor and the same chunks are written buffered, the kernel asked to start each
//! chunk's writeback as soon as it is written (Linux `sync_file_range` with
//! `SYNC_FILE_RANGE_WRITE`), so the disk works while the rest is produced. Either way the
//! durability is the fsync's that [`super::write_atomically_streamed`] makes before the
//! rename: `O_DIRECT` bypasses the page cache, not the device's cache.
//!
//! By hand rather than through a crate: it is std's positional reads and writes over an
//! aligned slice of a `Vec`, one `fcntl` and one channel, and it must rewrite bytes behind
//! (the IGES directory), which a plain aligned writer does not.
//!
//! Layer 2 (I/O adapter): depends on std, `libc` and `nix` (the open flag, `fcntl`,
//! `sync_file_range`) and `tracing` (the fallback, at debug level).

use std::fs::{self, File};
use std::io::{self, Seek, SeekFrom, Write};
use std::os::unix::fs::FileExt;
use std::path::Path;
use std::sync::mpsc;

/// Alignment of every direct write's offset, length and memory (module docs).
pub const ALIGN: usize = 4096;
/// Bytes held and written at a time: a multiple of [`ALIGN`].
const CHUNK: usize = 1 << 20;

/// [`CHUNK`] bytes and a scratch block of [`ALIGN`] (a rewrite's), from an aligned address.
struct Chunk {
    /// [`ALIGN`] bytes larger than used, never grown: its address never moves.
    mem: Vec<u8>,
    /// Offset of the first aligned byte of `mem`.
    start: usize,
}

impl Chunk {
    fn new() -> Chunk {
        let mem = vec![0u8; CHUNK + 2 * ALIGN];
        let start = (ALIGN - mem.as_ptr() as usize % ALIGN) % ALIGN;
        Chunk { mem, start }
    }

    /// The `len` bytes from `from` (of the chunk, or from [`CHUNK`] the scratch block).
    fn at(&self, from: usize, len: usize) -> &[u8] {
        &self.mem[self.start + from..self.start + from + len]
    }

    fn at_mut(&mut self, from: usize, len: usize) -> &mut [u8] {
        &mut self.mem[self.start + from..self.start + from + len]
    }
}

/// The thread that writes full chunks while the next one is filled: a direct write returns
/// only once the device has the bytes, so the thread that makes the file's bytes would wait
/// there otherwise.
struct Background {
    send: Option<mpsc::Sender<(Chunk, u64)>>,
    done: mpsc::Receiver<(Chunk, io::Result<()>)>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Background {
    fn start(file: &File) -> io::Result<Background> {
        let file = file.try_clone()?;
        let (send, todo) = mpsc::channel::<(Chunk, u64)>();
        let (report, done) = mpsc::channel();
        let thread = std::thread::Builder::new()
            .name("file-writer".into())
            .spawn(move || {
                for (chunk, offset) in todo {
                    let r = file.write_all_at(chunk.at(0, CHUNK), offset);
                    if report.send((chunk, r)).is_err() {
                        return;
                    }
                }
            })?;
        Ok(Background {
            send: Some(send),
            done,
            thread: Some(thread),
        })
    }
}

impl Drop for Background {
    /// Waits for the chunk in flight, if any (its write is bounded by the device's).
    fn drop(&mut self) {
        self.send = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn writer_gone() -> io::Error {
    io::Error::other("the file's writer thread ended before the file was written")
}

/// A file written through a chunk buffer of its own, directly or buffered (module docs).
pub struct StreamedFile {
    file: File,
    /// Whether the descriptor has `O_DIRECT` set.
    direct: bool,
    /// Whether a direct write has succeeded (after that, `EINVAL` is an error, not a refusal).
    direct_proven: bool,
    chunk: Chunk,
    /// The second chunk, once made, when it is not being written by `background`.
    spare: Option<Chunk>,
    /// Whether `background` is writing a chunk.
    in_flight: bool,
    /// Started at the second full chunk of a direct file.
    background: Option<Background>,
    /// File offset of the chunk's first byte (a multiple of [`CHUNK`]).
    chunk_at: u64,
    /// Bytes held in the chunk; the file's length is `chunk_at + fill`.
    fill: usize,
    /// Whether the chunk holds bytes not yet written.
    dirty: bool,
    /// Position of the next write, at most the file's length.
    pos: u64,
    /// Buffered: bytes before this offset have had their writeback started.
    started: u64,
}

/// Whether a failed direct open or first write means the file system or device refuses
/// `O_DIRECT` (then the file is written buffered) rather than a real error.
fn refuses_direct(e: &io::Error) -> bool {
    e.raw_os_error() == Some(libc::EINVAL)
}

impl StreamedFile {
    /// Creates `path` exclusively (`O_EXCL`) for reading and writing, with `O_DIRECT` unless
    /// the file system refuses it.
    pub(super) fn create_new(path: &Path) -> io::Result<StreamedFile> {
        use std::os::unix::fs::OpenOptionsExt;
        let open = |flags: libc::c_int| {
            fs::OpenOptions::new()
                .read(true)
                .write(true)
                .create_new(true)
                .custom_flags(flags)
                .open(path)
        };
        match open(libc::O_DIRECT) {
            Ok(file) => Ok(StreamedFile::new(file, true)),
            Err(e) if refuses_direct(&e) => {
                tracing::debug!(
                    "{}: O_DIRECT refused at open ({e}); writing it buffered",
                    path.display()
                );
                // Some kernels create the file before they refuse the flag.
                let _ = fs::remove_file(path);
                Ok(StreamedFile::new(open(0)?, false))
            }
            Err(e) => Err(e),
        }
    }

    /// A file written buffered, whatever its file system takes (a spool, a test).
    pub(super) fn buffered(file: File) -> StreamedFile {
        StreamedFile::new(file, false)
    }

    fn new(file: File, direct: bool) -> StreamedFile {
        StreamedFile {
            file,
            direct,
            direct_proven: false,
            chunk: Chunk::new(),
            spare: None,
            in_flight: false,
            background: None,
            chunk_at: 0,
            fill: 0,
            dirty: false,
            pos: 0,
            started: 0,
        }
    }

    /// Whether the bytes go to the device directly (`O_DIRECT`) rather than buffered.
    pub fn is_direct(&self) -> bool {
        self.direct
    }

    /// The file, once its bytes are written ([`Write::flush`] first).
    pub(super) fn into_file(mut self) -> File {
        self.background = None;
        self.file
    }

    fn len(&self) -> u64 {
        self.chunk_at + self.fill as u64
    }

    /// Writes `len` bytes of the chunk from `from` at `offset`; a direct write refused at the
    /// first try turns `O_DIRECT` off and is made buffered (module docs).
    fn write_chunk_at(&mut self, from: usize, len: usize, offset: u64) -> io::Result<()> {
        match self.file.write_all_at(self.chunk.at(from, len), offset) {
            Ok(()) => {
                self.direct_proven |= self.direct;
                Ok(())
            }
            Err(e) if self.direct && !self.direct_proven && refuses_direct(&e) => {
                tracing::debug!("O_DIRECT write refused ({e}); writing the file buffered");
                self.set_buffered()?;
                self.file.write_all_at(self.chunk.at(from, len), offset)
            }
            Err(e) => Err(e),
        }
    }

    /// Clears `O_DIRECT` on the descriptor.
    fn set_buffered(&mut self) -> io::Result<()> {
        use nix::fcntl::{fcntl, FcntlArg, OFlag};
        use std::os::fd::AsRawFd;
        let fd = self.file.as_raw_fd();
        let flags = OFlag::from_bits_truncate(fcntl(fd, FcntlArg::F_GETFL)?);
        fcntl(fd, FcntlArg::F_SETFL(flags - OFlag::O_DIRECT))?;
        self.direct = false;
        Ok(())
    }

    /// Waits until no chunk is being written by the background thread; its error, if any.
    fn drain(&mut self) -> io::Result<()> {
        if !self.in_flight {
            return Ok(());
        }
        let b = self.background.as_ref().ok_or_else(writer_gone)?;
        let (chunk, r) = b.done.recv().map_err(|_| writer_gone())?;
        self.in_flight = false;
        self.spare = Some(chunk);
        r
    }

    /// Writes the held chunk at its offset, here: whole when full; otherwise (a flush)
    /// padded to [`ALIGN`] when direct, then the file cut to its length.
    fn write_chunk(&mut self) -> io::Result<()> {
        self.drain()?;
        let fill = self.fill;
        let padded = if self.direct {
            fill.next_multiple_of(ALIGN)
        } else {
            fill
        };
        self.chunk.at_mut(fill, padded - fill).fill(0);
        self.write_chunk_at(0, padded, self.chunk_at)?;
        if padded != fill {
            self.file.set_len(self.len())?;
        }
        if !self.direct && self.len() >= self.started + CHUNK as u64 {
            start_writeback(&self.file, self.started, self.len() - self.started);
            self.started = self.len();
        }
        self.dirty = false;
        Ok(())
    }

    /// Hands on the full chunk: to the background thread once direct writes are proven (the
    /// spare chunk then takes its place), else written here; the next chunk starts empty.
    fn chunk_full(&mut self) -> io::Result<()> {
        if self.direct && self.direct_proven {
            if self.background.is_none() {
                self.background = Some(Background::start(&self.file)?);
            }
            self.drain()?;
            let spare = self.spare.take().unwrap_or_else(Chunk::new);
            let full = std::mem::replace(&mut self.chunk, spare);
            let send = self.background.as_ref().and_then(|b| b.send.as_ref());
            send.ok_or_else(writer_gone)?
                .send((full, self.chunk_at))
                .map_err(|_| writer_gone())?;
            self.in_flight = true;
        } else {
            self.write_chunk()?;
        }
        self.chunk_at += CHUNK as u64;
        self.fill = 0;
        self.dirty = false;
        Ok(())
    }

    /// Rewrites bytes already written behind the chunk, from `pos`, at most to the chunk;
    /// returns how many of `data` it took.
    fn rewrite_behind(&mut self, data: &[u8]) -> io::Result<usize> {
        self.drain()?;
        let n = data.len().min((self.chunk_at - self.pos) as usize);
        if !self.direct {
            self.file.write_all_at(&data[..n], self.pos)?;
            return Ok(n);
        }
        // One aligned block at a time, through the scratch block after the chunk.
        let block_at = self.pos - self.pos % ALIGN as u64;
        let within = (self.pos - block_at) as usize;
        let n = n.min(ALIGN - within);
        self.file
            .read_exact_at(self.chunk.at_mut(CHUNK, ALIGN), block_at)?;
        self.chunk
            .at_mut(CHUNK + within, n)
            .copy_from_slice(&data[..n]);
        self.write_chunk_at(CHUNK, ALIGN, block_at)?;
        Ok(n)
    }
}

impl Write for StreamedFile {
    fn write(&mut self, data: &[u8]) -> io::Result<usize> {
        if data.is_empty() {
            return Ok(0);
        }
        let n = if self.pos < self.chunk_at {
            self.rewrite_behind(data)?
        } else {
            let within = (self.pos - self.chunk_at) as usize;
            let n = data.len().min(CHUNK - within);
            self.chunk.at_mut(within, n).copy_from_slice(&data[..n]);
            self.fill = self.fill.max(within + n);
            self.dirty = true;
            if self.fill == CHUNK {
                self.chunk_full()?;
            }
            n
        };
        self.pos += n as u64;
        Ok(n)
    }

    /// Writes every byte held or in flight (the chunk stays held: later writes go on filling
    /// it).
    fn flush(&mut self) -> io::Result<()> {
        if self.dirty {
            self.write_chunk()?;
        }
        self.drain()
    }
}

impl Seek for StreamedFile {
    /// To any position up to the file's length (a seek past the end is refused: the file
    /// never has holes).
    fn seek(&mut self, to: SeekFrom) -> io::Result<u64> {
        let len = self.len();
        let target = match to {
            SeekFrom::Start(p) => Some(p),
            SeekFrom::End(d) => len.checked_add_signed(d),
            SeekFrom::Current(d) => self.pos.checked_add_signed(d),
        };
        match target {
            Some(p) if p <= len => {
                self.pos = p;
                Ok(p)
            }
            _ => Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                "a seek before the start or past the end of a file being written",
            )),
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Writes `len` bytes of a pattern into `f` in pieces of uneven sizes, rewrites a few
    /// bytes behind (one run across a block boundary, one at the start), and returns the
    /// bytes the file must then hold.
    fn write_pattern(f: &mut StreamedFile, len: usize) -> Vec<u8> {
        let mut want: Vec<u8> = (0..len).map(|i| (i % 251) as u8).collect();
        let mut at = 0;
        for piece in [3, 1_000_003, 4093, 1 << 20, 77].iter().cycle() {
            if at == len {
                break;
            }
            let end = (at + piece).min(len);
            f.write_all(&want[at..end]).unwrap();
            at = end;
        }
        for (offset, text) in [(4090usize, &b"across a block"[..]), (0, b"head")] {
            if offset + text.len() <= len {
                f.seek(SeekFrom::Start(offset as u64)).unwrap();
                f.write_all(text).unwrap();
                want[offset..offset + text.len()].copy_from_slice(text);
            }
        }
        assert_eq!(f.seek(SeekFrom::End(0)).unwrap(), len as u64);
        f.flush().unwrap();
        want
    }

    /// File lengths around the block and chunk boundaries: a tail of 0, 1, 4095, 4096 and
    /// 4097 bytes past none, one and three chunks and two blocks.
    fn lengths() -> Vec<usize> {
        let mut v = Vec::new();
        for base in [0, CHUNK, 3 * CHUNK + 2 * ALIGN] {
            for tail in [0, 1, 4095, 4096, 4097] {
                v.push(base + tail);
            }
        }
        v
    }

    /// Writes every length of [`lengths`] under `dir`, directly where the file system takes
    /// it (`buffered` false) or buffered; returns whether every file was written directly.
    fn every_length_holds_its_bytes(dir: &Path, buffered: bool) -> bool {
        let mut all_direct = true;
        for len in lengths() {
            let path = dir.join(format!("f{len}"));
            let mut f = if buffered {
                let file = fs::OpenOptions::new()
                    .read(true)
                    .write(true)
                    .create_new(true)
                    .open(&path)
                    .unwrap();
                StreamedFile::buffered(file)
            } else {
                StreamedFile::create_new(&path).unwrap()
            };
            let want = write_pattern(&mut f, len);
            all_direct &= f.is_direct();
            drop(f.into_file());
            let got = fs::read(&path).unwrap();
            assert_eq!(got.len(), len, "length {len}");
            assert!(got == want, "the bytes of a file of {len} bytes");
            fs::remove_file(&path).unwrap();
        }
        all_direct
    }

    #[test]
    fn direct_files_on_a_disk_hold_exactly_the_bytes_written() {
        // /var/tmp, not /tmp: it must be a disk's file system, where O_DIRECT means
        // something (on tmpfs it is the page cache either way).
        let dir = tempfile::tempdir_in("/var/tmp").unwrap();
        assert!(
            every_length_holds_its_bytes(dir.path(), false),
            "the file system under /var/tmp refused O_DIRECT: this test proves nothing \
             there; run it on a machine whose /var/tmp is on a disk"
        );
        assert!(!every_length_holds_its_bytes(dir.path(), true));
    }

    #[test]
    fn files_on_tmpfs_hold_exactly_the_bytes_written() {
        // tmpfs refuses O_DIRECT at open before Linux 6.6 and takes it since: either way the
        // bytes are the same, and the buffered path is taken when asked for.
        let dir = tempfile::tempdir_in("/dev/shm").unwrap();
        every_length_holds_its_bytes(dir.path(), false);
        assert!(!every_length_holds_its_bytes(dir.path(), true));
    }

    #[test]
    fn only_einval_counts_as_a_refusal_of_o_direct() {
        assert!(refuses_direct(&io::Error::from_raw_os_error(libc::EINVAL)));
        for e in [libc::ENOSPC, libc::EIO, libc::EACCES] {
            assert!(!refuses_direct(&io::Error::from_raw_os_error(e)));
        }
    }

    #[test]
    fn a_seek_past_the_end_is_refused() {
        let dir = tempfile::tempdir_in("/var/tmp").unwrap();
        let mut f = StreamedFile::create_new(&dir.path().join("f")).unwrap();
        f.write_all(b"abc").unwrap();
        assert_eq!(
            f.seek(SeekFrom::Start(4)).unwrap_err().kind(),
            io::ErrorKind::InvalidInput
        );
        assert_eq!(f.seek(SeekFrom::Current(-3)).unwrap(), 0);
    }
}
