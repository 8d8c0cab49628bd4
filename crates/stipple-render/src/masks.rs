//! The eight 3×3 silhouette masks of Dobrev et al. Fig. 3 (§3.2–3.3).
//!
//! The figure is not reproduced in the text, only its rule: a background pixel lies beyond the
//! silhouette when one of eight masks finds only background in its cells. We use the eight
//! *closed half-planes* of the 3×3 neighbourhood through its centre: four axial ones (a side
//! row or column plus the two neighbours on the centre line) and four diagonal ones (an L of
//! two adjoining sides). Each has five cells. A pixel at a straight or 45° silhouette matches
//! one of them; a pixel in a hole has object pixels on every side and matches none.
//!
//! Neighbour k ↔ offset (dx, dy), rows growing downwards:
//! ```text
//!   0 1 2      (-1,-1) (0,-1) (1,-1)
//!   3 · 4      (-1, 0)   ·    (1, 0)
//!   5 6 7      (-1, 1) (0, 1) (1, 1)
//! ```
//! The "product of the eight sums is zero" test of the paper becomes one table lookup: an
//! 8-bit set of "white" neighbours indexes [`BORDER`], true when a mask is entirely white.
//!
//! Generalisation (`radius`): the eight masks are the closed half-planes {o ≠ 0 : ⟨o, n⟩ ≥ 0}
//! for the eight directions n, so the same rule applies to a (2r+1)² window. Each cell of the
//! window belongs to some of the eight masks ([`window`]); every non-white cell blocks the
//! masks it belongs to, and the pixel is a border pixel unless all eight are blocked. With
//! r = 1 this is exactly the paper's test; r = 2 recognises holes between points up to about
//! four pixels apart, where the 3×3 masks see a clear half-plane.

/// Neighbour offsets in bit order.
pub const OFFSETS: [(i32, i32); 8] = [
    (-1, -1),
    (0, -1),
    (1, -1),
    (-1, 0),
    (1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
];

const fn bits(cells: [u8; 5]) -> u8 {
    let mut m = 0u8;
    let mut i = 0;
    while i < 5 {
        m |= 1 << cells[i];
        i += 1;
    }
    m
}

/// The eight masks as neighbour bit sets (keep in sync with the WGSL copy, if any).
pub const MASKS: [u8; 8] = [
    bits([0, 1, 2, 3, 4]), // top half-plane
    bits([5, 6, 7, 3, 4]), // bottom
    bits([0, 3, 5, 1, 6]), // left
    bits([2, 4, 7, 1, 6]), // right
    bits([0, 1, 2, 3, 5]), // top-left
    bits([0, 1, 2, 4, 7]), // top-right
    bits([5, 6, 7, 0, 3]), // bottom-left
    bits([5, 6, 7, 2, 4]), // bottom-right
];

const fn build_table() -> [bool; 256] {
    let mut t = [false; 256];
    let mut w = 0;
    while w < 256 {
        let mut k = 0;
        while k < 8 {
            if (w as u8) & MASKS[k] == MASKS[k] {
                t[w] = true;
            }
            k += 1;
        }
        w += 1;
    }
    t
}

/// `BORDER[white]`: does some mask see only white cells?
pub static BORDER: [bool; 256] = build_table();

/// Mask directions n, in the order of [`MASKS`].
pub const DIRECTIONS: [(i32, i32); 8] = [
    (0, -1),
    (0, 1),
    (-1, 0),
    (1, 0),
    (-1, -1),
    (1, -1),
    (-1, 1),
    (1, 1),
];

/// The largest supported window radius.
pub const MAX_RADIUS: u32 = 3;

/// The cells of the (2r+1)² window except the centre, each with the set of masks (bit k =
/// direction k) it belongs to, nearest cells first.
pub fn window(radius: u32) -> Vec<(i32, i32, u8)> {
    let r = radius as i32;
    let mut cells = Vec::new();
    for dy in -r..=r {
        for dx in -r..=r {
            if dx == 0 && dy == 0 {
                continue;
            }
            let mut m = 0u8;
            for (k, &(nx, ny)) in DIRECTIONS.iter().enumerate() {
                if dx * nx + dy * ny >= 0 {
                    m |= 1 << k;
                }
            }
            cells.push((dx, dy, m));
        }
    }
    cells.sort_by_key(|&(dx, dy, _)| dx.abs().max(dy.abs()));
    cells
}

/// The table packed into eight u32 words (bit `w` of word `w / 32`), the form a shader
/// takes as a uniform.
pub fn border_bits() -> [u32; 8] {
    let mut out = [0u32; 8];
    for (w, &b) in BORDER.iter().enumerate() {
        if b {
            out[w / 32] |= 1 << (w % 32);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn masks_are_distinct_half_planes() {
        for (i, a) in MASKS.iter().enumerate() {
            assert_eq!(a.count_ones(), 5);
            for b in &MASKS[i + 1..] {
                assert_ne!(a, b);
            }
        }
        // Every mask is closed under the half-plane property: it contains exactly one of each
        // pair of opposite neighbours or both of a pair on its boundary line.
        for m in MASKS {
            for k in 0..8 {
                let opp = 7 - k;
                let both = m & (1 << k) != 0 && m & (1 << opp) != 0;
                let none = m & (1 << k) == 0 && m & (1 << opp) == 0;
                assert!(!none, "mask {m:08b} misses both {k} and {opp}");
                let _ = both;
            }
        }
    }

    #[test]
    fn the_radius_one_window_is_the_papers_test() {
        let win = window(1);
        assert_eq!(win.len(), 8);
        for white in 0u32..256 {
            let mut blocked = 0u8;
            for (b, &(dx, dy)) in OFFSETS.iter().enumerate() {
                if white & (1 << b) == 0 {
                    blocked |= win.iter().find(|c| (c.0, c.1) == (dx, dy)).unwrap().2;
                }
            }
            assert_eq!(BORDER[white as usize], blocked != 0xFF, "{white:08b}");
        }
        // And each direction's cells are the mask of the same index.
        for (k, &m) in MASKS.iter().enumerate() {
            let cells: u8 = OFFSETS
                .iter()
                .enumerate()
                .filter(|(_, o)| win.iter().any(|c| (c.0, c.1) == **o && c.2 & (1 << k) != 0))
                .map(|(b, _)| 1u8 << b)
                .sum();
            assert_eq!(cells, m, "mask {k}");
        }
        assert_eq!(window(2).len(), 24);
    }

    #[test]
    fn table_matches_the_product_of_sums_rule() {
        // Reference: with background = 0 and object = 1 (the paper's depth-zero convention),
        // a pixel is a border pixel iff the product of the eight mask sums is zero.
        for white in 0u32..256 {
            let depth = |k: usize| if white & (1 << k) != 0 { 0.0 } else { 1.0 };
            let product: f64 = MASKS
                .iter()
                .map(|m| (0..8).filter(|k| m & (1 << k) != 0).map(depth).sum::<f64>())
                .product();
            assert_eq!(BORDER[white as usize], product == 0.0, "{white:08b}");
        }
        assert!(!BORDER[0] && BORDER[255]);
        let packed = border_bits();
        assert!((0..256).all(|w| ((packed[w / 32] >> (w % 32)) & 1 == 1) == BORDER[w]));
    }
}
