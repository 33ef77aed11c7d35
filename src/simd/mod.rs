//! The crate's few `unsafe` operations, each behind a safe function. The SIMD kernels themselves
//! use the safe `wide` crate (`src/bvh/wide/lanes.rs`); what is here has no safe equivalent.

/// Hints the CPU to bring the cache line holding `r` into the cache (no effect on other
/// targets). Used where loads go to addresses known well ahead but scattered, such as vertex
/// positions read through index buffers during refit.
#[inline(always)]
pub fn prefetch<T>(r: &T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch has no architectural effect and never faults, whatever the address
    // (here a valid reference anyway), and SSE, which provides it, is part of the x86_64
    // baseline.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
            std::ptr::from_ref(r).cast(),
        );
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = r;
}
