//! Large working buffers of the fit: a hint that lets the kernel back them with transparent
//! huge pages, so the first touch of a 10⁷-point grid costs a few hundred page faults instead
//! of a hundred thousand.
//!
//! Layer 1 (pure logic): depends on `libc` only (one advisory `madvise` on Linux; elsewhere a
//! no-op). The hint never changes the contents of memory, only how it is mapped.

/// Buffers smaller than one huge page (2 MiB) are left alone.
const MIN_ADVISED_BYTES: usize = 2 << 20;

/// Asks the kernel to map the whole capacity of `v` with transparent huge pages. Call it
/// right after allocating or growing `v`, before the memory is written, so the first touch
/// of each 2 MiB block maps one huge page. Failure (or a kernel without THP) is harmless.
pub(crate) fn advise_huge_pages<T>(v: &Vec<T>) {
    #[cfg(target_os = "linux")]
    {
        let bytes = v.capacity().saturating_mul(std::mem::size_of::<T>());
        if bytes < MIN_ADVISED_BYTES {
            return;
        }
        const PAGE: usize = 4096;
        let start = v.as_ptr() as usize;
        let first = start.next_multiple_of(PAGE);
        let end = (start + bytes) & !(PAGE - 1);
        if end > first {
            // SAFETY: [first, end) lies inside the allocation owned by `v` (rounded inwards
            // to whole pages). MADV_HUGEPAGE only changes how those pages are backed; it
            // never changes their contents, and no Rust reference is invalidated.
            let _ = unsafe {
                libc::madvise(first as *mut libc::c_void, end - first, libc::MADV_HUGEPAGE)
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn advised_buffers_keep_their_contents() {
        let mut v: Vec<f64> = Vec::with_capacity(3 << 20);
        v.extend((0..1000).map(|i| i as f64));
        advise_huge_pages(&v);
        v.extend((1000..(3 << 20)).map(|i| i as f64));
        assert!(v.iter().enumerate().all(|(i, &x)| x == i as f64));
    }
}
