//! The `.stlod` file: a versioned header, node payloads, and a node table, all little endian.
//! The layout is documented for users in `docs/lod-format.md`; keep the two in sync.
//!
//! ```text
//! 0        header (256 bytes, CRC-32 of its first 252 bytes in the last 4)
//! 256      payloads: each node's records, stored as the header's codec says (raw 16-byte
//!          records on 16-byte boundaries, or LZ4-compressed byte planes: crate::codec)
//! table    node table: node_count × 72 bytes, CRC-32 in the header
//! end      = table offset + table size: nothing follows
//! ```
//!
//! Opening checks everything that is cheap to check: the magic, the version, both checksums
//! (not enforced in builds with `--cfg fuzzing`, so fuzzing reaches what lies behind them),
//! that the file is exactly as long as the header says (a cut-short file is named as such),
//! and the node table's structure (every payload inside the payload area, children after
//! their parent, one parent per node, counts that add up). Payload checksums are verified
//! when a node is read ([`LodTree::read_node`]), so opening a terabyte tree stays instant;
//! [`LodTree::verify`] reads every payload.
//!
//! A build writes the header last: a file whose build was killed has a zeroed header and is
//! rejected as unfinished, whatever its name.

use crate::record::Record;
use crate::LodError;
use glam::{DVec3, Vec3};
use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use stipple_core::Bounds;

pub const MAGIC: [u8; 8] = *b"STIPLOD\n";
pub const VERSION: u32 = 2;
pub const HEADER_SIZE: u64 = 256;
pub const NODE_SIZE: u64 = 72;
pub const NONE: u32 = u32::MAX;

/// Header flag: records carry colours (from RGB, or grey from intensity).
pub const FLAG_COLOUR: u32 = 1;

/// Header flag: every input was LAS/LAZ, whose Z is elevation (the tree is framed Z-up).
pub const FLAG_Z_UP: u32 = 2;

/// The tree-wide facts stored in the header.
#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    pub flags: u32,
    /// M: leaves hold fewer than M points, inner nodes at most M samples.
    pub max_node_points: u32,
    /// Input points (the sum of the leaves' counts).
    pub point_count: u64,
    pub node_count: u32,
    /// World position of the local frame's origin; records are f32 offsets from it.
    pub origin: DVec3,
    /// Bounds of the root box in the local frame.
    pub bounds: Bounds,
    pub table_offset: u64,
    pub table_size: u64,
    pub table_crc: u32,
    /// How payloads are stored ([`CODEC_RAW`], [`CODEC_LZ4`]).
    pub codec: u32,
}

/// Payload codec: the records as they are.
pub const CODEC_RAW: u32 = 0;
/// Payload codec: byte planes of the records, compressed as one LZ4 block
/// ([`crate::codec`]).
pub const CODEC_LZ4: u32 = 1;

impl Header {
    pub fn has_colour(&self) -> bool {
        self.flags & FLAG_COLOUR != 0
    }

    /// Whether the inputs said +Z is up (see [`FLAG_Z_UP`]; trees built before the flag
    /// existed say no, and are framed by their shape).
    pub fn z_up(&self) -> bool {
        self.flags & FLAG_Z_UP != 0
    }

    pub fn encode(&self) -> [u8; HEADER_SIZE as usize] {
        let mut b = [0u8; HEADER_SIZE as usize];
        let mut w = Writer(&mut b, 0);
        w.bytes(&MAGIC);
        w.u32(VERSION);
        w.u32(HEADER_SIZE as u32);
        w.u32(self.flags);
        w.u32(self.max_node_points);
        w.u64(self.point_count);
        w.u32(self.node_count);
        w.u32(Record::SIZE as u32);
        for c in self.origin.to_array() {
            w.f64(c);
        }
        w.vec3(self.bounds.min);
        w.vec3(self.bounds.max);
        w.u64(self.table_offset);
        w.u64(self.table_size);
        w.u32(self.table_crc);
        w.u32(self.codec);
        let crc = crc32fast::hash(&b[..252]);
        b[252..].copy_from_slice(&crc.to_le_bytes());
        b
    }

    fn decode(b: &[u8; HEADER_SIZE as usize]) -> Result<Header, String> {
        if b[..8] != MAGIC {
            if b.iter().all(|&x| x == 0) {
                return Err(
                    "not a finished stipple LOD tree: the header is empty (a build that was \
                     interrupted leaves such a file; run build-lod again)"
                        .into(),
                );
            }
            return Err("not a stipple LOD tree (the file does not start with `STIPLOD`)".into());
        }
        let mut r = Reader(b, 8);
        let version = r.u32();
        if version != VERSION {
            return Err(format!(
                "format version {version} is not supported by this stipple (it reads version {VERSION}); rebuild the tree from its inputs with `stipple build-lod`"
            ));
        }
        let stored = u32::from_le_bytes(b[252..].try_into().unwrap());
        if crc32fast::hash(&b[..252]) != stored && !cfg!(fuzzing) {
            return Err("the header's checksum does not match: the file is corrupt".into());
        }
        let header_size = r.u32();
        let flags = r.u32();
        let max_node_points = r.u32();
        let point_count = r.u64();
        let node_count = r.u32();
        let record_size = r.u32();
        if header_size as u64 != HEADER_SIZE || record_size as usize != Record::SIZE {
            return Err(format!(
                "unexpected header size {header_size} or record size {record_size}: the file is corrupt"
            ));
        }
        let origin = DVec3::new(r.f64(), r.f64(), r.f64());
        let bounds = Bounds {
            min: r.vec3(),
            max: r.vec3(),
        };
        Ok(Header {
            flags,
            max_node_points,
            point_count,
            node_count,
            origin,
            bounds,
            table_offset: r.u64(),
            table_size: r.u64(),
            table_crc: r.u32(),
            codec: match r.u32() {
                c @ (CODEC_RAW | CODEC_LZ4) => c,
                c => {
                    return Err(format!(
                        "unknown payload codec {c}: the file is corrupt or from a newer stipple"
                    ))
                }
            },
        })
    }
}

/// One entry of the node table.
#[derive(Clone, Debug, PartialEq)]
pub struct Node {
    /// The node's kd box (local frame). Every record of the node lies inside it.
    pub bounds: Bounds,
    /// Input points in this node's box (stored in it, its descendants or its ancestors).
    pub subtree_points: u64,
    /// Records stored in this node: the samples it took out of its children (an inner node),
    /// or what its ancestors left of the points in its box (a leaf). Every input point is
    /// stored in exactly one node.
    pub sample_count: u32,
    /// Children, or [`NONE`] for a leaf.
    pub children: [u32; 2],
    /// Typical distance between the payload's samples (world units): the grid cell size of
    /// an inner node, an estimate from area and count for a leaf.
    pub spacing: f32,
    pub payload_offset: u64,
    /// Bytes of the stored payload (`sample_count` × 16 when stored raw).
    pub payload_bytes: u32,
    pub payload_crc: u32,
    /// Depth below the root.
    pub depth: u16,
}

impl Node {
    pub fn is_leaf(&self) -> bool {
        self.children[0] == NONE
    }

    /// Bytes of the decoded payload.
    pub fn records_size(&self) -> u64 {
        self.sample_count as u64 * Record::SIZE as u64
    }

    pub fn encode(&self, b: &mut [u8]) {
        let mut w = Writer(b, 0);
        w.vec3(self.bounds.min);
        w.vec3(self.bounds.max);
        w.u64(self.subtree_points);
        w.u32(self.sample_count);
        w.u32(self.children[0]);
        w.u32(self.children[1]);
        w.f32(self.spacing);
        w.u64(self.payload_offset);
        w.u32(self.payload_bytes);
        w.u32(self.payload_crc);
        w.u16(self.depth);
    }

    fn decode(b: &[u8]) -> Node {
        let mut r = Reader(b, 0);
        let bounds = Bounds {
            min: r.vec3(),
            max: r.vec3(),
        };
        Node {
            bounds,
            subtree_points: r.u64(),
            sample_count: r.u32(),
            children: [r.u32(), r.u32()],
            spacing: r.f32(),
            payload_offset: r.u64(),
            payload_bytes: r.u32(),
            payload_crc: r.u32(),
            depth: r.u16(),
        }
    }
}

/// An open tree: header and node table in memory, payloads read on demand (positional reads,
/// safe from several threads at once).
#[derive(Debug)]
pub struct LodTree {
    pub path: PathBuf,
    pub header: Header,
    pub nodes: Vec<Node>,
    file: File,
}

impl LodTree {
    /// Opens and checks a tree (see the module docs for what is checked).
    pub fn open(path: &Path) -> Result<LodTree, LodError> {
        let bad = |m: String| LodError::Corrupt {
            path: path.to_owned(),
            message: m,
        };
        let file = File::open(path).map_err(|e| LodError::io(path, e))?;
        let len = file.metadata().map_err(|e| LodError::io(path, e))?.len();
        if len < HEADER_SIZE {
            return Err(bad(format!(
                "the file is cut short: {len} bytes, less than the {HEADER_SIZE}-byte header"
            )));
        }
        let mut hb = [0u8; HEADER_SIZE as usize];
        file.read_exact_at(&mut hb, 0)
            .map_err(|e| LodError::io(path, e))?;
        let header = Header::decode(&hb).map_err(bad)?;
        let end = header.table_offset.checked_add(header.table_size);
        if end != Some(len) {
            return Err(bad(match end {
                Some(e) if e > len => format!(
                    "the file is cut short: it has {len} bytes but the header says {e} (an incomplete copy or download?)"
                ),
                Some(e) => format!("the file has {} bytes after its end at {e}", len - e),
                None => "the node table's offset overflows: the file is corrupt".into(),
            }));
        }
        if header.table_offset < HEADER_SIZE
            || header.table_size != header.node_count as u64 * NODE_SIZE
            || header.node_count == 0
        {
            return Err(bad(format!(
                "the node table ({} nodes, {} bytes at {}) is inconsistent: the file is corrupt",
                header.node_count, header.table_size, header.table_offset
            )));
        }
        // The table size was checked against the file's length, so this allocation is bounded
        // by what is on disk.
        let mut table = vec![0u8; header.table_size as usize];
        file.read_exact_at(&mut table, header.table_offset)
            .map_err(|e| LodError::io(path, e))?;
        if crc32fast::hash(&table) != header.table_crc && !cfg!(fuzzing) {
            return Err(bad(
                "the node table's checksum does not match: the file is corrupt".into(),
            ));
        }
        let nodes: Vec<Node> = table
            .chunks_exact(NODE_SIZE as usize)
            .map(Node::decode)
            .collect();
        check_structure(&header, &nodes).map_err(bad)?;
        Ok(LodTree {
            path: path.to_owned(),
            header,
            nodes,
            file,
        })
    }

    /// Reads one node's records and checks their checksum.
    pub fn read_node(&self, id: u32) -> Result<Vec<Record>, LodError> {
        let n = self
            .nodes
            .get(id as usize)
            .ok_or_else(|| LodError::Corrupt {
                path: self.path.clone(),
                message: format!("node {id} does not exist"),
            })?;
        let corrupt = |what: String| LodError::Corrupt {
            path: self.path.clone(),
            message: format!(
                "node {id}'s points (bytes {}..{}) {what}: the file is corrupt",
                n.payload_offset,
                n.payload_offset + n.payload_bytes as u64
            ),
        };
        let mut recs = vec![Record::zeroed(); n.sample_count as usize];
        if self.header.codec == CODEC_RAW {
            let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut recs);
            self.file
                .read_exact_at(bytes, n.payload_offset)
                .map_err(|e| LodError::io(&self.path, e))?;
            if crc32fast::hash(bytes) != n.payload_crc && !cfg!(fuzzing) {
                return Err(corrupt("do not match their checksum".into()));
            }
            return Ok(recs);
        }
        let mut stored = vec![0u8; n.payload_bytes as usize];
        self.file
            .read_exact_at(&mut stored, n.payload_offset)
            .map_err(|e| LodError::io(&self.path, e))?;
        if crc32fast::hash(&stored) != n.payload_crc && !cfg!(fuzzing) {
            return Err(corrupt("do not match their checksum".into()));
        }
        crate::codec::decode(self.header.codec, &stored, &mut recs).map_err(corrupt)?;
        Ok(recs)
    }

    /// Reads every payload and checks its checksum.
    pub fn verify(&self) -> Result<(), LodError> {
        for id in 0..self.nodes.len() as u32 {
            self.read_node(id)?;
        }
        Ok(())
    }

    pub fn root(&self) -> &Node {
        &self.nodes[0]
    }

    /// World bounds of the root box.
    pub fn world_bounds(&self) -> (DVec3, DVec3) {
        let b = self.header.bounds;
        (
            self.header.origin + b.min.as_dvec3(),
            self.header.origin + b.max.as_dvec3(),
        )
    }

    /// Depth of the deepest node.
    pub fn depth(&self) -> u16 {
        self.nodes.iter().map(|n| n.depth).max().unwrap_or(0)
    }
}

/// The structural checks of [`LodTree::open`]: a tree (node 0 the root, children after their
/// parent, one parent each), payloads inside the payload area, counts that add up.
fn check_structure(h: &Header, nodes: &[Node]) -> Result<(), String> {
    let mut parents = vec![0u8; nodes.len()];
    for (i, n) in nodes.iter().enumerate() {
        let end = n
            .payload_offset
            .checked_add(n.payload_bytes as u64)
            .ok_or("a payload offset overflows")?;
        let raw = h.codec == CODEC_RAW;
        if n.payload_offset < HEADER_SIZE
            || end > h.table_offset
            || (raw && n.payload_offset % 16 != 0)
        {
            return Err(format!(
                "node {i}'s points lie outside the payload area: the file is corrupt"
            ));
        }
        // What a payload decodes to is bounded by what is stored (no codec expands more than
        // `MAX_RATIO` times), so a crafted count cannot ask for a huge allocation.
        let fits = if raw {
            n.payload_bytes as u64 == n.records_size()
        } else {
            n.records_size() <= (n.payload_bytes as u64 + 64) * crate::codec::MAX_RATIO
        };
        if !fits {
            return Err(format!(
                "node {i} holds {} points in {} bytes: the file is corrupt",
                n.sample_count, n.payload_bytes
            ));
        }
        if n.sample_count as u64 > n.subtree_points
            || n.sample_count > h.max_node_points
            || !n.bounds.min.is_finite()
            || !n.bounds.max.is_finite()
        {
            return Err(format!(
                "node {i} has inconsistent counts or bounds: the file is corrupt"
            ));
        }
        if n.is_leaf() {
            if n.children[1] != NONE {
                return Err(format!("leaf {i} is inconsistent: the file is corrupt"));
            }
            continue;
        }
        let mut sum = 0u64;
        for &c in &n.children {
            if c as usize >= nodes.len() || c as usize <= i {
                return Err(format!(
                    "node {i} names a child {c} that does not follow it: the file is corrupt"
                ));
            }
            parents[c as usize] = parents[c as usize].saturating_add(1);
            // Checked: a crafted table (checksums are no protection against intent) can
            // hold counts whose sum overflows (found by fuzzing).
            sum = sum
                .checked_add(nodes[c as usize].subtree_points)
                .ok_or_else(|| format!("node {i}'s counts overflow: the file is corrupt"))?;
        }
        if sum != n.subtree_points {
            return Err(format!(
                "node {i}'s counts do not add up: the file is corrupt"
            ));
        }
    }
    if parents[0] != 0 || parents[1..].iter().any(|&p| p != 1) {
        return Err("the node table is not a tree: the file is corrupt".into());
    }
    if nodes[0].subtree_points != h.point_count {
        return Err("the root's point count differs from the header's: the file is corrupt".into());
    }
    // Every point is stored once: the records a subtree stores (its own and its
    // descendants') are at most the input points in its box, and the whole tree's are all of
    // them. Children follow their parents, so one pass from the end sums each subtree.
    let mut stored = vec![0u64; nodes.len()];
    for (i, n) in nodes.iter().enumerate().rev() {
        let mut s = n.sample_count as u64;
        if !n.is_leaf() {
            s += stored[n.children[0] as usize] + stored[n.children[1] as usize];
        }
        if s > n.subtree_points {
            return Err(format!(
                "node {i}'s subtree stores more points than its box holds: the file is corrupt"
            ));
        }
        stored[i] = s;
    }
    if stored[0] != h.point_count {
        return Err(format!(
            "the nodes store {} points, the header says {}: the file is corrupt",
            stored[0], h.point_count
        ));
    }
    Ok(())
}

struct Writer<'a>(&'a mut [u8], usize);

impl Writer<'_> {
    fn bytes(&mut self, b: &[u8]) {
        self.0[self.1..self.1 + b.len()].copy_from_slice(b);
        self.1 += b.len();
    }
    fn u16(&mut self, v: u16) {
        self.bytes(&v.to_le_bytes())
    }
    fn u32(&mut self, v: u32) {
        self.bytes(&v.to_le_bytes())
    }
    fn u64(&mut self, v: u64) {
        self.bytes(&v.to_le_bytes())
    }
    fn f32(&mut self, v: f32) {
        self.bytes(&v.to_le_bytes())
    }
    fn f64(&mut self, v: f64) {
        self.bytes(&v.to_le_bytes())
    }
    fn vec3(&mut self, v: Vec3) {
        for c in v.to_array() {
            self.f32(c);
        }
    }
}

struct Reader<'a>(&'a [u8], usize);

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> [u8; N] {
        let v = self.0[self.1..self.1 + N].try_into().unwrap();
        self.1 += N;
        v
    }
    fn u16(&mut self) -> u16 {
        u16::from_le_bytes(self.take())
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take())
    }
    fn u64(&mut self) -> u64 {
        u64::from_le_bytes(self.take())
    }
    fn f32(&mut self) -> f32 {
        f32::from_le_bytes(self.take())
    }
    fn f64(&mut self) -> f64 {
        f64::from_le_bytes(self.take())
    }
    fn vec3(&mut self) -> Vec3 {
        Vec3::new(self.f32(), self.f32(), self.f32())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DVec3, Vec3};

    /// A node table whose children's counts overflow when added is an error, not an
    /// arithmetic overflow (found by fuzzing with the checksums off; a crafted file can carry
    /// valid checksums).
    #[test]
    fn overflowing_counts_are_corrupt_not_a_panic() {
        let bounds = Bounds {
            min: Vec3::ZERO,
            max: Vec3::ONE,
        };
        let node = |subtree_points: u64, children: [u32; 2], at: u64| Node {
            bounds,
            subtree_points,
            sample_count: 1,
            children,
            spacing: 0.1,
            payload_offset: at,
            payload_bytes: 16,
            payload_crc: 0,
            depth: 0,
        };
        let big = u64::MAX / 2 + 1;
        let nodes = [
            node(u64::MAX, [1, 2], HEADER_SIZE),
            node(big, [NONE, NONE], HEADER_SIZE + 16),
            node(big, [NONE, NONE], HEADER_SIZE + 32),
        ];
        let h = Header {
            flags: 0,
            max_node_points: 64,
            point_count: u64::MAX,
            node_count: 3,
            origin: DVec3::ZERO,
            bounds,
            table_offset: HEADER_SIZE + 1024,
            table_size: 3 * NODE_SIZE,
            table_crc: 0,
            codec: CODEC_RAW,
        };
        let e = check_structure(&h, &nodes).unwrap_err();
        assert!(e.contains("node 0's counts overflow"), "{e}");
    }
}
