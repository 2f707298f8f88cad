//! Large working buffers of the fit and the report: a hint that lets the kernel back them
//! with transparent huge pages, so the first touch of a 10⁷-point grid costs a few hundred
//! page faults instead of a hundred thousand; and the heap's free pages given back between
//! the stages of a characterisation ([`release_free_heap`]).
//!
//! Layer 1 (pure logic): depends on `libc` only (an advisory `madvise` on Linux, `malloc_trim`
//! with glibc; elsewhere no-ops). Neither changes the contents of memory, only how it is mapped.

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

/// Gives the heap's free pages back to the kernel (glibc's `malloc_trim`; elsewhere a no-op).
/// Memory freed among live blocks stays resident until then, however much of it there is: a
/// stage that drops many small buffers (a 1000-line grid's roughness profiles, 93 MB in
/// 80 kB blocks) calls this before the next stage allocates large ones, or the peak holds both.
pub(crate) fn release_free_heap() {
    // SAFETY: malloc_trim takes the allocator's own locks and releases only free pages; no
    // live allocation is touched.
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    let _ = unsafe { libc::malloc_trim(0) };
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

    /// Giving the free pages back while blocks freed among live ones leave holes in the heap
    /// (as a dropped grid's per-line profiles do) leaves the live blocks' contents alone.
    #[test]
    fn releasing_free_heap_keeps_live_blocks() {
        let blocks: Vec<Vec<f64>> = (0..200).map(|b| vec![b as f64; 10_000]).collect();
        let live: Vec<Vec<f64>> = blocks
            .into_iter()
            .enumerate()
            .filter_map(|(b, v)| (b % 2 == 0).then_some(v))
            .collect();
        release_free_heap();
        for (k, v) in live.iter().enumerate() {
            assert!(v.iter().all(|&x| x == (2 * k) as f64), "block {}", 2 * k);
        }
    }
}
