//! SIMD kernels of the packet traversal (`packet`: the `wide` crate, AVX-512, AVX or
//! plain-array fallbacks chosen at compile time; the wide tree's are in
//! `src/bvh/wide/lanes.rs`), and the crate's few `unsafe` operations, each behind a safe
//! function: cache prefetch hints, which have no safe equivalent.

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
