//! Memory hints for the detector's large, long-lived tables (a working image's rays, pixel
//! solid angles and mask: tens of megabytes at 2448×2050, read per row band every frame).
//!
//! Owns two hints. On Linux such buffers are asked for transparent huge pages before they are
//! first written, so that reads scattered over megabytes of them (the refit's tiles, one
//! 16-pixel stretch per image row) miss the TLB less. Where the system gives none (huge
//! pages off, other systems, memory too fragmented) nothing changes but the speed. And a
//! stretch of such a table can be asked into the cache ahead of its reads (x86-64), where
//! the reads jump from image row to image row faster than the hardware's prefetchers learn.

/// Buffers smaller than this are not worth a huge page (one is 2 MiB on x86-64 and arm64).
const HUGE_PAGE: usize = 2 << 20;

/// Makes room for `len` elements in `v` (keeping its contents) and asks for huge pages over
/// its whole buffer. Pages already written keep their size until the kernel's background
/// collapse; call it on an empty vector before filling it.
pub fn reserve_huge<T>(v: &mut Vec<T>, len: usize) {
    v.reserve_exact(len.saturating_sub(v.len()));
    let bytes = v.capacity() * std::mem::size_of::<T>();
    if bytes >= HUGE_PAGE {
        advise_huge(v.as_ptr() as usize, bytes);
    }
}

#[cfg(target_os = "linux")]
fn advise_huge(start: usize, bytes: usize) {
    // SAFETY: sysconf reads a constant of the system.
    let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) };
    let page = if page > 0 { page as usize } else { 4096 };
    let (lo, hi) = (start.next_multiple_of(page), (start + bytes) / page * page);
    if hi > lo {
        // SAFETY: [lo, hi) lies inside the vector's own allocation, whole pages of it, and
        // MADV_HUGEPAGE changes no contents; a failure only means no huge pages.
        unsafe { libc::madvise(lo as *mut libc::c_void, hi - lo, libc::MADV_HUGEPAGE) };
    }
}

#[cfg(not(target_os = "linux"))]
fn advise_huge(_start: usize, _bytes: usize) {}

/// Asks the processor to bring the cache lines of `s` into its nearest cache ahead of their
/// reads (x86-64; elsewhere nothing). For reads the hardware's prefetchers cannot foresee,
/// such as one short stretch per image row of a table megabytes long.
#[inline(always)]
pub fn prefetch<T>(s: &[T]) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        // From the start of the first byte's cache line to the last byte.
        let p = s.as_ptr().cast::<i8>();
        let skew = p as usize % 64;
        let (first, end) = (p.wrapping_sub(skew), std::mem::size_of_val(s) + skew);
        for off in (0..end).step_by(64) {
            // SAFETY: SSE is part of x86-64's baseline; a prefetch is a hint that never
            // faults and changes nothing the program can read.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(first.wrapping_add(off)) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = s;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn room_is_made_and_contents_kept() {
        let mut v: Vec<[f32; 3]> = vec![[1.0, 2.0, 3.0]; 10];
        reserve_huge(&mut v, 1 << 20);
        assert!(v.capacity() >= 1 << 20);
        assert_eq!(v, vec![[1.0, 2.0, 3.0]; 10]);
        v.resize(1 << 20, [0.0; 3]);
        assert_eq!(v[(1 << 20) - 1], [0.0; 3]);
        // small buffers and a length below the contents' are left as they are
        let mut s = vec![7u8; 100];
        reserve_huge(&mut s, 10);
        assert_eq!(s, vec![7u8; 100]);
    }
}
