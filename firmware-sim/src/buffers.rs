//! Owned buffers for `spiv-core` on the host: the core takes caller-supplied
//! slices (a sidecar passes static arrays); here they are `Vec`s.

use spiv_core::region::Region;
use spiv_core::state::Buffers;
use spiv_core::{History, Workspace, WorkspaceSizes};

/// Storage of a spike history ring.
#[derive(Debug, Clone)]
pub struct HistoryBuf {
    words: Vec<u64>,
    width: u16,
    height: u16,
    depth: u16,
}

impl HistoryBuf {
    /// Room for `depth` planes (1..=256) of a whole `width × height` camera.
    pub fn new(width: u16, height: u16, depth: u16) -> Result<Self, spiv_core::Error> {
        let n =
            History::words_needed(width, height, depth).ok_or(spiv_core::Error::BadDimensions)?;
        Ok(HistoryBuf {
            words: vec![0; n],
            width,
            height,
            depth,
        })
    }

    /// An empty history over the whole camera.
    pub fn history(&mut self) -> Result<History<'_>, spiv_core::Error> {
        History::new(
            &mut self.words,
            self.width,
            self.height,
            0,
            self.height,
            self.depth,
        )
    }

    /// The history over the whole camera as it stood before tick `next_tick`.
    pub fn resume(&mut self, next_tick: u32) -> Result<History<'_>, spiv_core::Error> {
        Ok(self.history()?.resumed(next_tick))
    }
}

/// Owned per-pixel working memory of the adaptive reconstruction.
#[derive(Debug, Clone)]
pub struct WorkspaceBuf {
    sizes: WorkspaceSizes,
    counts: Vec<u8>,
    c_t: Vec<u8>,
    class: Vec<u8>,
    labels: Vec<u16>,
    masks: Vec<u64>,
    tiles: Vec<u8>,
    parents: Vec<u16>,
    regions: Vec<Region>,
}

impl WorkspaceBuf {
    /// Buffers of the given sizes.
    pub fn new(sizes: WorkspaceSizes) -> Self {
        let px = sizes.pixels();
        WorkspaceBuf {
            sizes,
            counts: vec![0; px],
            c_t: vec![0; px],
            class: vec![0; px],
            labels: vec![0; px],
            masks: vec![0; sizes.mask_words()],
            tiles: vec![0; sizes.tiles()],
            parents: vec![0; sizes.parents()],
            regions: vec![Region::default(); usize::from(sizes.max_regions)],
        }
    }

    /// Buffers for a whole `width × height` frame in one strip.
    pub fn whole(width: u16, height: u16) -> Self {
        Self::new(WorkspaceSizes::for_strip(width, height))
    }

    /// The workspace over these buffers.
    pub fn workspace(&mut self) -> Workspace<'_> {
        // The buffers were sized from `sizes`, so this cannot fail.
        Workspace::new(
            self.sizes,
            Buffers {
                counts: &mut self.counts,
                c_t: &mut self.c_t,
                class: &mut self.class,
                labels: &mut self.labels,
                masks: &mut self.masks,
                tiles: &mut self.tiles,
                parents: &mut self.parents,
                regions: &mut self.regions,
            },
        )
        .expect("buffers sized from their own WorkspaceSizes")
    }
}
