//! Owned buffers for the core on a host (`std` feature): the core takes
//! caller-supplied slices (a sidecar passes static arrays); here they are
//! `Vec`s, sized by the same functions.

use std::vec;
use std::vec::Vec;

use crate::downlink::DownlinkBuffers;
use crate::gray::Gray;
use crate::history::History;
use crate::region::Region;
use crate::sidecar::{Config, Memory};
use crate::state::{Buffers, Workspace, WorkspaceSizes};
use crate::wire::sender::SendBuffers;
use crate::wire::{MAX_ENCODED, MAX_PAYLOAD};
use crate::Error;

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
    pub fn new(width: u16, height: u16, depth: u16) -> Result<Self, Error> {
        let n = History::words_needed(width, height, depth).ok_or(Error::BadDimensions)?;
        Ok(HistoryBuf {
            words: vec![0; n],
            width,
            height,
            depth,
        })
    }

    /// An empty history over the whole camera.
    pub fn history(&mut self) -> Result<History<'_>, Error> {
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
    pub fn resume(&mut self, next_tick: u32) -> Result<History<'_>, Error> {
        Ok(self.history()?.resumed(next_tick))
    }
}

/// Owned per-pixel working memory of the adaptive reconstruction.
#[derive(Debug, Clone)]
pub struct WorkspaceBuf {
    sizes: WorkspaceSizes,
    counts: Vec<u64>,
    c_t: Vec<u8>,
    class: Vec<u8>,
    labels: Vec<u16>,
    masks: Vec<u64>,
    tiles: Vec<u8>,
    parents: Vec<u16>,
    regions: Vec<Region>,
    mc: Vec<u8>,
}

impl WorkspaceBuf {
    /// Buffers of the given sizes.
    pub fn new(sizes: WorkspaceSizes) -> Self {
        let px = sizes.pixels();
        WorkspaceBuf {
            sizes,
            counts: vec![0; sizes.count_words()],
            c_t: vec![0; px],
            class: vec![0; px],
            labels: vec![0; px],
            masks: vec![0; sizes.mask_words()],
            tiles: vec![0; sizes.tiles()],
            parents: vec![0; sizes.parents()],
            regions: vec![Region::default(); usize::from(sizes.max_regions)],
            mc: vec![0; px],
        }
    }

    /// Buffers for a whole `width × height` frame in one strip.
    pub fn whole(width: u16, height: u16) -> Self {
        Self::new(WorkspaceSizes::for_strip(width, height))
    }

    /// The workspace over these buffers (with the motion-compensated
    /// counts). The buffers were sized from their own sizes, so the core's
    /// checks pass; they are still checked, never assumed.
    pub fn workspace(&mut self) -> Result<Workspace<'_>, Error> {
        let mc = &mut self.mc;
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
        .and_then(|ws| ws.with_motion_counts(mc))
    }
}

/// Everything the [`crate::sidecar`] loop borrows, owned: history, adaptive
/// workspace, one frame of `G`, TFP counts, the sender's buffers and the
/// window caps.
#[derive(Debug, Clone)]
pub struct SidecarBuf<G> {
    history: HistoryBuf,
    workspace: WorkspaceBuf,
    frame: Vec<G>,
    counts: Vec<u8>,
    payload: Vec<u8>,
    wire: Vec<u8>,
    scratch: Vec<u16>,
    downlink_rx: Vec<u8>,
    /// Applied and waiting velocities per stored row and tile column (the
    /// finest grid: one column per 64-px word): vx, vy, next vx, next vy.
    rows: [Vec<i16>; 4],
    /// Applied and waiting caps.
    caps: [Vec<u16>; 2],
    refined: (Vec<i16>, Vec<i16>),
}

impl<G: Gray> SidecarBuf<G> {
    /// Buffers for a `width × height` sensor running `cfg`: a history of
    /// [`Config::depth`] planes, TFP counts only for TFP, codec scratch only
    /// for the sparse encoding.
    pub fn new(width: u16, height: u16, cfg: &Config) -> Result<Self, Error> {
        let m = cfg
            .memory_sizes(width, height)
            .ok_or(Error::BadDimensions)?;
        Ok(SidecarBuf {
            history: HistoryBuf::new(width, height, m.depth)?,
            workspace: WorkspaceBuf::new(m.workspace),
            frame: vec![G::from_level(0); m.frame],
            counts: vec![0; m.tfp_counts],
            payload: vec![0; MAX_PAYLOAD],
            wire: vec![0; MAX_ENCODED],
            scratch: vec![0; m.codec_scratch],
            downlink_rx: vec![0; crate::wire::control::MAX_CONTROL_ENCODED],
            rows: core::array::from_fn(|_| vec![0; m.motion_entries]),
            caps: core::array::from_fn(|_| vec![0; m.cap_bands]),
            refined: (vec![0; m.refined], vec![0; m.refined]),
        })
    }

    /// The memory for the next call of the loop, the history resumed at
    /// `next_tick` ([`crate::sidecar::Sidecar::next_tick`]).
    pub fn memory(&mut self, next_tick: u32) -> Result<Memory<'_, G>, Error> {
        Ok(Memory {
            history: self.history.resume(next_tick)?,
            workspace: self.workspace.workspace()?,
            frame: &mut self.frame,
            counts: &mut self.counts,
            send: SendBuffers {
                payload: &mut self.payload,
                wire: &mut self.wire,
                scratch: &mut self.scratch,
            },
            downlink: Self::downlink_of(&mut self.downlink_rx, &mut self.rows, &mut self.caps),
            refine: crate::sidecar::RefineBuffers {
                vx: &mut self.refined.0,
                vy: &mut self.refined.1,
            },
        })
    }

    /// The downlink's buffers alone (to hear control messages between
    /// planes).
    pub fn downlink(&mut self) -> DownlinkBuffers<'_> {
        Self::downlink_of(&mut self.downlink_rx, &mut self.rows, &mut self.caps)
    }

    fn downlink_of<'a>(
        rx: &'a mut [u8],
        rows: &'a mut [Vec<i16>; 4],
        caps: &'a mut [Vec<u16>; 2],
    ) -> DownlinkBuffers<'a> {
        let [vx, vy, next_vx, next_vy] = rows;
        let [caps, next_caps] = caps;
        DownlinkBuffers {
            rx,
            vx,
            vy,
            caps,
            next_vx,
            next_vy,
            next_caps,
        }
    }

    /// The sender's buffers alone (for the final status).
    pub fn send(&mut self) -> SendBuffers<'_> {
        SendBuffers {
            payload: &mut self.payload,
            wire: &mut self.wire,
            scratch: &mut self.scratch,
        }
    }
}

/// Storage of the static-light model's per-pixel state
/// ([`crate::light::LightState`], [`crate::light::LIGHT_BYTES_PER_PIXEL`]
/// bytes per pixel).
#[derive(Debug, Clone)]
pub struct LightBuf {
    last: Vec<u16>,
    period: Vec<u16>,
    rate: Vec<u32>,
    short: Vec<u16>,
    lead: Vec<i8>,
    flags: Vec<u8>,
}

impl LightBuf {
    /// Zeroed state for `pixels` pixels (a fresh model).
    pub fn new(pixels: usize) -> Self {
        LightBuf {
            last: vec![0; pixels],
            period: vec![0; pixels],
            rate: vec![0; pixels],
            short: vec![0; pixels],
            lead: vec![0; pixels],
            flags: vec![0; pixels],
        }
    }

    /// The state borrowed for [`crate::light::Light::new`] or
    /// [`crate::light::Light::resume`].
    pub fn state(&mut self) -> crate::light::LightState<'_> {
        crate::light::LightState {
            last: &mut self.last,
            period: &mut self.period,
            rate: &mut self.rate,
            short: &mut self.short,
            lead: &mut self.lead,
            flags: &mut self.flags,
        }
    }
}

/// A [`crate::warp::Flow`] owned: what a sidecar keeps of the last ask it
/// heard while the next one is put together in the assembly's slices.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FlowBuf {
    /// Nodes across (0: no motion).
    pub nx: u16,
    /// Nodes down (0: no motion).
    pub ny: u16,
    /// x of column 0, 1/16 px.
    pub x0: i32,
    /// y of row 0, 1/16 px.
    pub y0: i32,
    /// Node spacing, 1/16 px.
    pub pitch: u16,
    /// x velocity per node, Q12 px/tick, `ny × nx` row-major.
    pub vx: Vec<i16>,
    /// y velocity, as `vx`.
    pub vy: Vec<i16>,
    /// x acceleration along the path, Q16 px/tick², as `vx`.
    pub ax: Vec<i16>,
    /// y acceleration, as `vx`.
    pub ay: Vec<i16>,
}

impl FlowBuf {
    /// No motion ([`crate::warp::Flow::still`]).
    pub fn still() -> FlowBuf {
        FlowBuf::of(&crate::warp::Flow::still())
    }

    /// `f`, owned.
    pub fn of(f: &crate::warp::Flow<'_>) -> FlowBuf {
        if f.is_still() {
            return FlowBuf {
                nx: 0,
                ny: 0,
                x0: 0,
                y0: 0,
                pitch: 16,
                vx: Vec::new(),
                vy: Vec::new(),
                ax: Vec::new(),
                ay: Vec::new(),
            };
        }
        FlowBuf {
            nx: f.nx,
            ny: f.ny,
            x0: f.x0,
            y0: f.y0,
            pitch: f.pitch,
            vx: f.vx.to_vec(),
            vy: f.vy.to_vec(),
            ax: f.ax.to_vec(),
            ay: f.ay.to_vec(),
        }
    }

    /// Whether this is no motion.
    pub fn is_still(&self) -> bool {
        self.nx == 0 || self.ny == 0
    }

    /// The core's view.
    pub fn view(&self) -> crate::warp::Flow<'_> {
        crate::warp::Flow {
            nx: self.nx,
            ny: self.ny,
            x0: self.x0,
            y0: self.y0,
            pitch: self.pitch,
            vx: &self.vx,
            vy: &self.vy,
            ax: &self.ax,
            ay: &self.ay,
        }
    }
}
