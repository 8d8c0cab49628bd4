//! COPC, the Cloud Optimized Point Cloud (copc.io, version 1.0): a LAZ 1.4 file whose points
//! are grouped into the nodes of an octree, one LAZ chunk per node, with a hierarchy of nodes
//! (keys, offsets, sizes, point counts) in an extended VLR. Potree, QGIS, PDAL and
//! CloudCompare exchange multi-resolution clouds this way.
//!
//! - [`Copc::open`] reads and checks the header, the COPC info VLR, the LAZ VLR and every
//!   hierarchy page. Pages and chunks must lie inside the file, pages must not overlap or
//!   refer back to a page already read (a loop), keys must be valid and unique, and the
//!   nodes' point counts must add up to the header's. The pages' total size is bounded by
//!   the file's, so nothing is allocated from an unchecked count.
//! - [`Copc::read_nodes`] decodes chosen nodes only (in parallel, each chunk on its own):
//!   a view needs the coarse levels and the fine nodes near the eye, not the whole file.
//! - [`write_copc`] writes a cloud held in memory as a COPC file: an octree whose every node
//!   keeps one point per cell of a 128³ grid over its cube (the point nearest the cell's
//!   centre) and passes the rest to its children, down to nodes of at most
//!   [`MAX_NODE_POINTS`]. Every point is stored once. Point format 6, or 7 with colours;
//!   intensity, classification and return numbers are kept. Chunks are compressed in
//!   parallel. The file is written beside its destination under a temporary name and
//!   renamed when complete, so an interrupted write leaves nothing that opens.

use crate::IoError;
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::collections::{HashMap, HashSet};
use std::io::{Seek, Write};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use stipple_core::PointCloud;

/// The LAS 1.4 header's size; the COPC info VLR's data starts 54 bytes after it.
const HEADER_SIZE: usize = 375;
const VLR_HEADER: usize = 54;
const EVLR_HEADER: usize = 60;
const INFO_SIZE: usize = 160;
const ENTRY_SIZE: usize = 32;
/// Deepest octree level accepted in a file (a cube halved 32 times is far below any scale).
const MAX_LEVEL: i32 = 32;
/// Most points a written node holds; a node with more splits.
pub const MAX_NODE_POINTS: usize = 100_000;
/// Cells per axis of a written node's sampling grid.
pub const GRID: u32 = 128;
/// Deepest level [`write_copc`] splits to (coincident points beyond it share a leaf).
const WRITE_MAX_LEVEL: i32 = 20;

/// An octree node's address: level 0 is the root cube; x, y, z count cubes of that level.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct VoxelKey {
    pub level: i32,
    pub x: i32,
    pub y: i32,
    pub z: i32,
}

impl VoxelKey {
    pub const ROOT: VoxelKey = VoxelKey {
        level: 0,
        x: 0,
        y: 0,
        z: 0,
    };

    /// The child in octant `o` (bit 0: +x half, bit 1: +y, bit 2: +z).
    pub fn child(self, o: u32) -> VoxelKey {
        VoxelKey {
            level: self.level + 1,
            x: self.x * 2 + (o & 1) as i32,
            y: self.y * 2 + (o >> 1 & 1) as i32,
            z: self.z * 2 + (o >> 2 & 1) as i32,
        }
    }

    fn valid(&self) -> bool {
        (0..=MAX_LEVEL).contains(&self.level)
            && [self.x, self.y, self.z]
                .iter()
                .all(|&c| c >= 0 && (c as i64) < 1i64 << self.level)
    }
}

/// A node that holds points: where its LAZ chunk lies and how many points it has.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CopcNode {
    pub key: VoxelKey,
    pub offset: u64,
    pub byte_size: u64,
    pub point_count: u64,
}

/// The COPC info VLR.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CopcInfo {
    /// Centre and half the side of the root cube (world units).
    pub center: DVec3,
    pub halfsize: f64,
    /// Distance between the root node's points (its grid's cell size).
    pub spacing: f64,
    pub root_hier_offset: u64,
    pub root_hier_size: u64,
}

/// An opened, checked COPC file.
pub struct Copc {
    pub path: PathBuf,
    pub info: CopcInfo,
    /// Nodes with points, in the order the hierarchy lists them.
    pub nodes: Vec<CopcNode>,
    /// Hierarchy pages read (the root page included).
    pub pages: usize,
    pub point_count: u64,
    /// Point data record format (6, 7 or 8) and record length.
    pub format: u8,
    pub record_len: usize,
    pub scale: DVec3,
    pub offset: DVec3,
    /// The header's bounds of the points.
    pub min: DVec3,
    pub max: DVec3,
    laz: laz::LazVlr,
    file: std::fs::File,
}

fn le_u16(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}
fn le_u32(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}
fn le_i32(b: &[u8], at: usize) -> i32 {
    i32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}
fn le_u64(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}
fn le_f64(b: &[u8], at: usize) -> f64 {
    f64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}

/// The user id of a VLR header (NUL padding removed).
fn user_id(b: &[u8]) -> &[u8] {
    let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
    &b[..end]
}

/// Whether a file is a COPC file: LAS 1.4 whose first VLR is the COPC info VLR.
pub fn is_copc(path: &Path) -> bool {
    let Ok(f) = std::fs::File::open(path) else {
        return false;
    };
    let mut b = [0u8; HEADER_SIZE + VLR_HEADER];
    if f.read_exact_at(&mut b, 0).is_err() {
        return false;
    }
    let header_size = le_u16(&b, 94) as usize;
    &b[0..4] == b"LASF"
        && b[24] == 1
        && b[25] == 4
        && header_size == HEADER_SIZE
        && user_id(&b[HEADER_SIZE + 2..HEADER_SIZE + 18]) == b"copc"
        && le_u16(&b, HEADER_SIZE + 18) == 1
}

impl Copc {
    /// Opens a COPC file and checks its header, VLRs and whole hierarchy (see the module
    /// docs). Errors name the file and what is wrong.
    pub fn open(path: &Path) -> Result<Copc, IoError> {
        let bad = |m: String| IoError::invalid(path, m);
        let file = std::fs::File::open(path).map_err(|e| IoError::io(path, e))?;
        let len = file.metadata().map_err(|e| IoError::io(path, e))?.len();
        let read = |at: u64, n: usize| -> Result<Vec<u8>, IoError> {
            if at.checked_add(n as u64).is_none_or(|end| end > len) {
                return Err(IoError::invalid(
                    path,
                    format!(
                        "the file is cut short: {n} bytes at offset {at} lie beyond its end ({len} bytes)"
                    ),
                ));
            }
            let mut b = vec![0u8; n];
            file.read_exact_at(&mut b, at)
                .map_err(|e| IoError::io(path, e))?;
            Ok(b)
        };
        let h = read(0, HEADER_SIZE)?;
        if &h[0..4] != b"LASF" {
            return Err(bad("not a LAS/LAZ file (no LASF signature)".into()));
        }
        if (h[24], h[25]) != (1, 4) || le_u16(&h, 94) as usize != HEADER_SIZE {
            return Err(bad(format!(
                "COPC needs LAS 1.4 with a {HEADER_SIZE}-byte header; this is LAS {}.{} with {} bytes",
                h[24],
                h[25],
                le_u16(&h, 94)
            )));
        }
        let point_data = le_u32(&h, 96) as u64;
        let vlr_count = le_u32(&h, 100);
        let format = h[104] & 0x3f;
        let compressed = h[104] & 0x80 != 0;
        let record_len = le_u16(&h, 105) as usize;
        let scale = DVec3::new(le_f64(&h, 131), le_f64(&h, 139), le_f64(&h, 147));
        let offset = DVec3::new(le_f64(&h, 155), le_f64(&h, 163), le_f64(&h, 171));
        let max = DVec3::new(le_f64(&h, 179), le_f64(&h, 195), le_f64(&h, 211));
        let min = DVec3::new(le_f64(&h, 187), le_f64(&h, 203), le_f64(&h, 219));
        let point_count = le_u64(&h, 247);
        if !(6..=8).contains(&format) || !compressed {
            return Err(bad(format!(
                "COPC needs compressed point format 6, 7 or 8; the header says format {format}{}",
                if compressed { "" } else { ", uncompressed" }
            )));
        }
        let min_len = [30, 36, 38][format as usize - 6];
        if record_len < min_len {
            return Err(bad(format!(
                "point format {format} records are at least {min_len} bytes; the header says {record_len}"
            )));
        }
        if !scale.is_finite() || scale.min_element() <= 0.0 || !offset.is_finite() {
            return Err(bad(format!(
                "the header's scale {scale} or offset {offset} is not usable"
            )));
        }
        if point_data > len || point_data < (HEADER_SIZE + VLR_HEADER + INFO_SIZE) as u64 {
            return Err(bad(format!(
                "the point data offset {point_data} lies outside the file ({len} bytes) or inside its header"
            )));
        }
        // VLRs: all of them lie between the header and the point data.
        let vlrs = read(HEADER_SIZE as u64, point_data as usize - HEADER_SIZE)?;
        let mut at = 0usize;
        let mut info = None;
        let mut laz_vlr = None;
        for v in 0..vlr_count {
            if at + VLR_HEADER > vlrs.len() {
                return Err(bad(format!(
                    "VLR {v} of {vlr_count} starts beyond the point data offset: the header is corrupt"
                )));
            }
            let uid = user_id(&vlrs[at + 2..at + 18]).to_vec();
            let record = le_u16(&vlrs, at + 18);
            let size = le_u16(&vlrs, at + 20) as usize;
            let data = at + VLR_HEADER;
            if data + size > vlrs.len() {
                return Err(bad(format!(
                    "VLR {v} ({} {record}) runs past the point data offset: the header is corrupt",
                    String::from_utf8_lossy(&uid)
                )));
            }
            let d = &vlrs[data..data + size];
            if v == 0 {
                if uid != b"copc" || record != 1 || size != INFO_SIZE {
                    return Err(bad(
                        "not a COPC file: its first VLR is not the COPC info VLR (copc 1, 160 bytes)"
                            .into(),
                    ));
                }
                info = Some(CopcInfo {
                    center: DVec3::new(le_f64(d, 0), le_f64(d, 8), le_f64(d, 16)),
                    halfsize: le_f64(d, 24),
                    spacing: le_f64(d, 32),
                    root_hier_offset: le_u64(d, 40),
                    root_hier_size: le_u64(d, 48),
                });
            } else if uid == b"laszip encoded" && record == 22204 {
                laz_vlr = Some(
                    laz::LazVlr::from_buffer(d)
                        .map_err(|e| bad(format!("its LAZ VLR cannot be read: {e}")))?,
                );
            }
            at = data + size;
        }
        let info = info.ok_or_else(|| bad("not a COPC file: it has no VLRs".into()))?;
        let laz =
            laz_vlr.ok_or_else(|| bad("COPC needs the LAZ VLR; this file has none".into()))?;
        if laz.items_size() as usize != record_len {
            return Err(bad(format!(
                "the LAZ VLR describes {}-byte records, the header {record_len}",
                laz.items_size()
            )));
        }
        if !(info.center.is_finite() && info.halfsize > 0.0 && info.halfsize.is_finite()) {
            return Err(bad(format!(
                "the COPC root cube (centre {}, half size {}) is not usable",
                info.center, info.halfsize
            )));
        }
        // The hierarchy: pages reached from the root page, each read once.
        let mut nodes = Vec::new();
        let mut pages: Vec<(u64, u64)> = Vec::new();
        let mut seen_pages = HashSet::new();
        let mut seen_keys = HashSet::new();
        let mut todo = vec![(info.root_hier_offset, info.root_hier_size, None::<VoxelKey>)];
        while let Some((po, ps, from)) = todo.pop() {
            let what = match from {
                None => "the root hierarchy page".to_string(),
                Some(k) => format!(
                    "the hierarchy page of node {}-{}-{}-{}",
                    k.level, k.x, k.y, k.z
                ),
            };
            if ps == 0 || ps % ENTRY_SIZE as u64 != 0 {
                return Err(bad(format!(
                    "{what} has {ps} bytes, not a positive multiple of {ENTRY_SIZE}"
                )));
            }
            if po.checked_add(ps).is_none_or(|e| e > len) || po < point_data {
                return Err(bad(format!(
                    "{what} ({ps} bytes at {po}) lies outside the file's {len} bytes or before its points"
                )));
            }
            if !seen_pages.insert(po) {
                return Err(bad(format!(
                    "{what} at offset {po} was read before: the hierarchy loops"
                )));
            }
            pages.push((po, po + ps));
            let page = read(po, ps as usize)?;
            for e in page.chunks_exact(ENTRY_SIZE) {
                let key = VoxelKey {
                    level: le_i32(e, 0),
                    x: le_i32(e, 4),
                    y: le_i32(e, 8),
                    z: le_i32(e, 12),
                };
                let (off, size, count) = (le_u64(e, 16), le_i32(e, 24), le_i32(e, 28));
                let name = format!("node {}-{}-{}-{}", key.level, key.x, key.y, key.z);
                if !key.valid() {
                    return Err(bad(format!(
                        "{what} lists {name}, which is no octree node (level 0 to {MAX_LEVEL}, coordinates below 2^level)"
                    )));
                }
                if count == -1 {
                    todo.push((off, size.max(0) as u64, Some(key)));
                    continue;
                }
                if count < -1 || size < 0 {
                    return Err(bad(format!(
                        "{what}: {name} has point count {count} and byte size {size}"
                    )));
                }
                if !seen_keys.insert(key) {
                    return Err(bad(format!("{what}: {name} is listed twice")));
                }
                if count == 0 {
                    continue;
                }
                let size = size as u64;
                if size == 0
                    || off < point_data + 8
                    || off.checked_add(size).is_none_or(|e| e > len)
                {
                    return Err(bad(format!(
                        "{name}'s points ({size} bytes at {off}) lie outside the file's point data"
                    )));
                }
                nodes.push(CopcNode {
                    key,
                    offset: off,
                    byte_size: size,
                    point_count: count as u64,
                });
            }
        }
        pages.sort_unstable();
        if let Some(w) = pages.windows(2).find(|w| w[1].0 < w[0].1) {
            return Err(bad(format!(
                "hierarchy pages at {} and {} overlap",
                w[0].0, w[1].0
            )));
        }
        let mut chunks: Vec<(u64, u64)> = nodes
            .iter()
            .map(|n| (n.offset, n.offset + n.byte_size))
            .collect();
        chunks.sort_unstable();
        if let Some(w) = chunks.windows(2).find(|w| w[1].0 < w[0].1) {
            return Err(bad(format!(
                "the points of two nodes overlap (at {} and {})",
                w[0].0, w[1].0
            )));
        }
        let listed: u64 = nodes.iter().map(|n| n.point_count).sum();
        if listed != point_count {
            return Err(bad(format!(
                "the hierarchy lists {listed} points, the header {point_count}"
            )));
        }
        if point_count == 0 {
            return Err(bad("the cloud has no points (header count 0)".into()));
        }
        Ok(Copc {
            path: path.to_owned(),
            info,
            pages: pages.len(),
            nodes,
            point_count,
            format,
            record_len,
            scale,
            offset,
            min,
            max,
            laz,
            file,
        })
    }

    /// The cube of a node (world units).
    pub fn cube(&self, k: VoxelKey) -> (DVec3, DVec3) {
        let side = 2.0 * self.info.halfsize / (1u64 << k.level) as f64;
        let lo = self.info.center - DVec3::splat(self.info.halfsize)
            + DVec3::new(k.x as f64, k.y as f64, k.z as f64) * side;
        (lo, lo + DVec3::splat(side))
    }

    /// Distance between a node's points: the root's spacing halved per level.
    pub fn spacing(&self, k: VoxelKey) -> f64 {
        self.info.spacing / (1u64 << k.level) as f64
    }

    /// The points of the nodes `which` (indices into [`Copc::nodes`]), decoded in parallel,
    /// as one cloud with positions relative to `origin`.
    pub fn read_nodes(&self, which: &[usize], origin: DVec3) -> Result<PointCloud, IoError> {
        self.read_nodes_with(which, origin, None)
    }

    /// The node of the lowest level that holds points (the root, in a file whose root has
    /// points); None for a hierarchy without points.
    pub fn root(&self) -> Option<usize> {
        (0..self.nodes.len()).min_by_key(|&i| self.nodes[i].key.level)
    }

    /// How 16-bit colours become 8-bit ones for clouds read a node at a time: the shift (8
    /// or 0) the root node's colours ask for (see [`Copc::read_nodes`]), so that every node
    /// of a view streamed node by node is shifted alike; 0 without colours.
    pub fn colour_shift(&self) -> Result<u32, IoError> {
        if self.format < 7 {
            return Ok(0);
        }
        let Some(root) = self.root() else {
            return Ok(0);
        };
        let parts = self.decode(&[root], DVec3::ZERO)?;
        Ok(rgb_shift(parts.iter().flat_map(|p| p.rgb.iter())))
    }

    /// [`Copc::read_nodes`], with the colour shift given (None: from the nodes read).
    pub fn read_nodes_with(
        &self,
        which: &[usize],
        origin: DVec3,
        shift: Option<u32>,
    ) -> Result<PointCloud, IoError> {
        let path = &self.path;
        let rec = self.record_len;
        let colour = self.format >= 7;
        // LAZ can hold hundreds of identical points in a byte, so a node's count is checked
        // against the memory its points need (records, then the cloud's columns), not
        // against its bytes.
        let points: u64 = which.iter().map(|&w| self.nodes[w].point_count).sum();
        let need = points.saturating_mul(rec as u64 + 22);
        if let Some(avail) = stipple_core::sys::available_memory() {
            if need > avail {
                return Err(IoError::invalid(
                    path,
                    format!(
                        "{} nodes claim {points} points, which need {} MiB: more than the {} MiB \
                         of memory available (a smaller --point-budget reads fewer)",
                        which.len(),
                        need >> 20,
                        avail >> 20
                    ),
                ));
            }
        }
        let parts = self.decode(which, origin)?;
        let total: usize = parts.iter().map(|p| p.positions.len()).sum();
        let mut cloud = PointCloud {
            origin,
            positions: Vec::with_capacity(total),
            intensity: Some(Vec::with_capacity(total)),
            classification: Some(Vec::with_capacity(total)),
            return_number: Some(Vec::with_capacity(total)),
            z_up: true,
            ..Default::default()
        };
        let mut rgb: Vec<[u16; 3]> = Vec::with_capacity(if colour { total } else { 0 });
        for p in parts {
            cloud.positions.extend(p.positions);
            cloud.intensity.as_mut().unwrap().extend(p.intensity);
            cloud.classification.as_mut().unwrap().extend(p.class);
            cloud.return_number.as_mut().unwrap().extend(p.returns);
            rgb.extend(p.rgb);
        }
        if colour {
            let shift = shift.unwrap_or_else(|| rgb_shift(rgb.iter()));
            cloud.colors = Some(rgb.iter().map(|c| c.map(|v| (v >> shift) as u8)).collect());
        }
        Ok(cloud)
    }

    /// The chosen nodes' points, decoded in parallel (positions relative to `origin`).
    fn decode(&self, which: &[usize], origin: DVec3) -> Result<Vec<Part>, IoError> {
        let path = &self.path;
        let rec = self.record_len;
        let colour = self.format >= 7;
        which
            .par_iter()
            .map(|&w| {
                let n = self.nodes[w];
                let mut bytes = vec![0u8; n.byte_size as usize];
                self.file
                    .read_exact_at(&mut bytes, n.offset)
                    .map_err(|e| IoError::io(path, e))?;
                let mut raw = Vec::new();
                stipple_core::sys::try_reserve(
                    &mut raw,
                    n.point_count as usize * rec,
                    "a node's points",
                )
                .map_err(|m| IoError::invalid(path, m))?;
                raw.resize(n.point_count as usize * rec, 0);
                crate::las_io::decode_chunk(&bytes, &mut raw, &self.laz, n.point_count).map_err(
                    |e| {
                        IoError::invalid(
                            path,
                            format!(
                                "the points of node {}-{}-{}-{} are corrupt: {e}",
                                n.key.level, n.key.x, n.key.y, n.key.z
                            ),
                        )
                    },
                )?;
                let mut p = Part::default();
                for r in raw.chunks_exact(rec) {
                    let q = DVec3::new(
                        le_i32(r, 0) as f64,
                        le_i32(r, 4) as f64,
                        le_i32(r, 8) as f64,
                    ) * self.scale
                        + self.offset;
                    p.positions.push((q - origin).as_vec3());
                    p.intensity.push(le_u16(r, 12));
                    p.returns.push(r[14] & 0x0f);
                    p.class.push(r[16]);
                    if colour {
                        p.rgb.push([le_u16(r, 30), le_u16(r, 32), le_u16(r, 34)]);
                    }
                }
                Ok(p)
            })
            .collect::<Result<_, IoError>>()
    }
}

/// As the LAS reader: 8-bit values stored in 16 bits are kept (shift 0), others shifted by 8.
fn rgb_shift<'a>(rgb: impl Iterator<Item = &'a [u16; 3]>) -> u32 {
    let max = rgb.flatten().copied().max().unwrap_or(0);
    if max > 255 {
        8
    } else {
        0
    }
}

#[derive(Default)]
struct Part {
    positions: Vec<Vec3>,
    intensity: Vec<u16>,
    returns: Vec<u8>,
    class: Vec<u8>,
    rgb: Vec<[u16; 3]>,
}

/// What [`write_copc`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct CopcReport {
    pub points: u64,
    pub nodes: usize,
    pub levels: usize,
    pub bytes: u64,
}

/// Splits the points `idx` of node `key` (cube from `lo`, side `side`, local frame): the node
/// keeps the point nearest the centre of each cell of its grid, its children the rest.
fn octree(
    pts: &[Vec3],
    key: VoxelKey,
    lo: Vec3,
    side: f32,
    mut idx: Vec<u32>,
) -> Vec<(VoxelKey, Vec<u32>)> {
    if idx.len() <= MAX_NODE_POINTS || key.level >= WRITE_MAX_LEVEL {
        return vec![(key, idx)];
    }
    let g = GRID as f32;
    let cell = side / g;
    let cell_of = |p: Vec3| {
        let c = ((p - lo) / cell).floor();
        let c = [c.x, c.y, c.z].map(|v| (v.max(0.0) as u32).min(GRID - 1));
        (c[0] * GRID + c[1]) * GRID + c[2]
    };
    // (cell, squared distance to the cell's centre, index): the first of each cell is kept.
    let mut keyed: Vec<(u32, u32, u32)> = idx
        .par_iter()
        .map(|&i| {
            let p = pts[i as usize];
            let c = cell_of(p);
            let centre = lo
                + (Vec3::new(
                    (c / (GRID * GRID)) as f32,
                    (c / GRID % GRID) as f32,
                    (c % GRID) as f32,
                ) + 0.5)
                    * cell;
            (c, (p - centre).length_squared().to_bits(), i)
        })
        .collect();
    keyed.par_sort_unstable();
    let mut kept = Vec::new();
    let mut rest: [Vec<u32>; 8] = Default::default();
    let half = lo + Vec3::splat(side * 0.5);
    for (t, &(c, _, i)) in keyed.iter().enumerate() {
        if t == 0 || keyed[t - 1].0 != c {
            kept.push(i);
        } else {
            let p = pts[i as usize];
            let o = (p.x >= half.x) as usize
                | ((p.y >= half.y) as usize) << 1
                | ((p.z >= half.z) as usize) << 2;
            rest[o].push(i);
        }
    }
    drop(keyed);
    idx.clear();
    let mut out = vec![(key, kept)];
    let children: Vec<Vec<(VoxelKey, Vec<u32>)>> = rest
        .into_par_iter()
        .enumerate()
        .filter(|(_, r)| !r.is_empty())
        .map(|(o, r)| {
            let o = o as u32;
            let clo = lo
                + Vec3::new((o & 1) as f32, (o >> 1 & 1) as f32, (o >> 2 & 1) as f32) * side * 0.5;
            octree(pts, key.child(o), clo, side * 0.5, r)
        })
        .collect();
    for c in children {
        out.extend(c);
    }
    out
}

/// The power of ten at or above `x` (x > 0).
fn decade_at_or_above(x: f64) -> f64 {
    10f64.powi(x.log10().ceil() as i32)
}

/// Writes `cloud` as a COPC file at `path` (see the module docs). The file appears only when
/// complete; an existing file at `path` is replaced, so callers check first.
pub fn write_copc(path: &Path, cloud: &PointCloud) -> Result<CopcReport, IoError> {
    let n = cloud.len();
    if n == 0 {
        return Err(IoError::invalid(
            path,
            "nothing to write: the cloud has no points",
        ));
    }
    if n > i32::MAX as usize {
        return Err(IoError::invalid(
            path,
            format!(
                "{n} points: a COPC file written by stipple holds at most {}",
                i32::MAX
            ),
        ));
    }
    // Root cube (local frame), a hair larger than the points' box.
    let b = stipple_core::cloud::Bounds::from_points(&cloud.positions);
    let centre_local = b.center();
    let half = (b.extent().max_element() * 0.5).max(f32::MIN_POSITIVE) * (1.0 + 1e-6) + 1e-6;
    let lo = centre_local - Vec3::splat(half);
    let side = 2.0 * half;
    let nodes = octree(
        &cloud.positions,
        VoxelKey::ROOT,
        lo,
        side,
        (0..n as u32).collect(),
    );
    // Integer coordinates: scale a power of ten at about the f32 positions' own precision.
    let center = cloud.origin + centre_local.as_dvec3();
    let scale = decade_at_or_above((side as f64) * 2f64.powi(-24)).max(1e-9);
    let offset = center.round();
    let colour = cloud.colors.is_some();
    let format: u8 = if colour { 7 } else { 6 };
    let rec = if colour { 36 } else { 30 };
    let laz_vlr = laz::LazVlrBuilder::default()
        .with_point_format(format, 0)
        .map_err(|e| IoError::invalid(path, format!("cannot describe the compression: {e}")))?
        .with_variable_chunk_size()
        .build();
    let quant = |i: usize| -> [i32; 3] {
        let w = cloud.world(i);
        let q = ((w - offset) / scale).round();
        [q.x as i32, q.y as i32, q.z as i32]
    };
    // Each node's chunk, compressed on its own (in parallel), and its points' extent.
    type Chunk = (Vec<u8>, [i32; 3], [i32; 3], [u64; 15]);
    let chunks: Vec<Chunk> = nodes
        .par_iter()
        .map(|(_, idx)| {
            let mut raw = vec![0u8; idx.len() * rec];
            let (mut qlo, mut qhi) = ([i32::MAX; 3], [i32::MIN; 3]);
            let mut by_return = [0u64; 15];
            for (r, &i) in raw.chunks_exact_mut(rec).zip(idx) {
                let i = i as usize;
                let q = quant(i);
                for a in 0..3 {
                    qlo[a] = qlo[a].min(q[a]);
                    qhi[a] = qhi[a].max(q[a]);
                    r[a * 4..a * 4 + 4].copy_from_slice(&q[a].to_le_bytes());
                }
                let intensity = cloud.intensity.as_ref().map_or(0, |v| v[i]);
                r[12..14].copy_from_slice(&intensity.to_le_bytes());
                let ret = cloud
                    .return_number
                    .as_ref()
                    .map_or(1, |v| v[i].clamp(1, 15));
                // Return number and number of returns (unknown: at least this one).
                r[14] = ret | ret << 4;
                by_return[ret as usize - 1] += 1;
                r[16] = cloud.classification.as_ref().map_or(0, |v| v[i]);
                if let Some(c) = &cloud.colors {
                    for (a, v) in c[i].iter().enumerate() {
                        let v = *v as u16 * 257;
                        r[30 + a * 2..32 + a * 2].copy_from_slice(&v.to_le_bytes());
                    }
                }
            }
            let mut c =
                laz::LasZipCompressor::new(std::io::Cursor::new(Vec::new()), laz_vlr.clone())
                    .map_err(|e| IoError::invalid(path, format!("cannot compress: {e}")))?;
            c.compress_many(&raw).map_err(|e| IoError::io(path, e))?;
            c.finish_current_chunk().map_err(|e| IoError::io(path, e))?;
            let end = c
                .get_mut()
                .stream_position()
                .map_err(|e| IoError::io(path, e))? as usize;
            let mut bytes = c.into_inner().into_inner();
            // The compressor starts with an 8-byte chunk-table offset: the chunk follows it.
            bytes.truncate(end);
            bytes.drain(..8);
            Ok((bytes, qlo, qhi, by_return))
        })
        .collect::<Result<_, IoError>>()?;
    let mut laz_data = Vec::new();
    laz_vlr
        .write_to(&mut laz_data)
        .map_err(|e| IoError::io(path, e))?;
    let point_data = HEADER_SIZE + VLR_HEADER + INFO_SIZE + VLR_HEADER + laz_data.len();
    // Layout: header, VLRs, chunk-table offset, chunks, chunk table, hierarchy EVLR.
    let mut offsets = Vec::with_capacity(chunks.len());
    let mut at = point_data as u64 + 8;
    for (bytes, ..) in &chunks {
        offsets.push(at);
        at += bytes.len() as u64;
    }
    let chunk_table_at = at;
    let mut table = laz::laszip::ChunkTable::with_capacity(chunks.len());
    for ((bytes, ..), (_, idx)) in chunks.iter().zip(&nodes) {
        table.push(laz::laszip::ChunkTableEntry {
            point_count: idx.len() as u64,
            byte_count: bytes.len() as u64,
        });
    }
    let mut table_bytes = Vec::new();
    table
        .write_to(&mut table_bytes, &laz_vlr)
        .map_err(|e| IoError::io(path, e))?;
    let evlr_at = chunk_table_at + table_bytes.len() as u64;
    let page_at = evlr_at + EVLR_HEADER as u64;
    let mut page = Vec::with_capacity(nodes.len() * ENTRY_SIZE);
    for (((key, idx), (bytes, ..)), &off) in nodes.iter().zip(&chunks).zip(&offsets) {
        for v in [key.level, key.x, key.y, key.z] {
            page.extend_from_slice(&v.to_le_bytes());
        }
        page.extend_from_slice(&off.to_le_bytes());
        page.extend_from_slice(&(bytes.len() as i32).to_le_bytes());
        page.extend_from_slice(&(idx.len() as i32).to_le_bytes());
    }
    let (mut qlo, mut qhi) = ([i32::MAX; 3], [i32::MIN; 3]);
    let mut by_return = [0u64; 15];
    for (_, lo, hi, r) in &chunks {
        for a in 0..3 {
            qlo[a] = qlo[a].min(lo[a]);
            qhi[a] = qhi[a].max(hi[a]);
        }
        for (t, v) in by_return.iter_mut().zip(r) {
            *t += v;
        }
    }
    let world = |q: [i32; 3]| DVec3::new(q[0] as f64, q[1] as f64, q[2] as f64) * scale + offset;
    let (wlo, whi) = (world(qlo), world(qhi));

    let mut h = vec![0u8; HEADER_SIZE];
    h[0..4].copy_from_slice(b"LASF");
    // Global encoding: WKT (required with point formats 6 and up).
    h[6..8].copy_from_slice(&16u16.to_le_bytes());
    h[24] = 1;
    h[25] = 4;
    let text = |h: &mut [u8], at: usize, s: &str| {
        let b = s.as_bytes();
        h[at..at + b.len().min(32)].copy_from_slice(&b[..b.len().min(32)]);
    };
    text(&mut h, 26, "stipple");
    text(&mut h, 58, concat!("stipple ", env!("CARGO_PKG_VERSION")));
    h[94..96].copy_from_slice(&(HEADER_SIZE as u16).to_le_bytes());
    h[96..100].copy_from_slice(&(point_data as u32).to_le_bytes());
    h[100..104].copy_from_slice(&2u32.to_le_bytes());
    h[104] = format | 0x80;
    h[105..107].copy_from_slice(&(rec as u16).to_le_bytes());
    for a in 0..3 {
        h[131 + a * 8..139 + a * 8].copy_from_slice(&scale.to_le_bytes());
        h[155 + a * 8..163 + a * 8].copy_from_slice(&offset[a].to_le_bytes());
        h[179 + a * 16..187 + a * 16].copy_from_slice(&whi[a].to_le_bytes());
        h[187 + a * 16..195 + a * 16].copy_from_slice(&wlo[a].to_le_bytes());
    }
    h[235..243].copy_from_slice(&evlr_at.to_le_bytes());
    h[243..247].copy_from_slice(&1u32.to_le_bytes());
    h[247..255].copy_from_slice(&(n as u64).to_le_bytes());
    for (t, v) in by_return.iter().enumerate() {
        h[255 + t * 8..263 + t * 8].copy_from_slice(&v.to_le_bytes());
    }
    let vlr_header = |uid: &str, record: u16, len: usize, what: &str| {
        let mut v = vec![0u8; VLR_HEADER];
        v[2..2 + uid.len()].copy_from_slice(uid.as_bytes());
        v[18..20].copy_from_slice(&record.to_le_bytes());
        v[20..22].copy_from_slice(&(len as u16).to_le_bytes());
        v[22..22 + what.len()].copy_from_slice(what.as_bytes());
        v
    };
    let mut info = vec![0u8; INFO_SIZE];
    let root_half = half as f64;
    for (a, v) in [
        center.x,
        center.y,
        center.z,
        root_half,
        side as f64 / GRID as f64,
    ]
    .iter()
    .enumerate()
    {
        info[a * 8..a * 8 + 8].copy_from_slice(&v.to_le_bytes());
    }
    info[40..48].copy_from_slice(&page_at.to_le_bytes());
    info[48..56].copy_from_slice(&(page.len() as u64).to_le_bytes());
    let mut evlr = vec![0u8; EVLR_HEADER];
    evlr[2..6].copy_from_slice(b"copc");
    evlr[18..20].copy_from_slice(&1000u16.to_le_bytes());
    evlr[20..28].copy_from_slice(&(page.len() as u64).to_le_bytes());
    evlr[28..28 + 19].copy_from_slice(b"COPC hierarchy page");

    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.{}.partial", std::process::id()));
    let write = || -> std::io::Result<()> {
        let f = std::fs::File::create(&tmp)?;
        let mut w = std::io::BufWriter::with_capacity(1 << 20, f);
        w.write_all(&h)?;
        w.write_all(&vlr_header("copc", 1, INFO_SIZE, "COPC info VLR"))?;
        w.write_all(&info)?;
        w.write_all(&vlr_header(
            "laszip encoded",
            22204,
            laz_data.len(),
            "laz variable chunks",
        ))?;
        w.write_all(&laz_data)?;
        w.write_all(&(chunk_table_at as i64).to_le_bytes())?;
        for (bytes, ..) in &chunks {
            w.write_all(bytes)?;
        }
        w.write_all(&table_bytes)?;
        w.write_all(&evlr)?;
        w.write_all(&page)?;
        let f = w.into_inner().map_err(|e| e.into_error())?;
        f.sync_all()?;
        Ok(())
    };
    if let Err(e) = write().and_then(|()| std::fs::rename(&tmp, path)) {
        let _ = std::fs::remove_file(&tmp);
        return Err(IoError::io(path, e));
    }
    let levels = nodes.iter().map(|(k, _)| k.level).max().unwrap_or(0) as usize + 1;
    Ok(CopcReport {
        points: n as u64,
        nodes: nodes.len(),
        levels,
        bytes: page_at + page.len() as u64,
    })
}

/// Nodes of `copc` chosen for a view: breadth first from the root by `priority` (larger
/// first; a node's children only after the node), until `budget` points. `priority` gets
/// a node's cube and point spacing (world units) and returns how much detail it adds to
/// the view (negative: none, e.g. outside the frustum), and children are considered only
/// where the node itself was taken.
pub fn select_nodes(
    copc: &Copc,
    budget: u64,
    priority: impl Fn(DVec3, DVec3, f64) -> f64,
) -> Vec<usize> {
    let by_key: HashMap<VoxelKey, usize> = copc
        .nodes
        .iter()
        .enumerate()
        .map(|(i, n)| (n.key, i))
        .collect();
    // Keys that hold points below them (a node without points of its own can still lead to
    // children with points).
    let mut has_below: HashSet<VoxelKey> = HashSet::new();
    for n in &copc.nodes {
        let mut k = n.key;
        while k.level > 0 {
            k = VoxelKey {
                level: k.level - 1,
                x: k.x >> 1,
                y: k.y >> 1,
                z: k.z >> 1,
            };
            if !has_below.insert(k) {
                break;
            }
        }
    }
    #[derive(PartialEq)]
    struct Cand(f64, VoxelKey);
    impl Eq for Cand {}
    impl PartialOrd for Cand {
        fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
            Some(self.cmp(o))
        }
    }
    impl Ord for Cand {
        fn cmp(&self, o: &Self) -> std::cmp::Ordering {
            self.0.total_cmp(&o.0).then(o.1.cmp(&self.1))
        }
    }
    let mut heap = std::collections::BinaryHeap::new();
    let mut out = Vec::new();
    let mut taken = 0u64;
    let root = VoxelKey::ROOT;
    let (lo, hi) = copc.cube(root);
    heap.push(Cand(
        priority(lo, hi, copc.spacing(root)).max(0.0) + f64::MAX / 4.0,
        root,
    ));
    while let Some(Cand(_, k)) = heap.pop() {
        if let Some(&i) = by_key.get(&k) {
            let c = copc.nodes[i].point_count;
            if taken + c > budget && !out.is_empty() {
                continue;
            }
            taken += c;
            out.push(i);
        }
        if !has_below.contains(&k) {
            continue;
        }
        for o in 0..8 {
            let ch = k.child(o);
            if !by_key.contains_key(&ch) && !has_below.contains(&ch) {
                continue;
            }
            let (lo, hi) = copc.cube(ch);
            let p = priority(lo, hi, copc.spacing(ch));
            if p >= 0.0 {
                heap.push(Cand(p, ch));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("stipple-copc-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// A sphere of radius 50 m around a georeferenced centre, with colours, intensity,
    /// classification and return numbers that vary from point to point.
    fn cloud(n: usize) -> PointCloud {
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut r = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f32 / (1u64 << 53) as f32
        };
        let mut c = PointCloud {
            origin: DVec3::new(637_000.0, 851_000.0, 120.0),
            intensity: Some(Vec::new()),
            classification: Some(Vec::new()),
            return_number: Some(Vec::new()),
            colors: Some(Vec::new()),
            z_up: true,
            ..Default::default()
        };
        for i in 0..n {
            let v = loop {
                let v = Vec3::new(r() * 2.0 - 1.0, r() * 2.0 - 1.0, r() * 2.0 - 1.0);
                if v.length_squared() > 0.01 && v.length_squared() <= 1.0 {
                    break v.normalize();
                }
            };
            c.positions.push(v * 50.0);
            c.intensity.as_mut().unwrap().push((i * 7 % 65536) as u16);
            c.classification.as_mut().unwrap().push((i % 19) as u8);
            c.return_number.as_mut().unwrap().push((i % 3 + 1) as u8);
            c.colors
                .as_mut()
                .unwrap()
                .push([(i % 256) as u8, (i / 256 % 256) as u8, 77]);
        }
        c
    }

    /// Every point's attributes (unique per point in [`cloud`]: colour gives i mod 65 536,
    /// class and return i mod 19 and 3) and world position, sorted by the attributes.
    type Row = ((u16, u8, u8, [u8; 3]), DVec3);
    fn rows(c: &PointCloud) -> Vec<Row> {
        let mut v: Vec<Row> = (0..c.len())
            .map(|i| {
                (
                    (
                        c.intensity.as_ref().unwrap()[i],
                        c.classification.as_ref().unwrap()[i],
                        c.return_number.as_ref().unwrap()[i],
                        c.colors.as_ref().unwrap()[i],
                    ),
                    c.world(i),
                )
            })
            .collect();
        v.sort_unstable_by_key(|a| a.0);
        v
    }

    /// The same points within `tol` (world units).
    fn same_points(a: &PointCloud, b: &PointCloud, tol: f64) {
        let (ra, rb) = (rows(a), rows(b));
        assert_eq!(ra.len(), rb.len());
        for (x, y) in ra.iter().zip(&rb) {
            assert_eq!(x.0, y.0);
            assert!((x.1 - y.1).abs().max_element() <= tol, "{} vs {}", x.1, y.1);
        }
    }

    #[test]
    fn a_written_copc_reads_back_as_the_same_points_and_a_valid_octree() {
        let d = dir("roundtrip");
        let path = d.join("sphere.copc.laz");
        let src = cloud(260_000);
        let report = write_copc(&path, &src).unwrap();
        assert_eq!(report.points, 260_000);
        assert!(report.levels >= 2, "{report:?}");
        assert!(is_copc(&path));
        let copc = Copc::open(&path).unwrap();
        assert_eq!(copc.point_count, 260_000);
        assert_eq!(copc.nodes.len(), report.nodes);
        assert_eq!(copc.format, 7);
        // Every node's points lie in its cube; the root spacing is the grid's.
        let origin = src.origin;
        for (i, n) in copc.nodes.iter().enumerate() {
            let part = copc.read_nodes(&[i], origin).unwrap();
            assert_eq!(part.len() as u64, n.point_count);
            let (lo, hi) = copc.cube(n.key);
            let slack = copc.scale.x;
            for p in 0..part.len() {
                let w = part.world(p);
                assert!(
                    w.cmpge(lo - slack).all() && w.cmple(hi + slack).all(),
                    "node {:?}: {w} outside {lo}..{hi}",
                    n.key
                );
            }
            assert!(n.point_count <= MAX_NODE_POINTS as u64);
        }
        assert!((copc.info.spacing - 2.0 * copc.info.halfsize / GRID as f64).abs() < 1e-9);
        // The same points, as our decoder of chosen nodes and as the `las` crate (a plain
        // LAZ reader that knows nothing of COPC) see them.
        let all: Vec<usize> = (0..copc.nodes.len()).collect();
        let ours = copc.read_nodes(&all, origin).unwrap();
        // Quantised to the file's scale (a power of ten at the positions' f32 precision).
        assert!(copc.scale.x <= 1e-4, "{}", copc.scale);
        same_points(&ours, &src, copc.scale.x);
        let flat = crate::read_cloud(&path).unwrap();
        same_points(&flat, &src, copc.scale.x);
        // The header's bounds are the points'.
        let (lo, hi) = src.world_bounds();
        assert!(
            (copc.min - lo).abs().max_element() < 1e-3,
            "{} {lo}",
            copc.min
        );
        assert!(
            (copc.max - hi).abs().max_element() < 1e-3,
            "{} {hi}",
            copc.max
        );
        // No temporary file is left beside it.
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_view_takes_coarse_nodes_first_within_the_budget() {
        let d = dir("select");
        let path = d.join("s.copc.laz");
        write_copc(&path, &cloud(400_000)).unwrap();
        let copc = Copc::open(&path).unwrap();
        assert!(copc.nodes.len() > 1);
        // Detail: spacing over distance from an eye on the +x side.
        let eye = copc.info.center + DVec3::new(200.0, 0.0, 0.0);
        let pri = |lo: DVec3, hi: DVec3, s: f64| s / ((lo + hi) * 0.5 - eye).length().max(1e-9);
        let root = copc
            .nodes
            .iter()
            .find(|n| n.key.level == 0)
            .unwrap()
            .point_count;
        let budget = root + 120_000;
        let sel = select_nodes(&copc, budget, pri);
        let taken: u64 = sel.iter().map(|&i| copc.nodes[i].point_count).sum();
        assert!(taken <= budget && taken > root, "{taken} of {budget}");
        assert_eq!(copc.nodes[sel[0]].key, VoxelKey::ROOT);
        // Children near the eye (x half) come before those far from it.
        let near = sel
            .iter()
            .filter(|&&i| copc.nodes[i].key.level == 1 && copc.nodes[i].key.x == 1)
            .count();
        let far = sel
            .iter()
            .filter(|&&i| copc.nodes[i].key.level == 1 && copc.nodes[i].key.x == 0)
            .count();
        assert!(near > far, "near {near}, far {far}");
        // Every chosen node's parent was chosen too (or holds no points).
        let keys: HashSet<VoxelKey> = sel.iter().map(|&i| copc.nodes[i].key).collect();
        for k in &keys {
            if k.level > 0 {
                let p = VoxelKey {
                    level: k.level - 1,
                    x: k.x >> 1,
                    y: k.y >> 1,
                    z: k.z >> 1,
                };
                assert!(keys.contains(&p), "{k:?} without its parent");
            }
        }
        // The whole budget: every node.
        assert_eq!(select_nodes(&copc, u64::MAX, pri).len(), copc.nodes.len());
        let _ = std::fs::remove_dir_all(&d);
    }

    /// Writes a COPC file of `n` points as `name` in a fresh folder, then changes its bytes
    /// with `edit` (bytes, root page offset, page size). Returns the folder and the file.
    fn patched(
        name: &str,
        n: usize,
        edit: impl Fn(&mut Vec<u8>, usize, usize),
    ) -> (PathBuf, PathBuf) {
        let d = dir(name.trim_end_matches(".copc.laz"));
        let path = d.join(name);
        write_copc(&path, &cloud(n)).unwrap();
        let mut b = std::fs::read(&path).unwrap();
        let info = HEADER_SIZE + VLR_HEADER;
        let page = le_u64(&b, info + 40) as usize;
        let size = le_u64(&b, info + 48) as usize;
        edit(&mut b, page, size);
        std::fs::write(&path, &b).unwrap();
        (d, path)
    }

    /// The error opening a small COPC file changed by `edit` (see `patched`) gives.
    fn broken(name: &str, edit: impl Fn(&mut Vec<u8>, usize, usize)) -> String {
        let (d, path) = patched(&format!("{name}-b.copc.laz"), 30_000, edit);
        let e = Copc::open(&path)
            .err()
            .expect("opened a broken file")
            .to_string();
        let _ = std::fs::remove_dir_all(&d);
        assert!(e.contains("-b.copc.laz"), "{e}");
        e
    }

    #[test]
    fn broken_hierarchies_are_clear_errors() {
        // The root page points beyond the file.
        let e = broken("outside", |b, _, _| {
            let at = HEADER_SIZE + VLR_HEADER + 40;
            b[at..at + 8].copy_from_slice(&(1u64 << 40).to_le_bytes());
        });
        assert!(e.contains("outside the file"), "{e}");
        // The root's entry becomes a page that is the root page itself: a loop.
        let e = broken("loop", |b, page, size| {
            b[page + 16..page + 24].copy_from_slice(&(page as u64).to_le_bytes());
            b[page + 24..page + 28].copy_from_slice(&(size as i32).to_le_bytes());
            b[page + 28..page + 32].copy_from_slice(&(-1i32).to_le_bytes());
        });
        assert!(e.contains("loops"), "{e}");
        // A child page overlapping the root page (starting 32 bytes into it).
        let e = broken("overlap", |b, page, size| {
            b[page + 16..page + 24].copy_from_slice(&(page as u64 + 32).to_le_bytes());
            b[page + 24..page + 28].copy_from_slice(&(size as i32 - 32).to_le_bytes());
            b[page + 28..page + 32].copy_from_slice(&(-1i32).to_le_bytes());
        });
        assert!(e.contains("overlap") || e.contains("listed twice"), "{e}");
        // A page size that is no multiple of an entry.
        let e = broken("size", |b, _, size| {
            let at = HEADER_SIZE + VLR_HEADER + 48;
            b[at..at + 8].copy_from_slice(&(size as u64 - 5).to_le_bytes());
        });
        assert!(e.contains("multiple of 32"), "{e}");
        // A point count that differs from the header's.
        let e = broken("count", |b, page, _| {
            let c = le_i32(b, page + 28);
            b[page + 28..page + 32].copy_from_slice(&(c + 1).to_le_bytes());
        });
        assert!(e.contains("lists") && e.contains("the header"), "{e}");
        // A key that is no octree node.
        let e = broken("key", |b, page, _| {
            b[page + 4..page + 8].copy_from_slice(&5i32.to_le_bytes());
        });
        assert!(e.contains("no octree node"), "{e}");
        // A chunk beyond the file.
        let e = broken("chunk", |b, page, _| {
            b[page + 16..page + 24].copy_from_slice(&(u64::MAX - 4).to_le_bytes());
        });
        assert!(e.contains("outside the file's point data"), "{e}");
        // Not COPC at all: a plain LAS 1.4 header without the info VLR.
        let e = broken("plain", |b, _, _| {
            b[HEADER_SIZE + 2..HEADER_SIZE + 6].copy_from_slice(b"xxxx");
        });
        assert!(e.contains("not a COPC file"), "{e}");
    }

    /// A node claiming 2³¹ − 1 points (with a header that agrees) opens, but reading it is
    /// refused before anything that size is allocated.
    #[test]
    fn a_node_claiming_billions_of_points_is_refused_before_allocating() {
        let (d, path) = patched("c.copc.laz", 30_000, |b, page, _| {
            b[page + 28..page + 32].copy_from_slice(&i32::MAX.to_le_bytes());
            b[247..255].copy_from_slice(&(i32::MAX as u64).to_le_bytes());
        });
        let e = Copc::open(&path).unwrap().read_nodes(&[0], DVec3::ZERO);
        let e = e.err().unwrap().to_string();
        assert!(
            e.contains("memory available") && e.contains("c.copc.laz"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&d);
    }

    /// A chunk whose layer table claims gigabytes (the `laz` crate would allocate them) is an
    /// error, whether the file is read as COPC or as plain LAZ (found by fuzzing).
    #[test]
    fn a_chunk_whose_layers_claim_gigabytes_is_refused() {
        // The root chunk follows the chunk-table offset; its first layer's size follows its
        // first point (36 bytes) and its point count.
        let (d, path) = patched("l.copc.laz", 3_000, |b, _, _| {
            let chunk = le_u32(b, 96) as usize + 8;
            let at = chunk + 36 + 4;
            b[at..at + 4].copy_from_slice(&0xF000_0000u32.to_le_bytes());
        });
        let e = Copc::open(&path).unwrap().read_nodes(&[0], DVec3::ZERO);
        let e = e.err().unwrap().to_string();
        assert!(
            e.contains("layers claim") && e.contains("l.copc.laz"),
            "{e}"
        );
        let e = crate::read_cloud(&path).err().unwrap().to_string();
        assert!(
            e.contains("layers claim") && e.contains("l.copc.laz"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn duplicate_points_and_a_single_point_are_written() {
        let d = dir("dups");
        let path = d.join("d.copc.laz");
        let mut c = cloud(1);
        let n = 150_000;
        c.positions = vec![Vec3::new(1.0, 2.0, 3.0); n];
        c.intensity = Some(vec![1; n]);
        c.classification = Some(vec![2; n]);
        c.return_number = Some(vec![1; n]);
        c.colors = None;
        let r = write_copc(&path, &c).unwrap();
        assert_eq!(r.points, n as u64);
        let copc = Copc::open(&path).unwrap();
        assert_eq!(copc.format, 6);
        let all: Vec<usize> = (0..copc.nodes.len()).collect();
        assert_eq!(copc.read_nodes(&all, c.origin).unwrap().len(), n);
        let one = cloud(1);
        write_copc(&path, &one).unwrap();
        assert_eq!(Copc::open(&path).unwrap().point_count, 1);
        let _ = std::fs::remove_dir_all(&d);
    }
}
