//! Memory advice to the operating system: the BVH's large arrays asked to be backed by
//! transparent huge pages, as Embree asks for its own (`os_advise` in `common/sys/alloc.cpp`
//! calls `madvise(MADV_HUGEPAGE)` on every block it maps). A ray's walk touches nodes and
//! triangle blocks scattered over megabytes; with 4 KiB pages most of those touches also miss
//! the TLB. Measured in PERFORMANCE.md.
//!
//! With `src/simd.rs`, the only file of the library allowed `unsafe`.
#![allow(unsafe_code)]

/// Below this many bytes an array cannot hold one whole 2 MiB page; no advice is given.
const HUGE_PAGE: usize = 2 << 20;

/// An empty vector with room for `n` elements whose memory, when it spans a huge page or more,
/// has been advised for transparent huge pages before any of it is touched. Fill it up to `n`
/// without reallocating (`resize`, `extend`, rayon's `par_extend` of an indexed iterator).
pub(crate) fn huge_vec<T>(n: usize) -> Vec<T> {
    let v: Vec<T> = Vec::with_capacity(n);
    let bytes = v.capacity() * size_of::<T>();
    if bytes >= HUGE_PAGE {
        advise(v.as_ptr().cast(), bytes);
    }
    v
}

#[cfg(target_os = "linux")]
fn advise(ptr: *const u8, bytes: usize) {
    // `madvise` takes a page-aligned start. Rounded outwards to whole pages: a huge page needs
    // its whole 2 MiB range advised, and a large buffer starts a few bytes into its mapping.
    let page = 4096;
    let start = ptr as usize / page * page;
    let len = (ptr as usize + bytes).next_multiple_of(page) - start;
    // SAFETY: `start..start + len` is the vector's buffer widened to the pages holding its first
    // and last bytes, all mapped in this process. `MADV_HUGEPAGE` is advice only: it changes no
    // contents, permissions or mapping, so no Rust reference to that memory (ours, or other data
    // sharing the end pages) can observe it. A failure (no THP support) leaves 4 KiB pages and is
    // ignored on purpose.
    unsafe {
        libc::madvise(start as *mut libc::c_void, len, libc::MADV_HUGEPAGE);
    }
}

#[cfg(not(target_os = "linux"))]
fn advise(_: *const u8, _: usize) {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn huge_vec_has_the_room_asked_for_and_keeps_it() {
        for n in [0, 1, 1000, 3 << 20] {
            let mut v: Vec<u32> = huge_vec(n);
            assert!(v.is_empty() && v.capacity() >= n);
            let cap = v.capacity();
            v.resize(n, 7);
            assert_eq!(v.capacity(), cap);
            assert!(v.iter().all(|&x| x == 7));
        }
    }
}
