//! # bucket_sort: hierarchical bucket sorting of points, back to front (Gunjee et al. §4.2)
//!
//! Back-to-front blending needs the points in order of depth, but not a total order: points
//! whose depths differ by less than a slice thickness ε cover each other the same either way
//! (the paper takes ε = the smallest point size). So the points are *sliced*, not sorted:
//!
//! 1. View culling (the paper's step 1): a point is kept when it projects into the image
//!    between the near and far planes; its view depth z (Eq. 12: the distance to the eye
//!    times the cosine to the view direction, i.e. the depth along the view direction) and
//!    the kept points' nearest and farthest depths P_near, P_far are found on the way.
//! 2. The slices: S = ⌈(P_far − P_near) / ε⌉ (Eq. 10), and two bucket sets of N = K = ⌈√S⌉
//!    buckets (Eq. 11); point p lies in slice s = ⌊(z − P_near) / ε⌋, in first-level bucket
//!    s / K and second-level bucket s mod K ([`Slicing`]).
//! 3. A counting pass distributes the points into the N first-level buckets; then each
//!    first-level bucket, back to front, is distributed into the K accurate buckets, which
//!    read back to front give the rendering order. Linear time, N + K counters instead of S.
//!
//! The CPU ([`cpu`]) runs both levels as stable counting sorts (first level: per-thread
//! histograms and offsets; second level: first-level buckets in parallel), so its order is
//! exactly the slices from far to near and, within a slice, increasing point index. The GPU
//! ([`gpu`], `bucket_sort.wgsl`) does the same with atomics: a histogram and a scatter for
//! the first level, then one workgroup per first-level bucket that counts, scans and scatters
//! its points into the K accurate buckets in workgroup memory. Atomics make the order within
//! a slice depend on thread timing; the slices and their contents are the CPU's.
//!
//! Deviations: ε is widened where it would make more than [`MAX_SLICES`] slices (N and K are
//! at most [`MAX_N`] and [`MAX_K`]: the second level's counters must fit one workgroup's
//! memory on every GPU), and the slice count never falls below one.

pub mod cpu;
pub mod gpu;

/// The most first-level buckets.
pub const MAX_N: u32 = 8192;
/// The most second-level (accurate) buckets: K counters and 256 partial sums fit the 16 KiB
/// of workgroup memory every adapter offers.
pub const MAX_K: u32 = 2048;
/// The most slices.
pub const MAX_SLICES: u32 = MAX_N * MAX_K;

/// The slices of a view's depth range (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Slicing {
    /// P_near: the nearest kept point's depth.
    pub near: f32,
    /// The slice thickness (ε, widened to at most [`MAX_SLICES`] slices).
    pub eps: f32,
    /// First-level buckets.
    pub n: u32,
    /// Second-level buckets per first-level bucket.
    pub k: u32,
}

impl Slicing {
    /// Slices of thickness `eps` over depths `near..=far` (Eq. 10, 11).
    pub fn new(near: f32, far: f32, eps: f32) -> Slicing {
        let range = (far - near).max(0.0);
        let eps = if eps > 0.0 && eps.is_finite() {
            eps
        } else {
            // No thickness given: one slice.
            (2.0 * range).max(f32::MIN_POSITIVE)
        };
        let mut slices = (range as f64 / eps as f64).floor() + 1.0;
        let mut eps = eps;
        if slices > MAX_SLICES as f64 {
            // Widened; the farthest depth falls in the last slice (`slice` clamps).
            slices = MAX_SLICES as f64;
            eps = (range as f64 / MAX_SLICES as f64) as f32;
        }
        let slices = slices.max(1.0) as u64;
        let k = ((slices as f64).sqrt().ceil() as u32).clamp(1, MAX_K);
        let n = (slices.div_ceil(k as u64) as u32).clamp(1, MAX_N);
        Slicing { near, eps, n, k }
    }

    /// The number of slices, N · K.
    pub fn slices(&self) -> u32 {
        self.n * self.k
    }

    /// The slice of view depth `z` (a kept point's, so at least `near`).
    #[inline]
    pub fn slice(&self, z: f32) -> u32 {
        let s = ((z - self.near) / self.eps).max(0.0);
        (s as u32).min(self.slices() - 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slices_cover_the_range_with_square_root_buckets() {
        // The paper's example: 0.01 to 10 at ε = 0.001 gives 9991 slices from two sets of
        // 100 buckets.
        let s = Slicing::new(0.01, 10.0, 0.001);
        assert_eq!((s.n, s.k), (100, 100));
        assert_eq!(s.slice(0.01), 0);
        // (In f32, as both backends compute it: 9989.99… → 9989.)
        assert_eq!(s.slice(10.0), ((10.0f32 - 0.01) / 0.001) as u32);
        assert!(s.slice(10.0) >= 9989);
        // Too thin a slice is widened; the far end stays in the last slice.
        let s = Slicing::new(1.0, 2.0, 1e-12);
        assert_eq!(s.slices(), MAX_SLICES);
        assert_eq!(s.slice(2.0), MAX_SLICES - 1);
        assert!(s.slice(1.999_9) < MAX_SLICES - 1);
        // One depth only, or no thickness: one slice.
        let s = Slicing::new(3.0, 3.0, 0.1);
        assert_eq!((s.n, s.k, s.slice(3.0)), (1, 1, 0));
        assert_eq!(Slicing::new(1.0, 2.0, 0.0).slices(), 1);
    }
}
