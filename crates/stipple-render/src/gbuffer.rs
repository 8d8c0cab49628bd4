//! Per-frame images.

/// Point id of a background pixel.
pub const BACKGROUND: u32 = u32::MAX;

/// Id of a pixel the visibility operator (Pintus §4) emptied: it shows no point, like
/// `BACKGROUND`, but the anisotropic fill may give it a value (mutable), while `BACKGROUND`
/// pixels it judged visible stay background (immutable).
pub const HOLE: u32 = u32::MAX - 1;

/// Whether a G-buffer id names a point (not `BACKGROUND` or `HOLE`).
#[inline]
pub fn is_point(id: u32) -> bool {
    id < HOLE
}

/// The visibility G-buffer: for each pixel the view depth of the point shown there and its
/// index (`BACKGROUND` or `HOLE`, and +inf, where no point is). The colour, normal and lit value of a pixel
/// are functions of its point id, resolved by the `shade` pass, so the geometry passes move
/// eight bytes per pixel instead of a full G-buffer.
#[derive(Clone, Debug, PartialEq)]
pub struct GBuffer {
    pub width: u32,
    pub height: u32,
    pub depth: Vec<f32>,
    pub id: Vec<u32>,
}

impl GBuffer {
    pub fn new(width: u32, height: u32) -> GBuffer {
        let n = width as usize * height as usize;
        GBuffer {
            width,
            height,
            depth: vec![f32::INFINITY; n],
            id: vec![BACKGROUND; n],
        }
    }

    pub fn covered(&self) -> usize {
        self.id.iter().filter(|&&i| is_point(i)).count()
    }

    /// Builds a G-buffer from a picture for tests: `#` = a point at depth 1, `.` = background,
    /// digits = a point at that depth. Ids count up in reading order.
    pub fn from_ascii(rows: &[&str]) -> GBuffer {
        let h = rows.len() as u32;
        let w = rows[0].len() as u32;
        let mut g = GBuffer::new(w, h);
        let mut next = 0;
        for (j, r) in rows.iter().enumerate() {
            assert_eq!(r.len() as u32, w, "ragged picture");
            for (i, c) in r.chars().enumerate() {
                let k = j * w as usize + i;
                let d = match c {
                    '.' => continue,
                    '#' => 1.0,
                    c => c.to_digit(10).expect("picture cell") as f32,
                };
                g.depth[k] = d;
                g.id[k] = next;
                next += 1;
            }
        }
        g
    }

    /// The coverage as a picture (`#` covered, `.` background), for test messages.
    pub fn to_ascii(&self) -> String {
        let mut s = String::new();
        for j in 0..self.height as usize {
            for i in 0..self.width as usize {
                s.push(if !is_point(self.id[j * self.width as usize + i]) {
                    '.'
                } else {
                    '#'
                });
            }
            s.push('\n');
        }
        s
    }
}

pub use crate::stats::PassStat;
