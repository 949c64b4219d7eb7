//! The gatherings' scratch buffers: the binning's and the work items', kept on the device from
//! gathering to gathering, and how any buffer the GPU fills is made (here, below the [`Gpu`]
//! that holds them, so that the two do not import each other).
//!
//! [`Gpu`]: super::Gpu

use super::records::ITEM_BYTES;

/// A buffer of `size` bytes that the GPU fills (not written on creation), bindable: never
/// empty, a whole number of words.
pub(super) fn buffer(device: &wgpu::Device, label: &str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(32).next_multiple_of(4),
        usage,
        mapped_at_creation: false,
    })
}

/// What a gathering needs of the scratch buffers: words of a round's regions (at least its
/// tiles' per segment), (tile, plane) pairs, work items, (plane, orientation) rows, and words
/// of the blocks' offsets and lists.
#[derive(Clone, Copy, Debug)]
pub(super) struct Need {
    pub(super) regions: u64,
    pub(super) pairs: u64,
    pub(super) items: u64,
    pub(super) orients: u64,
    pub(super) blocks: u64,
}

/// The scratch buffers of the binning and the work items, kept from gathering to gathering
/// (grown when one needs more): made a few times a process, not once a piece.
#[derive(Default)]
pub(super) struct Scratch {
    buffers: Option<ScratchBuffers>,
}

#[derive(Clone)]
pub(super) struct ScratchBuffers {
    /// Words of a round's regions (tiles + 1 a batch), (tile, plane) pairs, work items,
    /// (plane, orientation) rows and words of the blocks' lists they hold.
    capacity: (u64, u64, u64, u64, u64),
    /// Per tile and segment of a batch, its planes that reach the tile.
    pub(super) tile_counts: wgpu::Buffer,
    /// Per batch of a round (its region), per tile its first list entry, then the batch's end.
    pub(super) offsets: wgpu::Buffer,
    /// The gather's grid (x, y, 1) and the round's work items, then per batch of the round,
    /// per tile its first work item, then the batch's end: the gather is dispatched from its
    /// first bytes.
    pub(super) item_offsets: wgpu::Buffer,
    pub(super) list: wgpu::Buffer,
    /// Per list entry, the plane's pixel columns in the tile per group of pixel rows
    /// (`bin.wgsl`'s `ranges`).
    pub(super) ranges: wgpu::Buffer,
    pub(super) items: wgpu::Buffer,
    pub(super) partial: wgpu::Buffer,
    /// Each plane's further orientations (`gather.wgsl`'s `orients`).
    pub(super) orients: wgpu::Buffer,
    /// The binning's first tier: per block and segment its first entry, then the blocks' lists
    /// (`bin.wgsl`'s `blocks`).
    pub(super) blocks: wgpu::Buffer,
}

impl Scratch {
    /// Buffers for `need`'s words, pairs, items and rows (handles to them): those held if they
    /// are large enough, else new ones of the larger of each.
    pub(super) fn at_least(&mut self, device: &wgpu::Device, need: Need) -> ScratchBuffers {
        let Need { regions, pairs, items, orients, blocks } = need;
        let held = self.buffers.as_ref().map_or((0, 0, 0, 0, 0), |b| b.capacity);
        if held.0 < regions || held.1 < pairs || held.2 < items || held.3 < orients || held.4 < blocks {
            let (regions, pairs, items, orients, blocks) =
                (held.0.max(regions), held.1.max(pairs), held.2.max(items), held.3.max(orients), held.4.max(blocks));
            let storage = wgpu::BufferUsages::STORAGE;
            let words = regions * 4;
            // The old buffers are let go first (wgpu frees them once the work using them is done).
            self.buffers = None;
            self.buffers = Some(ScratchBuffers {
                capacity: (regions, pairs, items, orients, blocks),
                tile_counts: buffer(device, "tile counts", words, storage),
                offsets: buffer(device, "offsets", words, storage),
                item_offsets: buffer(device, "item offsets", words + 16, storage | wgpu::BufferUsages::INDIRECT),
                list: buffer(device, "list", pairs * 4, storage),
                ranges: buffer(device, "ranges", pairs * 4, storage),
                items: buffer(device, "items", items * 16, storage),
                partial: buffer(device, "partial", items * ITEM_BYTES, storage),
                orients: buffer(device, "orientations", orients * 16, storage),
                blocks: buffer(device, "blocks", blocks * 4, storage),
            });
        }
        self.buffers.clone().expect("made above")
    }
}
