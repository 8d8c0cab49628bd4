//! Parallel building blocks: writes at disjoint places from many threads, and a stable
//! radix sort.

use rayon::prelude::*;

/// A slice that parallel tasks write at disjoint places they do not know in advance (each
/// neighbour query writes its own point's row, and points lie anywhere; each chunk of a
/// radix sort writes its share of every bucket).
pub(crate) struct Scatter<'a, T> {
    at: *mut T,
    len: usize,
    _slice: std::marker::PhantomData<&'a mut [T]>,
}

// SAFETY: `Scatter` only writes, through `write_row` and `write`, whose callers guarantee
// that no two threads write the same element; `T: Send` lets the values cross threads.
unsafe impl<T: Send> Sync for Scatter<'_, T> {}

impl<'a, T: Copy> Scatter<'a, T> {
    pub(crate) fn new(s: &'a mut [T]) -> Scatter<'a, T> {
        Scatter {
            at: s.as_mut_ptr(),
            len: s.len(),
            _slice: std::marker::PhantomData,
        }
    }

    /// Copies `row` to elements `start..start + row.len()` (bounds checked).
    ///
    /// # Safety
    /// No other thread may read or write those elements while the `Scatter` lives.
    pub(crate) unsafe fn write_row(&self, start: usize, row: &[T]) {
        assert!(start <= self.len && row.len() <= self.len - start);
        // SAFETY: in bounds (checked above); exclusive by the caller's guarantee.
        unsafe { std::ptr::copy_nonoverlapping(row.as_ptr(), self.at.add(start), row.len()) }
    }

    /// Writes `v` to element `at` (bounds checked).
    ///
    /// # Safety
    /// No other thread may read or write that element while the `Scatter` lives.
    #[inline]
    pub(crate) unsafe fn write(&self, at: usize, v: T) {
        assert!(at < self.len);
        // SAFETY: in bounds (checked above); exclusive by the caller's guarantee.
        unsafe { self.at.add(at).write(v) }
    }
}

/// Bits per pass of [`sort_bits`]: 2048 buckets, whose counters stay in the first-level
/// cache.
const DIGIT: u32 = 11;

/// Sorts `v` by bits `lo..lo + bits` of each value, stably (values equal in those bits keep
/// their order; the other bits ride along): a least-significant-digit radix sort, each pass
/// counted and scattered by chunks in parallel. A pass whose digit is the same for every
/// value is skipped.
///
/// With an index in the low bits and a key above it, values in index order come out sorted
/// by key and then index: what `par_sort_unstable` of (key, index) pairs gives, in a third
/// of its time when the key has few bits (the neighbour search's grid of Autzen's 10.65 M
/// points: 26 bits, 3 passes).
pub fn sort_bits(v: &mut Vec<u64>, lo: u32, bits: u32) {
    assert!(
        lo <= 64 && bits <= 64 - lo,
        "bits {lo}..{} of a u64",
        lo + bits
    );
    let n = v.len();
    if n < 2 || bits == 0 {
        return;
    }
    let chunks = (rayon::current_num_threads() * 4).clamp(1, n.div_ceil(1 << 14));
    let size = n.div_ceil(chunks);
    let mut tmp: Vec<u64> = Vec::new();
    let end = lo + bits;
    let mut shift = lo;
    while shift < end {
        let width = DIGIT.min(end - shift);
        let buckets = 1usize << width;
        let mask = (buckets - 1) as u64;
        let digit = move |x: u64| ((x >> shift) & mask) as usize;
        let counts: Vec<Vec<u32>> = v
            .par_chunks(size)
            .map(|c| {
                let mut h = vec![0u32; buckets];
                for &x in c {
                    h[digit(x)] += 1;
                }
                h
            })
            .collect();
        shift += width;
        // Where each chunk's share of each bucket starts: buckets in order, and within a
        // bucket the chunks in order (which keeps the sort stable).
        let mut offsets = vec![vec![0usize; buckets]; counts.len()];
        let mut at = 0usize;
        let mut single = false;
        for b in 0..buckets {
            let start = at;
            for (off, h) in offsets.iter_mut().zip(&counts) {
                off[b] = at;
                at += h[b] as usize;
            }
            single |= at - start == n;
        }
        if single {
            continue;
        }
        if tmp.len() != n {
            tmp = vec![0u64; n];
        }
        {
            let dst = Scatter::new(&mut tmp);
            v.par_chunks(size)
                .zip(offsets.par_iter_mut())
                .for_each(|(c, off)| {
                    for &x in c {
                        let b = digit(x);
                        // SAFETY: the offsets give each (chunk, bucket) its own range of
                        // exactly its count, so every element is written by one chunk once.
                        unsafe { dst.write(off[b], x) };
                        off[b] += 1;
                    }
                });
        }
        std::mem::swap(v, &mut tmp);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// Against the standard library's stable sort on the same bits: random keys of several
    /// widths and offsets, with many equal keys (stability shows), and lengths around the
    /// chunking's edges.
    #[test]
    fn radix_sort_is_a_stable_sort_on_its_bits() {
        let mut r = Rng::new(5);
        for &(n, lo, bits) in &[
            (0usize, 0u32, 8u32),
            (1, 0, 8),
            (100, 32, 5),
            (70_001, 32, 26),
            (200_000, 20, 40),
            (50_000, 0, 64),
            (30_000, 60, 4),
        ] {
            let mask = if bits == 64 {
                u64::MAX
            } else {
                ((1u64 << bits) - 1) << lo
            };
            let mut v: Vec<u64> = (0..n).map(|_| r.next_u64()).collect();
            // Fewer distinct keys than values, so ties are many.
            for x in v.iter_mut() {
                if r.below(2) == 0 {
                    *x &= !mask | (mask & (mask << 3));
                }
            }
            let mut want = v.clone();
            want.sort_by_key(|&x| x & mask);
            sort_bits(&mut v, lo, bits);
            assert_eq!(v, want, "n {n}, bits {lo}..{}", lo + bits);
        }
    }

    /// A digit that is the same for every value is skipped, and the result is still right.
    #[test]
    fn constant_digits_are_skipped() {
        let mut v: Vec<u64> = (0..50_000u64).rev().map(|i| (i << 32) | 7).collect();
        let mut want = v.clone();
        want.sort_unstable();
        sort_bits(&mut v, 0, 64);
        assert_eq!(v, want);
    }
}
