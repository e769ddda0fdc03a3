//! The sparse tree of an exported grid (OpenVDB's `Tree_*_5_4_3`: a root map of 32^3 internal
//! nodes, each of 16^3 internal nodes, each of 8^3 leaves) and its two serialised passes,
//! topology and leaf buffers (`tree/RootNode.h`, `InternalNode.h`, `LeafNode.h`,
//! `io/Compression.h`).
//!
//! Every grid of one export shares the topology built from the density channel, so the tree is
//! built once and each grid only gathers its own values.

use std::io::Write;
use std::ops::Range;

use half::f16;
use rayon::prelude::*;

use super::bytes::PutBytes;
use crate::error::{beyond_half, invalid, Result};
use crate::grid::GridDims;
use crate::source::VolumeSource;
use crate::VoxelRange;

/// Voxels per leaf edge (log2 = 3).
const LEAF_DIM: usize = 8;
/// Voxels per edge of a lower internal node (16 leaves of 8).
const NODE4_SPAN: i32 = 128;
/// Voxels per edge of an upper internal node (32 lower nodes of 128).
const NODE5_SPAN: i32 = 4096;
/// `NO_MASK_OR_INACTIVE_VALS`: every inactive value equals the background, so (with active-mask
/// compression) only the active values follow.
const NODE_META_ACTIVE_ONLY: u8 = 0;
/// `NO_MASK_AND_ALL_VALS`: every value follows.
const NODE_META_ALL_VALUES: u8 = 6;

/// One stored leaf: its origin (a multiple of 8 in index space `(x, y, z)`) and its active mask,
/// bit `x << 6 | y << 3 | z` of the 512 (z fastest, as OpenVDB orders voxels).
#[derive(Debug, Clone)]
pub(crate) struct Leaf {
    pub(crate) origin: [i32; 3],
    pub(crate) mask: [u64; 8],
}

impl Leaf {
    /// Returns the active voxels' offsets in the leaf, in OpenVDB's storage order.
    fn active(&self) -> impl Iterator<Item = usize> + '_ {
        (0..512).filter(move |&i| self.mask[i >> 6] >> (i & 63) & 1 == 1)
    }
}

struct Node4 {
    child_mask: [u64; 64],
    leaves: Range<usize>,
}

struct Node5 {
    origin: [i32; 3],
    child_mask: Box<[u64; 512]>,
    nodes: Vec<Node4>,
}

/// The topology shared by the grids of one export: the leaves in depth-first order and the two
/// levels of internal nodes above them.
pub(crate) struct Topology {
    dims: GridDims,
    leaves: Vec<Leaf>,
    roots: Vec<Node5>,
}

/// How value arrays are stored.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Encoding {
    pub(crate) half: bool,
    pub(crate) zlib: bool,
}

/// What one grid stores: its name (for errors) and, per voxel, the values of consecutive
/// channels of the source (1 for float grids, 3 for vec3 grids).
pub(crate) struct GridValues<'a> {
    pub(crate) name: &'a str,
    pub(crate) channels: Range<usize>,
    /// Replaces NaN and infinities (validated beforehand when `None`).
    pub(crate) replace_non_finite: Option<f32>,
}

impl GridValues<'_> {
    fn fix(&self, v: f32) -> f32 {
        match self.replace_non_finite {
            Some(r) if !v.is_finite() => r,
            _ => v,
        }
    }

    /// Reads this grid's channels over `region` of `source`.
    fn read(&self, source: &dyn VolumeSource, region: VoxelRange) -> Result<Block> {
        Ok(Block {
            values: source.read_block(self.channels.clone(), &region)?,
            region,
        })
    }
}

/// Values of some channels over a region, as [`VolumeSource::read_block`] returns them.
struct Block {
    region: VoxelRange,
    values: Vec<f32>,
}

impl Block {
    /// The value of component `c` at voxel `(x, y, z)` of the whole grid (inside the region).
    fn at(&self, c: usize, [x, y, z]: [usize; 3]) -> f32 {
        let d = self.region.dims();
        let (r, at) = (&self.region, |v: usize, start: usize| v - start);
        self.values
            [c * d.voxel_count() + d.index(at(z, r.z.start), at(y, r.y.start), at(x, r.x.start))]
    }
}

/// The voxels of the cube of side `span` at `origin` (index space `(x, y, z)`) inside `dims`.
fn cube_region(origin: [i32; 3], span: usize, dims: GridDims) -> VoxelRange {
    let [x, y, z] = origin.map(|c| c as usize);
    VoxelRange {
        z: z..(z + span).min(dims.d),
        y: y..(y + span).min(dims.h),
        x: x..(x + span).min(dims.w),
    }
}

fn node5_origin(o: [i32; 3]) -> [i32; 3] {
    o.map(|c| c & !(NODE5_SPAN - 1))
}

/// Slot of a child in a 32^3 node, `x << 10 | y << 5 | z`.
fn node5_slot(o: [i32; 3]) -> usize {
    let [x, y, z] = o.map(|c| ((c & (NODE5_SPAN - 1)) >> 7) as usize);
    x << 10 | y << 5 | z
}

/// Slot of a leaf in a 16^3 node, `x << 8 | y << 4 | z`.
fn node4_slot(o: [i32; 3]) -> usize {
    let [x, y, z] = o.map(|c| ((c & (NODE4_SPAN - 1)) >> 3) as usize);
    x << 8 | y << 4 | z
}

fn set_bit(mask: &mut [u64], i: usize) {
    mask[i >> 6] |= 1 << (i & 63);
}

impl Topology {
    /// Builds the tree over the density grid of `source`: one leaf per 8^3 block that holds a
    /// voxel with density `> threshold`, whose active voxels are exactly those. Reads the
    /// density in slabs of whole leaves.
    pub(crate) fn build(
        source: &dyn VolumeSource,
        density: &GridValues<'_>,
        threshold: f32,
    ) -> Result<Self> {
        let dims = source.dims();
        if dims.xyz().iter().any(|&n| n > i32::MAX as usize - LEAF_DIM) {
            return Err(invalid(
                "dims",
                format!("{dims:?} exceeds the index range of a VDB grid (i32)"),
            ));
        }
        let blocks = dims.xyz().map(|n| n.div_ceil(LEAF_DIM));
        let slab_leaves = (source.slab_values() / (LEAF_DIM * dims.h * dims.w)).max(1);
        let mut leaves: Vec<Leaf> = Vec::new();
        for bz0 in (0..blocks[2]).step_by(slab_leaves) {
            let bzs = bz0..(bz0 + slab_leaves).min(blocks[2]);
            let z = bzs.start * LEAF_DIM..(bzs.end * LEAF_DIM).min(dims.d);
            let slab = density.read(source, VoxelRange::z_slab(dims, z))?;
            let per_slab = blocks[0] * blocks[1] * bzs.len();
            leaves.par_extend((0..per_slab).into_par_iter().filter_map(|b| {
                let (bx, by, bz) = (
                    b / (blocks[1] * bzs.len()),
                    b / bzs.len() % blocks[1],
                    bzs.start + b % bzs.len(),
                );
                let origin = [bx, by, bz].map(|c| c * LEAF_DIM);
                let mut mask = [0u64; 8];
                for x in origin[0]..(origin[0] + LEAF_DIM).min(dims.w) {
                    for y in origin[1]..(origin[1] + LEAF_DIM).min(dims.h) {
                        for z in origin[2]..(origin[2] + LEAF_DIM).min(dims.d) {
                            if density.fix(slab.at(0, [x, y, z])) > threshold {
                                set_bit(&mut mask, (x & 7) << 6 | (y & 7) << 3 | (z & 7));
                            }
                        }
                    }
                }
                mask.iter().any(|&m| m != 0).then(|| Leaf {
                    origin: origin.map(|c| c as i32),
                    mask,
                })
            }));
        }
        // Depth-first order: root children by origin (x, then y, then z, as OpenVDB's
        // `std::map<Coord, _>`), then child slots in index order.
        leaves.sort_by_key(|l| {
            (
                node5_origin(l.origin),
                node5_slot(l.origin),
                node4_slot(l.origin),
            )
        });

        let mut roots: Vec<Node5> = Vec::new();
        for (i, leaf) in leaves.iter().enumerate() {
            let origin5 = node5_origin(leaf.origin);
            if roots.last().is_none_or(|r| r.origin != origin5) {
                roots.push(Node5 {
                    origin: origin5,
                    child_mask: Box::new([0; 512]),
                    nodes: Vec::new(),
                });
            }
            let root = roots.last_mut().expect("pushed above");
            let slot5 = node5_slot(leaf.origin);
            if root.child_mask[slot5 >> 6] >> (slot5 & 63) & 1 == 0 {
                set_bit(&mut root.child_mask[..], slot5);
                root.nodes.push(Node4 {
                    child_mask: [0; 64],
                    leaves: i..i,
                });
            }
            let node = root.nodes.last_mut().expect("pushed above");
            set_bit(&mut node.child_mask, node4_slot(leaf.origin));
            node.leaves.end = i + 1;
        }
        Ok(Self {
            dims,
            leaves,
            roots,
        })
    }

    /// Returns the stored leaves in file order.
    pub(crate) fn leaves(&self) -> &[Leaf] {
        &self.leaves
    }

    /// Returns the number of active voxels.
    pub(crate) fn active_voxels(&self) -> u64 {
        self.leaves
            .iter()
            .flat_map(|l| l.mask)
            .map(|m| u64::from(m.count_ones()))
            .sum()
    }

    /// Returns the inclusive index bbox of the active voxels, or OpenVDB's empty box
    /// (`min = i32::MAX`, `max = i32::MIN`) when there are none.
    pub(crate) fn active_bbox(&self) -> ([i32; 3], [i32; 3]) {
        let mut lo = [i32::MAX; 3];
        let mut hi = [i32::MIN; 3];
        for leaf in &self.leaves {
            for i in leaf.active() {
                let p = [i >> 6, (i >> 3) & 7, i & 7];
                for a in 0..3 {
                    let c = leaf.origin[a] + p[a] as i32;
                    lo[a] = lo[a].min(c);
                    hi[a] = hi[a].max(c);
                }
            }
        }
        (lo, hi)
    }

    /// Appends the topology pass (`Tree::writeTopology`): buffer count, root background and
    /// child list, then depth first each internal node's child and value masks and its (empty)
    /// tile values, and each leaf's active mask.
    pub(crate) fn put_topology(&self, buf: &mut Vec<u8>, components: usize, enc: Encoding) {
        buf.put_i32(1);
        // The background (0) is stored at full precision even for half grids.
        buf.extend(std::iter::repeat_n(0u8, 4 * components));
        buf.put_u32(0); // root tiles
        buf.put_u32(self.roots.len() as u32);
        for root in &self.roots {
            root.origin.iter().for_each(|&c| buf.put_i32(c));
            put_internal(buf, &root.child_mask[..], components, enc);
            for node in &root.nodes {
                put_internal(buf, &node.child_mask, components, enc);
                for leaf in &self.leaves[node.leaves.clone()] {
                    leaf.mask
                        .iter()
                        .for_each(|&m| buf.extend_from_slice(&m.to_le_bytes()));
                }
            }
        }
    }

    /// Writes the buffer pass (`Tree::writeBuffers`) of one grid: per leaf, in the topology's
    /// order, the active mask and the active values (all other values are the background 0).
    /// Reads the grid's values one lower internal node (a 128^3 brick) at a time and encodes its
    /// leaves in parallel. Fails if a half-float grid gets a value beyond the half range.
    pub(crate) fn write_buffers(
        &self,
        w: &mut dyn FnMut(&[u8]) -> Result<()>,
        source: &dyn VolumeSource,
        grid: &GridValues<'_>,
        enc: Encoding,
    ) -> Result<()> {
        for node in self.roots.iter().flat_map(|r| &r.nodes) {
            let leaves = &self.leaves[node.leaves.clone()];
            let origin = leaves[0].origin.map(|c| c & !(NODE4_SPAN - 1));
            let brick = grid.read(source, cube_region(origin, NODE4_SPAN as usize, self.dims))?;
            let chunks: Vec<Vec<u8>> = leaves
                .par_iter()
                .map(|leaf| leaf_buffer(leaf, &brick, grid, enc))
                .collect::<Result<_>>()?;
            chunks.iter().try_for_each(|c| w(c))?;
        }
        Ok(())
    }
}

/// One leaf's buffer: its active mask, then its active values from `brick`.
fn leaf_buffer(
    leaf: &Leaf,
    brick: &Block,
    grid: &GridValues<'_>,
    enc: Encoding,
) -> Result<Vec<u8>> {
    let components = grid.channels.len();
    let mut out = Vec::with_capacity(65 + 512 * 4 * components);
    leaf.mask
        .iter()
        .for_each(|&m| out.extend_from_slice(&m.to_le_bytes()));
    out.put_u8(NODE_META_ACTIVE_ONLY);
    let bytes_per = if enc.half { 2 } else { 4 };
    let mut raw = Vec::with_capacity(512 * bytes_per * components);
    for i in leaf.active() {
        let xyz = [
            leaf.origin[0] as usize + (i >> 6),
            leaf.origin[1] as usize + ((i >> 3) & 7),
            leaf.origin[2] as usize + (i & 7),
        ];
        for c in 0..components {
            let v = grid.fix(brick.at(c, xyz));
            if enc.half {
                let h = f16::from_f32(v);
                if h.is_infinite() && v.is_finite() {
                    let [x, y, z] = xyz;
                    return Err(beyond_half(
                        &format!("grid `{}`", grid.name),
                        v,
                        &format!("index ({x}, {y}, {z})"),
                    ));
                }
                raw.extend_from_slice(&h.to_le_bytes());
            } else {
                raw.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    put_values(&mut out, &raw, enc);
    Ok(out)
}

/// Appends an internal node's child mask, an all-off value mask (no tiles) and its value array.
///
/// Under active-mask compression the array holds no values, except for zlib-compressed half
/// grids: there OpenVDB's `HalfReader` reads nothing at all for an empty array while vdb-rs still
/// reads a zip byte count, so the two readers would fall out of step. Storing all (zero) values
/// keeps both in step, at about a hundred compressed bytes per node.
fn put_internal(buf: &mut Vec<u8>, child_mask: &[u64], components: usize, enc: Encoding) {
    child_mask
        .iter()
        .for_each(|&m| buf.extend_from_slice(&m.to_le_bytes()));
    buf.extend(std::iter::repeat_n(0u8, child_mask.len() * 8));
    if enc.half && enc.zlib {
        buf.put_u8(NODE_META_ALL_VALUES);
        let slots = child_mask.len() * 64;
        put_values(buf, &vec![0u8; slots * components * 2], enc);
    } else {
        buf.put_u8(NODE_META_ACTIVE_ONLY);
        put_values(buf, &[], enc);
    }
}

/// Appends an encoded value array as `io::writeData` does: raw bytes, or with zlib an `i64`
/// byte count and the stream, where a negative count means the `-n` raw bytes that follow
/// (used when compression would not shrink them, as OpenVDB's `zipToStream` does).
fn put_values(buf: &mut Vec<u8>, raw: &[u8], enc: Encoding) {
    if !enc.zlib {
        buf.extend_from_slice(raw);
        return;
    }
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    z.write_all(raw)
        .expect("compressing into memory cannot fail");
    let zipped = z.finish().expect("compressing into memory cannot fail");
    if zipped.len() < raw.len() {
        buf.put_i64(zipped.len() as i64);
        buf.extend_from_slice(&zipped);
    } else {
        buf.put_i64(-(raw.len() as i64));
        buf.extend_from_slice(raw);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_follow_openvdb_order() {
        assert_eq!(node4_slot([8, 0, 0]), 256);
        assert_eq!(node4_slot([0, 8, 0]), 16);
        assert_eq!(node4_slot([0, 0, 8]), 1);
        assert_eq!(node5_slot([128, 0, 0]), 1024);
        assert_eq!(node5_origin([4100, 8, 0]), [4096, 0, 0]);
    }

    #[test]
    fn leaves_cover_occupied_blocks_only() {
        let dims = GridDims::new(9, 3, 17); // z, y, x
        let mut values = vec![0f32; 4 * dims.voxel_count()];
        values[dims.index(8, 2, 16)] = 1.0; // block (2, 0, 1)
        values[dims.index(0, 0, 0)] = 0.5; // block (0, 0, 0), below the threshold
        let tensor = candle_core::Tensor::from_vec(
            values,
            (4, dims.d, dims.h, dims.w),
            &candle_core::Device::Cpu,
        )
        .unwrap();
        let volume = crate::RadianceVolume::new(tensor, crate::Aabb::CUBE).unwrap();
        let g = GridValues {
            name: "density",
            channels: 0..1,
            replace_non_finite: None,
        };
        let t = Topology::build(&volume, &g, 0.5).unwrap();
        assert_eq!(t.leaves().len(), 1);
        assert_eq!(t.leaves()[0].origin, [16, 0, 8]);
        assert_eq!(t.active_voxels(), 1);
        assert_eq!(t.active_bbox(), ([16, 2, 8], [16, 2, 8]));
    }
}
