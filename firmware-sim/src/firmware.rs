//! The sidecar firmware, simulated: the core's loop
//! ([`spiv_core::sidecar`], the same code the Cortex-M4 firmware runs) over
//! owned buffers, sending into a [`Link`] — a writer, memory, or a
//! [`Faulty`] link that drops, corrupts, truncates, stalls, reorders and duplicates
//! messages — and the drivers that feed it planes from a simulated scene, a
//! `.dat` file or memory.
//!
//! Everything per message is bounded: one band of at most 16 KiB payload, one
//! message buffer. The frame buffer is one frame of u16 (a device with a
//! strip workspace would send each strip as it is done).

use spiv_core::buffers::SidecarBuf;
use spiv_core::downlink::DownlinkStats;
use spiv_core::sidecar::{Probe, Sidecar};
pub use spiv_core::wire::control::Control;
use spiv_core::wire::sender::Slot;

pub use spiv_core::sidecar::{capped_frame, Config, CAP_BAND};

use crate::Error;

/// Where messages go: one call per whole message (delimiter included).
pub trait Link {
    /// Sends one framed message.
    fn send(&mut self, message: &[u8]) -> std::io::Result<()>;
    /// Pushes out anything held.
    fn flush(&mut self) -> std::io::Result<()>;
}

/// A link over any writer.
#[derive(Debug)]
pub struct Plain<W: std::io::Write>(pub W);

impl<W: std::io::Write> Link for Plain<W> {
    fn send(&mut self, message: &[u8]) -> std::io::Result<()> {
        self.0.write_all(message)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.0.flush()
    }
}

/// Messages kept in memory (for in-process runs and tests).
impl Link for Vec<u8> {
    fn send(&mut self, message: &[u8]) -> std::io::Result<()> {
        self.extend_from_slice(message);
        Ok(())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The core's sender writes through this.
struct CoreLink<'a, L: Link>(&'a mut L);

impl<L: Link> spiv_core::wire::sender::Link for CoreLink<'_, L> {
    type Error = std::io::Error;
    fn send(&mut self, message: &[u8]) -> std::io::Result<()> {
        self.0.send(message)
    }
}

/// A frame the firmware made, as it made it (for in-process comparison).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SentFrame {
    /// Frame counter.
    pub frame_id: u32,
    /// Centre tick.
    pub tick: u32,
    /// Pair counter and member (0: k, 1: k + dt).
    pub pair: u32,
    /// 0 or 1.
    pub member: u8,
    /// Samples in stored row order as the receiver will decode them.
    pub data: Vec<u16>,
}

/// Keeps copies of the frames sent, when asked to.
struct Keep<'a>(&'a mut Option<Vec<SentFrame>>);

impl Probe<u16> for Keep<'_> {
    fn sent(&mut self, frame_id: u32, slot: Slot, frame: &[u16]) {
        if let Some(keep) = self.0 {
            keep.push(SentFrame {
                frame_id,
                tick: slot.tick,
                pair: slot.pair,
                member: slot.member,
                data: frame.to_vec(),
            });
        }
    }
}

/// The firmware's counters (also sent as a status message): the core
/// sender's.
pub type Counters = spiv_core::wire::sender::Sent;

/// The loop with its memory and its link.
#[derive(Debug)]
pub struct Firmware<L: Link> {
    sidecar: Sidecar,
    buf: SidecarBuf<u16>,
    link: L,
    /// Keep copies of what was sent (tests, in-process comparison).
    pub keep: Option<Vec<SentFrame>>,
}

impl<L: Link> Firmware<L> {
    /// A firmware for a `width × height` sensor sending to `link`.
    pub fn new(width: u16, height: u16, cfg: Config, link: L) -> Result<Self, Error> {
        let sidecar = Sidecar::new(width, height, cfg)?;
        Ok(Firmware {
            buf: SidecarBuf::new(width, height, &cfg)?,
            sidecar,
            link,
            keep: None,
        })
    }

    /// Takes bytes from the downlink (control messages from the host, any
    /// chunking): a valid control applies from the start of its pair,
    /// anything else is counted and dropped (`spiv_core::downlink`).
    pub fn hear(&mut self, bytes: &[u8]) {
        self.sidecar.hear(&mut self.buf.downlink(), bytes);
    }

    /// What the downlink heard so far.
    pub fn downlink(&self) -> DownlinkStats {
        self.sidecar.downlink()
    }

    /// The pair whose first frame the next plane completes, if it does.
    pub fn pair_due(&self) -> Option<u32> {
        self.sidecar.pair_due()
    }

    /// Pushes out what the link holds.
    pub fn flush(&mut self) -> Result<(), Error> {
        Ok(self.link.flush()?)
    }

    /// Rows per tile message.
    pub fn tile_rows(&self) -> u16 {
        self.sidecar.tile_rows()
    }

    /// The counters so far.
    pub fn counters(&self) -> Counters {
        self.sidecar.sent()
    }

    /// The link (to take a memory link back).
    pub fn into_link(self) -> L {
        self.link
    }

    /// Ingests the next plane (stored row order, `width·height/8` bytes) and
    /// sends every frame whose window it completes.
    pub fn push_plane(&mut self, plane: &[u8]) -> Result<(), Error> {
        let mut mem = self.buf.memory(self.sidecar.next_tick())?;
        self.sidecar.push_plane(
            &mut mem,
            plane,
            &mut CoreLink(&mut self.link),
            &mut Keep(&mut self.keep),
        )?;
        Ok(())
    }

    /// True once every scheduled pair was sent.
    pub fn done(&self) -> bool {
        self.sidecar.done()
    }

    /// Sends the final status and flushes the link.
    pub fn finish(&mut self) -> Result<Counters, Error> {
        let sent = self
            .sidecar
            .finish(&mut self.buf.send(), &mut CoreLink(&mut self.link))?;
        self.link.flush()?;
        Ok(sent)
    }
}

/// Faults a link can suffer, as probabilities per message.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Faults {
    /// The message is lost.
    pub drop: f64,
    /// One random bit of the message flips.
    pub corrupt: f64,
    /// The message is cut short (its delimiter lost with its tail).
    pub truncate: f64,
    /// The link stalls for a few milliseconds before the message.
    pub stall: f64,
    /// The message is held back and sent after the next one.
    pub reorder: f64,
    /// The message is sent twice, back to back.
    pub duplicate: f64,
}

impl Faults {
    /// Parses `drop=P,corrupt=P,truncate=P,stall=P,reorder=P,duplicate=P`
    /// (any subset).
    pub fn parse(s: &str) -> Result<Faults, String> {
        let mut f = Faults::default();
        for part in s.split(',').filter(|p| !p.is_empty()) {
            let (k, v) = part
                .split_once('=')
                .ok_or_else(|| format!("fault `{part}` is not NAME=P"))?;
            let p: f64 = v
                .parse()
                .map_err(|_| format!("fault {k}: `{v}` is not a number"))?;
            if !(0.0..=1.0).contains(&p) {
                return Err(format!("fault {k}: probability {p} outside 0..1"));
            }
            match k {
                "drop" => f.drop = p,
                "corrupt" => f.corrupt = p,
                "truncate" => f.truncate = p,
                "stall" => f.stall = p,
                "reorder" => f.reorder = p,
                "duplicate" => f.duplicate = p,
                _ => {
                    return Err(format!(
                        "unknown fault `{k}` (drop, corrupt, truncate, stall, reorder, duplicate)"
                    ))
                }
            }
        }
        Ok(f)
    }
}

/// What the faulty link did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FaultCounts {
    /// Messages dropped.
    pub dropped: u64,
    /// Messages with a flipped bit.
    pub corrupted: u64,
    /// Messages cut short.
    pub truncated: u64,
    /// Stalls.
    pub stalled: u64,
    /// Messages sent late.
    pub reordered: u64,
    /// Messages sent twice.
    pub duplicated: u64,
}

/// A link that injects [`Faults`], deterministic for a seed.
#[derive(Debug)]
pub struct Faulty<L: Link> {
    inner: L,
    faults: Faults,
    rng: rand_chacha::ChaCha8Rng,
    held: Option<Vec<u8>>,
    /// What was done.
    pub counts: FaultCounts,
}

impl<L: Link> Faulty<L> {
    /// Faults on `inner` with `seed`.
    pub fn new(inner: L, faults: Faults, seed: u64) -> Self {
        use rand::SeedableRng;
        Faulty {
            inner,
            faults,
            rng: rand_chacha::ChaCha8Rng::seed_from_u64(seed),
            held: None,
            counts: FaultCounts::default(),
        }
    }

    /// The link underneath.
    pub fn into_inner(self) -> L {
        self.inner
    }

    /// The link underneath, to take what it holds.
    pub fn inner_mut(&mut self) -> &mut L {
        &mut self.inner
    }

    fn hit(&mut self, p: f64) -> bool {
        use rand::Rng;
        p > 0.0 && self.rng.gen::<f64>() < p
    }
}

impl<L: Link> Link for Faulty<L> {
    fn send(&mut self, message: &[u8]) -> std::io::Result<()> {
        use rand::Rng;
        if self.hit(self.faults.stall) {
            self.counts.stalled += 1;
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        if self.hit(self.faults.drop) {
            self.counts.dropped += 1;
            return Ok(());
        }
        let mut m = message.to_vec();
        if self.hit(self.faults.corrupt) {
            let bit = self.rng.gen_range(0..m.len() * 8);
            m[bit / 8] ^= 1 << (bit % 8);
            self.counts.corrupted += 1;
        }
        if self.hit(self.faults.truncate) && m.len() > 1 {
            let keep = self.rng.gen_range(1..m.len());
            m.truncate(keep);
            self.counts.truncated += 1;
        }
        if self.held.is_none() && self.hit(self.faults.reorder) {
            self.held = Some(m);
            self.counts.reordered += 1;
            return Ok(());
        }
        self.inner.send(&m)?;
        if self.hit(self.faults.duplicate) {
            self.inner.send(&m)?;
            self.counts.duplicated += 1;
        }
        if let Some(h) = self.held.take() {
            self.inner.send(&h)?;
        }
        Ok(())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        if let Some(h) = self.held.take() {
            self.inner.send(&h)?;
        }
        self.inner.flush()
    }
}

/// Runs the firmware on planes held in memory (back to back, stored row
/// order), from the first, told `control`.
pub fn run_on_planes<L: Link>(
    planes: &[u8],
    width: u16,
    height: u16,
    cfg: Config,
    control: Control,
    link: L,
    keep: bool,
) -> Result<Firmware<L>, Error> {
    let mut fw = Firmware::new(width, height, cfg, link)?;
    if !control.is_empty() {
        fw.hear(&control.message(0, 0, width, height)?);
    }
    if keep {
        fw.keep = Some(Vec::new());
    }
    let pb = usize::from(width) * usize::from(height) / 8;
    for plane in planes.chunks_exact(pb.max(1)) {
        if fw.done() {
            break;
        }
        fw.push_plane(plane)?;
    }
    fw.finish()?;
    Ok(fw)
}
