//! SIMD kernels of the packet traversal (`packet`: the `wide` crate, AVX-512, AVX or
//! plain-array fallbacks chosen at compile time; the wide tree's are in
//! `src/bvh/wide/lanes.rs`), and the crate's few `unsafe` operations, each behind a safe
//! function: cache prefetch hints and the huge-page hint of [`reserve_huge`], which have no
//! safe equivalent, and the reads of the uninitialised traversal [`Stack`].

pub mod packet;

/// [`prefetch`] of every cache line `r` spans.
#[inline(always)]
pub fn prefetch_all<T>(r: &T) {
    let p = std::ptr::from_ref(r).cast::<u8>();
    let size = std::mem::size_of::<T>();
    let mut off = 0;
    while off < size {
        prefetch_addr(p.wrapping_add(off));
        off += 64;
    }
    prefetch_addr(p.wrapping_add(size.saturating_sub(1)));
}

/// [`prefetch`] of every cache line the elements of `s` span.
#[inline(always)]
pub fn prefetch_slice<T>(s: &[T]) {
    let p = s.as_ptr().cast::<u8>();
    let size = std::mem::size_of_val(s);
    let mut off = 0;
    while off < size {
        prefetch_addr(p.wrapping_add(off));
        off += 64;
    }
    if size > 0 {
        prefetch_addr(p.wrapping_add(size - 1));
    }
}

/// Hints the CPU to bring the cache line holding `r` into the cache (no effect on other
/// targets). Used where loads go to addresses known well ahead but scattered, such as vertex
/// positions read through index buffers during refit.
#[inline(always)]
pub fn prefetch<T>(r: &T) {
    prefetch_addr(std::ptr::from_ref(r).cast());
}

/// Prefetches the line holding `p` (any address: it is never dereferenced).
#[inline(always)]
fn prefetch_addr(p: *const u8) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch has no architectural effect and never faults, whatever the address
    // (callers pass addresses inside a live reference), and SSE, which provides it, is part of
    // the x86_64 baseline.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p.cast());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// Smallest allocation [`reserve_huge`] asks huge pages for: one 2 MiB huge page.
const HUGE_PAGE: usize = 2 << 20;

/// Room for `additional` more elements in `v`: nothing happens when it has that room already;
/// otherwise a new buffer with `headroom` more than that, which (when at least 2 MiB) is asked to be
/// backed by transparent huge pages (Linux `madvise(MADV_HUGEPAGE)`) before anything is written
/// to it. For arrays that rays walk in random order (the wide trees' nodes and triangle
/// blocks): a 2 MiB page takes one TLB entry where 4 KiB pages take 512, and random rays over a
/// million-triangle tree otherwise miss the TLB on most node and block loads. A hint only: where
/// huge pages are off (or on other systems) nothing changes.
pub fn reserve_huge<T>(v: &mut Vec<T>, additional: usize, headroom: usize) {
    if v.capacity() - v.len() >= additional {
        return;
    }
    let mut fresh: Vec<T> = Vec::with_capacity(v.len() + additional + headroom);
    advise_huge(
        fresh.as_mut_ptr().cast::<u8>(),
        fresh.capacity() * std::mem::size_of::<T>(),
    );
    fresh.append(v);
    *v = fresh;
}

/// `len` zeroed items in fresh storage of `capacity` (at least `len`), with the huge-page hint
/// ([`advise_huge_vec`]): for storage whose every item the caller overwrites, the system's
/// zeroed pages, backed when a thread first writes them (by every thread that writes a part,
/// not by one that fills it all first).
pub fn zeroed_huge<T: bytemuck::Zeroable + Clone>(len: usize, capacity: usize) -> Vec<T> {
    let mut v = bytemuck::zeroed_vec(capacity.max(len));
    advise_huge_vec(&mut v);
    v.truncate(len);
    v
}

/// Asks for huge pages over `v`'s whole buffer (a hint, as for [`reserve_huge`]), for a buffer
/// the allocator has just mapped and nothing has touched yet, such as a large `vec![0; n]`.
pub fn advise_huge_vec<T>(v: &mut Vec<T>) {
    advise_huge(
        v.as_mut_ptr().cast::<u8>(),
        v.capacity() * std::mem::size_of::<T>(),
    );
}

/// Asks for huge pages over `s` (a hint, as for [`reserve_huge`]), for part of a buffer the
/// allocator has just mapped and nothing has touched yet.
pub fn advise_huge_slice<T>(s: &mut [T]) {
    advise_huge(s.as_mut_ptr().cast::<u8>(), std::mem::size_of_val(s));
}

/// Asks for huge pages over the whole pages inside `len` bytes from `p` (an allocation of
/// ours, nothing of it written yet).
fn advise_huge(p: *mut u8, len: usize) {
    const PAGE: usize = 4096;
    let start = (p as usize).next_multiple_of(PAGE);
    let end = (p as usize + len) / PAGE * PAGE;
    if end < start + HUGE_PAGE {
        return;
    }
    #[cfg(target_os = "linux")]
    // SAFETY: MADV_HUGEPAGE changes only how the kernel backs the pages of the range, never
    // their contents or who may access them; the range is page-aligned and lies inside the
    // caller's live allocation. Failure (THP not built into the kernel) leaves the pages as
    // they were, so the result is ignored.
    unsafe {
        libc::madvise(
            p.wrapping_add(start - p as usize).cast(),
            end - start,
            libc::MADV_HUGEPAGE,
        );
    }
}

/// A traversal stack of at most `N` entries whose storage is not written before use: a fresh
/// `[T; N]` would be zeroed on every ray (512 bytes for the wide trees' 64 entries, several
/// percent of a ray's time in a profile of BVH8 closest hits), and only the entries below the
/// top are ever read. Pushing beyond `N` panics.
pub struct Stack<T: Copy, const N: usize> {
    items: [std::mem::MaybeUninit<T>; N],
    len: usize,
}

impl<T: Copy, const N: usize> Default for Stack<T, N> {
    #[inline(always)]
    fn default() -> Self {
        Self {
            items: [const { std::mem::MaybeUninit::uninit() }; N],
            len: 0,
        }
    }
}

impl<T: Copy, const N: usize> Stack<T, N> {
    /// Number of entries.
    #[inline(always)]
    #[must_use]
    pub fn len(&self) -> usize {
        self.len
    }

    /// Zeroes the storage (for benchmarks: what a fresh `[T; N]` costs).
    #[inline(always)]
    pub fn zero(&mut self) {
        self.items = [const { std::mem::MaybeUninit::zeroed() }; N];
    }

    /// Puts `v` on top.
    #[inline(always)]
    pub fn push(&mut self, v: T) {
        self.items[self.len] = std::mem::MaybeUninit::new(v);
        self.len += 1;
    }

    /// Takes the top entry.
    #[inline(always)]
    pub fn pop(&mut self) -> Option<T> {
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        // SAFETY: every entry below `len` was written by `push` or `insert_by` (which only
        // write at indices up to `len` before raising it), and `T: Copy` has no drop.
        Some(unsafe { self.items[self.len].assume_init() })
    }

    /// Puts `v` below the entries from `base` up that `above(v, entry)` says go above it
    /// (an insertion step: entries from `base` stay sorted if they were). `base <= len`.
    #[inline(always)]
    pub fn insert_by(&mut self, base: usize, v: T, above: impl Fn(&T, &T) -> bool) {
        let mut j = self.len;
        assert!(j < N && base <= j, "stack overflow");
        while j > base {
            // SAFETY: `j - 1 < len`, so the entry was written (see `pop`).
            let e = unsafe { self.items[j - 1].assume_init() };
            if !above(&v, &e) {
                break;
            }
            self.items[j] = std::mem::MaybeUninit::new(e);
            j -= 1;
        }
        self.items[j] = std::mem::MaybeUninit::new(v);
        self.len += 1;
    }
}
