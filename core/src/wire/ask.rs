//! The live loop's downlink payload ([`super::Kind::Ask`]): what the host's
//! estimator asks the sidecar to make of the pairs from `from_pair` on —
//! the separations of the rung frames, the ticks of events around each
//! pair's midpoint, and the flow on a grid of nodes the rung frames are
//! warped along ([`crate::warp::Flow`], stored order).
//!
//! ```text
//! payload = from_pair u32 | reach u16 | count u8 | reserved u8 |
//!           separations 8 × u16 |
//!           nx u16 | ny u16 | x0 i32 | y0 i32 | pitch u16 | row0 u16 |
//!           rows × nx × (vx i16, vy i16, ax i16, ay i16)
//! ```
//!
//! - `count`: separations in use (at most [`MAX_RUNGS`]), ticks, shortest
//!   first; the rest of the eight are 0.
//! - `reach`: ticks on each side of the midpoint whose events the pair
//!   carries (0: none).
//! - The flow: node `(r, c)` at `(x0 + c·pitch, y0 + r·pitch)` in 1/16 px;
//!   `vx, vy` in 1/4096 px per tick, `ax, ay` in 1/65536 px per tick²;
//!   `nx·ny = 0` is no flow (no rung frames can follow it). A message
//!   carries node rows `row0..row0 + rows` (`rows` from its length), at
//!   most [`MAX_ASK_NODES`] nodes, so that a payload fits one message; an
//!   ask of more nodes (at most [`MAX_FLOW_NODES`]) is sent as consecutive
//!   parts from row 0 ([`ask_parts`]), each with the whole head, and
//!   [`AskAssembly`] puts them together in caller-supplied slices.
//!
//! Parsing checks every length and range before anything is read; the
//! nodes are read in place ([`AskView::node`]).

use super::{WireError, MAX_PAYLOAD};
use crate::error::Error;
use crate::rungs::{Rungs, MAX_RUNGS};
use crate::warp::{Flow, MAX_PITCH};

/// Bytes before the nodes.
pub const ASK_HEAD: usize = 40;

/// Bytes per node.
const NODE: usize = 8;

/// Most nodes one ask message carries (a 400 × 250 sensor on an 8-px
/// grid has 1,550).
pub const MAX_ASK_NODES: usize = 2040;

/// Most nodes of a whole ask (a 4096 × 4096 sensor on a 16-px grid).
pub const MAX_FLOW_NODES: usize = 1 << 16;

const _: () = assert!(ASK_HEAD + NODE * MAX_ASK_NODES <= MAX_PAYLOAD);

/// Largest ask payload, bytes.
pub const MAX_ASK_PAYLOAD: usize = ASK_HEAD + NODE * MAX_ASK_NODES;

/// The fixed part of an ask.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AskHead {
    /// First pair it applies to.
    pub from_pair: u32,
    /// Rung separations and the events' reach.
    pub rungs: Rungs,
    /// Nodes across (0: no flow).
    pub nx: u16,
    /// Nodes down (0: no flow).
    pub ny: u16,
    /// x of node column 0, 1/16 px.
    pub x0: i32,
    /// y of node row 0, 1/16 px.
    pub y0: i32,
    /// Node spacing, 1/16 px.
    pub pitch: u16,
    /// First node row this message carries.
    pub row0: u16,
}

/// A checked ask payload, read in place.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AskView<'a> {
    /// The fixed part.
    pub head: AskHead,
    nodes: &'a [u8],
}

fn u16_at(b: &[u8], i: usize) -> u16 {
    match b.get(i..i + 2) {
        Some(s) => u16::from_le_bytes([s[0], s[1]]),
        None => 0,
    }
}

fn i32_at(b: &[u8], i: usize) -> i32 {
    match b.get(i..i + 4) {
        Some(s) => i32::from_le_bytes([s[0], s[1], s[2], s[3]]),
        None => 0,
    }
}

/// Whether `head` describes rungs and a grid the core can make frames of:
/// at most [`MAX_RUNGS`] separations, each at least 1 tick; with nodes, at
/// most [`MAX_FLOW_NODES`] of them, a pitch in `16..=MAX_PITCH` and an
/// origin within 2^24 sixteenths of a pixel; the message's `rows` node
/// rows from `row0` within the grid and at most [`MAX_ASK_NODES`] nodes.
fn head_ok(h: &AskHead, rows: usize) -> bool {
    let count = usize::from(h.rungs.count);
    if count > MAX_RUNGS || h.rungs.separations[..count].contains(&0) {
        return false;
    }
    let (nx, ny) = (usize::from(h.nx), usize::from(h.ny));
    if nx * ny == 0 {
        return h.row0 == 0 && rows == 0;
    }
    nx * ny <= MAX_FLOW_NODES
        && rows >= 1
        && nx * rows <= MAX_ASK_NODES
        && usize::from(h.row0) + rows <= ny
        && (16..=MAX_PITCH).contains(&h.pitch)
        && h.x0.unsigned_abs() < 1 << 24
        && h.y0.unsigned_abs() < 1 << 24
}

impl<'a> AskView<'a> {
    /// Parses and checks a payload ([`head_ok`]'s ranges, and a length of
    /// exactly the head and its nodes).
    pub fn parse(b: &'a [u8]) -> Result<Self, Error> {
        if b.len() < ASK_HEAD {
            return Err(WireError::Payload.into());
        }
        let mut separations = [0u16; MAX_RUNGS];
        for (k, s) in separations.iter_mut().enumerate() {
            *s = u16_at(b, 8 + 2 * k);
        }
        let head = AskHead {
            from_pair: u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            rungs: Rungs {
                separations,
                count: b[6],
                reach: u16_at(b, 4),
            },
            nx: u16_at(b, 24),
            ny: u16_at(b, 26),
            x0: i32_at(b, 28),
            y0: i32_at(b, 32),
            pitch: u16_at(b, 36),
            row0: u16_at(b, 38),
        };
        let body = b.len() - ASK_HEAD;
        let row = NODE * usize::from(head.nx).max(1);
        if !body.is_multiple_of(row) || !head_ok(&head, body / row) {
            return Err(WireError::Payload.into());
        }
        // Separations past `count` are not the ask's.
        let mut head = head;
        head.rungs.separations[usize::from(head.rungs.count)..].fill(0);
        Ok(AskView {
            head,
            nodes: &b[ASK_HEAD..],
        })
    }

    /// Nodes this message carries.
    pub fn nodes(&self) -> usize {
        self.nodes.len() / NODE
    }

    /// Node rows this message carries (from [`AskHead::row0`]).
    pub fn rows(&self) -> usize {
        self.nodes() / usize::from(self.head.nx).max(1)
    }

    /// Node `i` of this message (row-major from row `row0`): `(vx, vy, ax,
    /// ay)`; zeros past the end.
    pub fn node(&self, i: usize) -> (i16, i16, i16, i16) {
        let at = |k: usize| u16_at(self.nodes, NODE * i + 2 * k) as i16;
        (at(0), at(1), at(2), at(3))
    }
}

/// ```
/// use spiv_core::rungs::Rungs;
/// use spiv_core::warp::Flow;
/// use spiv_core::wire::ask::{ask_parts, encode_ask, AskView, MAX_ASK_PAYLOAD};
///
/// # fn main() -> Result<(), spiv_core::Error> {
/// let v = [410i16; 6]; // 0.1 px per tick
/// let flow = Flow { nx: 3, ny: 2, x0: 128, y0: 128, pitch: 256, vx: &v, vy: &v, ax: &v, ay: &v };
/// let mut rungs = Rungs::events(0);
/// rungs.separations[..2].copy_from_slice(&[16, 32]);
/// rungs.count = 2;
/// let parts: Vec<_> = ask_parts(&flow).collect();
/// assert_eq!(parts, vec![(0, 2)]);
/// let mut buf = vec![0u8; MAX_ASK_PAYLOAD];
/// let n = encode_ask(5, &rungs, &flow, parts[0], &mut buf)?;
/// let ask = AskView::parse(&buf[..n])?;
/// assert_eq!((ask.head.from_pair, ask.nodes()), (5, 6));
/// assert_eq!(ask.node(4), (410, 410, 410, 410));
/// # Ok(())
/// # }
/// ```
///
/// Writes the ask message payload that carries node rows `row0..row0 +
/// rows` of `flow` (all of them: [`ask_parts`]) into `out`, with
/// `from_pair` and `rungs`; returns its length. A still flow has no rows
/// (`row0 = rows = 0`). Refused ([`WireError::Payload`]) when the rungs,
/// the flow or the rows are out of the ranges a sidecar takes, or the
/// flow's slices are not `nx·ny` long.
pub fn encode_ask(
    from_pair: u32,
    rungs: &Rungs,
    flow: &Flow<'_>,
    (row0, rows): (u16, u16),
    out: &mut [u8],
) -> Result<usize, Error> {
    let still = flow.is_still();
    let head = AskHead {
        from_pair,
        rungs: *rungs,
        nx: if still { 0 } else { flow.nx },
        ny: if still { 0 } else { flow.ny },
        x0: if still { 0 } else { flow.x0 },
        y0: if still { 0 } else { flow.y0 },
        pitch: if still { 16 } else { flow.pitch },
        row0,
    };
    let nx = usize::from(head.nx);
    let n = nx * usize::from(rows);
    if !head_ok(&head, usize::from(rows)) || (!still && flow.check().is_err()) {
        return Err(WireError::Payload.into());
    }
    let len = ASK_HEAD + NODE * n;
    let out = out.get_mut(..len).ok_or(WireError::TooLarge)?;
    out[..ASK_HEAD].fill(0);
    out[0..4].copy_from_slice(&head.from_pair.to_le_bytes());
    out[4..6].copy_from_slice(&head.rungs.reach.to_le_bytes());
    out[6] = head.rungs.count;
    for (k, s) in head.rungs.separations().iter().enumerate() {
        out[8 + 2 * k..10 + 2 * k].copy_from_slice(&s.to_le_bytes());
    }
    out[24..26].copy_from_slice(&head.nx.to_le_bytes());
    out[26..28].copy_from_slice(&head.ny.to_le_bytes());
    out[28..32].copy_from_slice(&head.x0.to_le_bytes());
    out[32..36].copy_from_slice(&head.y0.to_le_bytes());
    out[36..38].copy_from_slice(&head.pitch.to_le_bytes());
    out[38..40].copy_from_slice(&head.row0.to_le_bytes());
    let first = nx * usize::from(row0);
    for k in 0..n {
        let (o, i) = (ASK_HEAD + NODE * k, first + k);
        for (j, v) in [flow.vx[i], flow.vy[i], flow.ax[i], flow.ay[i]]
            .into_iter()
            .enumerate()
        {
            out[o + 2 * j..o + 2 * j + 2].copy_from_slice(&v.to_le_bytes());
        }
    }
    Ok(len)
}

/// The node rows of each message of an ask of `flow`: `(row0, rows)`
/// parts of at most [`MAX_ASK_NODES`] nodes, in order (one part of no rows
/// for a still flow). Empty when a row alone is over the limit.
pub fn ask_parts(flow: &Flow<'_>) -> impl Iterator<Item = (u16, u16)> {
    let (nx, ny) = if flow.is_still() {
        (0, 0)
    } else {
        (usize::from(flow.nx), usize::from(flow.ny))
    };
    let per = MAX_ASK_NODES.checked_div(nx).unwrap_or(1);
    let parts = if nx == 0 {
        1
    } else if per == 0 {
        0
    } else {
        ny.div_ceil(per)
    };
    (0..parts).map(move |k| {
        let r0 = k * per;
        let rows = if nx == 0 { 0 } else { per.min(ny - r0) };
        (r0 as u16, rows as u16)
    })
}

/// An ask put together from its messages, in the caller's slices: parts
/// must come in order from row 0 ([`ask_parts`]); a part of a newer ask
/// starts it again, and one that does not follow (another ask's, a gap, a
/// repeat) is refused.
#[derive(Debug)]
pub struct AskAssembly<'a> {
    vx: &'a mut [i16],
    vy: &'a mut [i16],
    ax: &'a mut [i16],
    ay: &'a mut [i16],
    head: Option<AskHead>,
    rows: usize,
}

/// Where an [`AskAssembly`] stands besides its slices: an assembly taken
/// apart ([`AskAssembly::progress`]) and made again over the same slices
/// ([`AskAssembly::resume`]) goes on with the ask it was putting together.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AskProgress {
    head: Option<AskHead>,
    rows: usize,
}

/// What a part did to an [`AskAssembly`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Part {
    /// The ask is whole: [`AskAssembly::head`] and [`AskAssembly::flow`].
    Whole,
    /// Taken; more rows to come.
    Taken,
    /// Not taken: it does not continue the ask being put together, or its
    /// flow is larger than the slices.
    Refused,
}

impl<'a> AskAssembly<'a> {
    /// An assembly into `vx, vy, ax, ay` (each as long as the largest
    /// flow it will take, at most [`MAX_FLOW_NODES`]).
    pub fn new(vx: &'a mut [i16], vy: &'a mut [i16], ax: &'a mut [i16], ay: &'a mut [i16]) -> Self {
        AskAssembly {
            vx,
            vy,
            ax,
            ay,
            head: None,
            rows: 0,
        }
    }

    /// An assembly into the slices an assembly at `progress` used, going
    /// on where it stood.
    pub fn resume(
        vx: &'a mut [i16],
        vy: &'a mut [i16],
        ax: &'a mut [i16],
        ay: &'a mut [i16],
        progress: AskProgress,
    ) -> Self {
        AskAssembly {
            head: progress.head,
            rows: progress.rows,
            ..AskAssembly::new(vx, vy, ax, ay)
        }
    }

    /// Where it stands ([`AskAssembly::resume`]).
    pub fn progress(&self) -> AskProgress {
        AskProgress {
            head: self.head,
            rows: self.rows,
        }
    }

    /// Takes one message's ask.
    pub fn take(&mut self, part: &AskView<'_>) -> Part {
        let h = part.head;
        let same = self.head.is_some_and(|a| {
            (a.from_pair, a.rungs, a.nx, a.ny, a.x0, a.y0, a.pitch)
                == (h.from_pair, h.rungs, h.nx, h.ny, h.x0, h.y0, h.pitch)
        });
        let n = usize::from(h.nx) * usize::from(h.ny);
        let room = self
            .vx
            .len()
            .min(self.vy.len())
            .min(self.ax.len())
            .min(self.ay.len());
        if h.row0 == 0 {
            if n > room {
                return Part::Refused;
            }
            self.head = Some(h);
            self.rows = 0;
        } else if !same || usize::from(h.row0) != self.rows {
            return Part::Refused;
        }
        let first = usize::from(h.nx) * usize::from(h.row0);
        for k in 0..part.nodes() {
            let i = first + k;
            (self.vx[i], self.vy[i], self.ax[i], self.ay[i]) = part.node(k);
        }
        self.rows += part.rows();
        if self.rows >= usize::from(h.ny) {
            Part::Whole
        } else {
            Part::Taken
        }
    }

    /// The head of the ask being put together (its `row0` that of its last
    /// part).
    pub fn head(&self) -> Option<AskHead> {
        self.head
    }

    /// The whole ask's flow (still until an ask with nodes is whole).
    pub fn flow(&self) -> Flow<'_> {
        match self.head {
            Some(h) if h.nx > 0 && self.rows >= usize::from(h.ny) => {
                let n = usize::from(h.nx) * usize::from(h.ny);
                Flow {
                    nx: h.nx,
                    ny: h.ny,
                    x0: h.x0,
                    y0: h.y0,
                    pitch: h.pitch,
                    vx: &self.vx[..n],
                    vy: &self.vy[..n],
                    ax: &self.ax[..n],
                    ay: &self.ay[..n],
                }
            }
            _ => Flow::still(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flow(v: &[i16], nx: u16, ny: u16) -> Flow<'_> {
        Flow {
            nx,
            ny,
            x0: -40,
            y0: 128,
            pitch: 256,
            vx: v,
            vy: v,
            ax: v,
            ay: v,
        }
    }

    /// Every part of `f`'s ask, encoded.
    fn messages(f: &Flow<'_>, rungs: &Rungs) -> std::vec::Vec<std::vec::Vec<u8>> {
        ask_parts(f)
            .map(|part| {
                let mut buf = std::vec![0u8; MAX_ASK_PAYLOAD];
                let len = encode_ask(7, rungs, f, part, &mut buf).unwrap();
                buf.truncate(len);
                buf
            })
            .collect()
    }

    #[test]
    fn an_ask_round_trips_in_one_part_or_many() {
        let mut rungs = Rungs::events(24);
        rungs.separations[..3].copy_from_slice(&[16, 32, 64]);
        rungs.count = 3;
        for (nx, ny) in [(3u16, 2u16), (100, 50)] {
            let n = usize::from(nx) * usize::from(ny);
            let v: std::vec::Vec<i16> = (0..n).map(|i| (i as i16).wrapping_mul(37)).collect();
            let f = flow(&v, nx, ny);
            let msgs = messages(&f, &rungs);
            assert_eq!(
                msgs.len(),
                n.div_ceil(MAX_ASK_NODES / usize::from(nx) * usize::from(nx))
            );
            let (mut a, mut b, mut c, mut d) = (vec![0; n], vec![0; n], vec![0; n], vec![0; n]);
            let mut asm = AskAssembly::new(&mut a, &mut b, &mut c, &mut d);
            let mut last = Part::Refused;
            for m in &msgs {
                last = asm.take(&AskView::parse(m).unwrap());
            }
            assert_eq!(last, Part::Whole);
            assert_eq!(asm.head().unwrap().rungs, rungs);
            let g = asm.flow();
            assert_eq!((g.nx, g.ny, g.x0, g.y0, g.pitch), (nx, ny, -40, 128, 256));
            assert_eq!(g.vx, &v[..]);
            assert_eq!(g.ay, &v[..]);
        }
        // A still flow: one part of no rows, events only.
        let msgs = messages(&Flow::still(), &Rungs::events(24));
        assert_eq!(msgs.len(), 1);
        let view = AskView::parse(&msgs[0]).unwrap();
        assert_eq!((view.nodes(), view.head.rungs.reach), (0, 24));
        let mut asm = AskAssembly::new(&mut [], &mut [], &mut [], &mut []);
        assert_eq!(asm.take(&view), Part::Whole);
        assert!(asm.flow().is_still());
    }

    /// An assembly taken apart between parts and resumed over the same
    /// slices puts the ask together as one that never stopped.
    #[test]
    fn an_assembly_resumed_between_parts_goes_on() {
        let n = 100 * 50;
        let v: std::vec::Vec<i16> = (0..n).map(|i| i as i16).collect();
        let f = flow(&v, 100, 50);
        let msgs = messages(&f, &Rungs::events(8));
        assert!(msgs.len() >= 3);
        let (mut a, mut b, mut c, mut d) = (vec![0; n], vec![0; n], vec![0; n], vec![0; n]);
        let mut progress = AskProgress::default();
        let mut last = Part::Refused;
        for m in &msgs {
            let mut asm = AskAssembly::resume(&mut a, &mut b, &mut c, &mut d, progress);
            last = asm.take(&AskView::parse(m).unwrap());
            progress = asm.progress();
        }
        assert_eq!(last, Part::Whole);
        let asm = AskAssembly::resume(&mut a, &mut b, &mut c, &mut d, progress);
        assert_eq!(asm.flow().vx, &v[..]);
        // Started afresh each time instead, the second part is refused.
        let mut asm = AskAssembly::new(&mut a, &mut b, &mut c, &mut d);
        assert_eq!(asm.take(&AskView::parse(&msgs[1]).unwrap()), Part::Refused);
    }

    #[test]
    fn parts_out_of_order_are_refused() {
        let n = 100 * 50;
        let v = vec![1i16; n];
        let f = flow(&v, 100, 50);
        let msgs = messages(&f, &Rungs::events(8));
        assert!(msgs.len() >= 3);
        let (mut a, mut b, mut c, mut d) = (vec![0; n], vec![0; n], vec![0; n], vec![0; n]);
        let mut asm = AskAssembly::new(&mut a, &mut b, &mut c, &mut d);
        let part = |k: usize| AskView::parse(&msgs[k]).unwrap();
        // A gap, then a repeat: refused; the flow stays still.
        assert_eq!(asm.take(&part(0)), Part::Taken);
        assert_eq!(asm.take(&part(2)), Part::Refused);
        assert_eq!(asm.take(&part(1)), Part::Taken);
        assert_eq!(asm.take(&part(1)), Part::Refused);
        assert!(asm.flow().is_still());
        // Too small a store refuses the first part.
        let mut small = [0i16; 10];
        let (mut s2, mut s3, mut s4) = ([0i16; 10], [0i16; 10], [0i16; 10]);
        let mut tiny = AskAssembly::new(&mut small, &mut s2, &mut s3, &mut s4);
        assert_eq!(tiny.take(&part(0)), Part::Refused);
    }

    #[test]
    fn bad_asks_are_refused() {
        let v = [0i16; 6];
        let mut buf = [0u8; MAX_ASK_PAYLOAD];
        let f = flow(&v, 3, 2);
        let len = encode_ask(1, &Rungs::events(8), &f, (0, 2), &mut buf).unwrap();
        assert!(AskView::parse(&buf[..len]).is_ok());
        // Truncated, lengthened, or rows past the grid.
        assert!(AskView::parse(&buf[..len - 1]).is_err());
        assert!(AskView::parse(&buf[..len + 1]).is_err());
        let mut b = buf;
        b[38] = 1;
        assert!(AskView::parse(&b[..len]).is_err());
        // Too many rungs, a zero separation, a pitch out of range.
        let mut b = buf;
        b[6] = MAX_RUNGS as u8 + 1;
        assert!(AskView::parse(&b[..len]).is_err());
        let mut b = buf;
        b[6] = 1;
        assert!(AskView::parse(&b[..len]).is_err());
        let mut b = buf;
        b[36..38].copy_from_slice(&8u16.to_le_bytes());
        assert!(AskView::parse(&b[..len]).is_err());
        // Not encoded: slices that do not match the grid, rows past it, a
        // part over the node limit.
        assert!(encode_ask(1, &Rungs::events(8), &flow(&v[..5], 3, 2), (0, 2), &mut buf).is_err());
        assert!(encode_ask(1, &Rungs::events(8), &f, (1, 2), &mut buf).is_err());
        let big = vec![0i16; MAX_ASK_NODES + 1];
        let g = flow(&big, (MAX_ASK_NODES + 1) as u16, 1);
        assert!(encode_ask(1, &Rungs::events(8), &g, (0, 1), &mut buf).is_err());
        assert_eq!(ask_parts(&g).count(), 0);
        // Too small a buffer.
        assert_eq!(
            encode_ask(1, &Rungs::events(8), &f, (0, 2), &mut buf[..10]),
            Err(WireError::TooLarge.into())
        );
    }

    proptest::proptest! {
        /// Arbitrary bytes: parsed or refused, never a panic; what parses
        /// puts together into a flow the warp takes.
        #[test]
        fn any_bytes_parse_or_are_refused(
            b in proptest::collection::vec(proptest::num::u8::ANY, 0..400),
            head in proptest::collection::vec(proptest::num::u8::ANY, ASK_HEAD..ASK_HEAD + 1),
        ) {
            let _ = AskView::parse(&b);
            // A plausible head with arbitrary fields and nodes.
            let mut m = head.clone();
            m.extend_from_slice(&b[..b.len() / NODE * NODE]);
            if let Ok(v) = AskView::parse(&m) {
                let n = usize::from(v.head.nx) * usize::from(v.head.ny);
                let (mut a, mut c, mut d, mut e) = (vec![0; n], vec![0; n], vec![0; n], vec![0; n]);
                let mut asm = AskAssembly::new(&mut a, &mut c, &mut d, &mut e);
                if asm.take(&v) == Part::Whole {
                    proptest::prop_assert!(asm.flow().check().is_ok());
                }
            }
        }
    }
}
