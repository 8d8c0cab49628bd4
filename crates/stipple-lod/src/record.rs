//! The 16-byte point record stored in tree payloads and passed between build stages.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// One point: position relative to the tree's origin, sRGB colour, and a reserved byte
/// (always 0 in version 1). Little endian on disk, read by casting (see `format.rs`).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Record {
    pub pos: [f32; 3],
    pub rgb: [u8; 3],
    pub reserved: u8,
}

const _: () = assert!(std::mem::size_of::<Record>() == Record::SIZE);

impl Record {
    pub const SIZE: usize = 16;

    pub fn new(p: Vec3, rgb: [u8; 3]) -> Record {
        Record {
            pos: p.to_array(),
            rgb,
            reserved: 0,
        }
    }

    pub fn zeroed() -> Record {
        Zeroable::zeroed()
    }

    pub fn p(&self) -> Vec3 {
        Vec3::from_array(self.pos)
    }
}
