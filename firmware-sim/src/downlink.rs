//! The simulated sidecar's downlink: control bytes from the host — the TCP
//! connection's other direction, a control file or FIFO, or stdin — read on
//! a thread and heard by the firmware between planes, with faults injected
//! per message like the uplink's.
//!
//! A real sidecar never waits for the host: the sensor does not stop, so a
//! control applies from the first pair that begins after it arrives. A
//! simulation runs faster than a host's PIV, so [`ControlStream::wait`]
//! can pace it: before each pair after the first it waits (up to a limit)
//! until the host answered the previous pair — the closed loop a fast
//! host would give, reproducible in tests.

use std::io::Read;
use std::sync::mpsc::{channel, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use crate::firmware::{FaultCounts, Faults, Faulty, Firmware, Link};
use crate::ladder::LadderFirmware;
use crate::Error;

/// Control bytes arriving from the host.
#[derive(Debug)]
pub struct ControlStream {
    rx: Receiver<Vec<u8>>,
    faults: std::sync::Arc<std::sync::Mutex<FaultCounts>>,
    wait: Option<Duration>,
    mark: u64,
    closed: bool,
    /// Pairs that began without the host's answer within the wait.
    pub timeouts: u32,
}

/// Splits a byte stream at message delimiters and passes each message
/// through a faulty link into the channel.
struct Splitter {
    faulty: Faulty<Vec<u8>>,
    partial: Vec<u8>,
}

impl Splitter {
    fn push(&mut self, bytes: &[u8]) -> Vec<u8> {
        for &b in bytes {
            self.partial.push(b);
            if b == 0 {
                let m = std::mem::take(&mut self.partial);
                // A Vec link cannot fail.
                let _ = self.faulty.send(&m);
            }
        }
        self.take()
    }

    /// The stream ended: a held (reordered) message and a tail without
    /// delimiter go through as they are.
    fn finish(&mut self) -> Vec<u8> {
        let _ = self.faulty.flush();
        let mut rest = self.take();
        rest.append(&mut self.partial);
        rest
    }

    fn take(&mut self) -> Vec<u8> {
        std::mem::take(self.faulty.inner_mut())
    }
}

impl ControlStream {
    /// Reads `source` on a thread (opened there, so a FIFO's open does not
    /// block the caller) with `faults` per message, deterministic for
    /// `seed`.
    pub fn spawn<R: Read + Send + 'static>(
        open: impl FnOnce() -> std::io::Result<R> + Send + 'static,
        faults: Faults,
        seed: u64,
    ) -> ControlStream {
        let (tx, rx) = channel();
        let counts = std::sync::Arc::new(std::sync::Mutex::new(FaultCounts::default()));
        let shared = counts.clone();
        std::thread::spawn(move || {
            let Ok(mut r) = open() else { return };
            let mut split = Splitter {
                faulty: Faulty::new(Vec::new(), faults, seed),
                partial: Vec::new(),
            };
            let mut buf = vec![0u8; 4096];
            loop {
                let n = match r.read(&mut buf) {
                    Ok(0) | Err(_) => break,
                    Ok(n) => n,
                };
                let out = split.push(&buf[..n]);
                if let Ok(mut c) = shared.lock() {
                    *c = split.faulty.counts;
                }
                if !out.is_empty() && tx.send(out).is_err() {
                    return;
                }
            }
            let rest = split.finish();
            if let Ok(mut c) = shared.lock() {
                *c = split.faulty.counts;
            }
            if !rest.is_empty() {
                let _ = tx.send(rest);
            }
        });
        ControlStream {
            rx,
            faults: counts,
            wait: None,
            mark: 0,
            closed: false,
            timeouts: 0,
        }
    }

    /// All of `bytes` (a whole control stream, already read) with `faults`
    /// per message, heard before the first plane: deterministic, for
    /// `--checksum` runs that must print the same line on every run (and
    /// on the Cortex-M4, which hears its committed control the same way).
    pub fn preloaded(bytes: &[u8], faults: Faults, seed: u64) -> ControlStream {
        let (tx, rx) = channel();
        let mut split = Splitter {
            faulty: Faulty::new(Vec::new(), faults, seed),
            partial: Vec::new(),
        };
        let mut all = split.push(bytes);
        all.append(&mut split.finish());
        let counts = std::sync::Arc::new(std::sync::Mutex::new(split.faulty.counts));
        if !all.is_empty() {
            // The receiver is alive: it is returned below.
            let _ = tx.send(all);
        }
        ControlStream {
            rx,
            faults: counts,
            wait: None,
            mark: 0,
            closed: true,
            timeouts: 0,
        }
    }

    /// Before each pair after the first, waits up to `limit` for the
    /// host's answer to the previous pair (any control chunk, valid or
    /// not).
    pub fn wait(mut self, limit: Duration) -> Self {
        self.wait = Some(limit);
        self
    }

    /// Reads (and drops) what arrives until the host closes its end, or
    /// for `limit` at most.
    pub fn drain(&mut self, limit: Duration) {
        let deadline = Instant::now() + limit;
        while !self.closed {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.rx.recv_timeout(left) {
                Ok(_) => {}
                Err(RecvTimeoutError::Timeout) => break,
                Err(RecvTimeoutError::Disconnected) => self.closed = true,
            }
        }
    }

    /// What the fault injector did to the downlink.
    pub fn fault_counts(&self) -> FaultCounts {
        self.faults.lock().map(|c| *c).unwrap_or_default()
    }

    /// Call before each plane: the firmware hears whatever arrived, and,
    /// pacing, waits for the host when the plane begins a pair.
    pub fn before_plane<L: Link>(&mut self, fw: &mut Firmware<L>) -> Result<(), Error> {
        let pair = fw.pair_due();
        self.pace(fw, pair)
    }

    /// Call before the live loop sends pair `pair`
    /// ([`crate::ladder::LadderFirmware::pair_due`]): it hears whatever
    /// arrived and, pacing, waits for the host's answer to the pair before.
    pub fn before_pair<F: Hears>(&mut self, fw: &mut F, pair: u32) -> Result<(), Error> {
        self.pace(fw, Some(pair))
    }

    fn pace<F: Hears>(&mut self, fw: &mut F, pair: Option<u32>) -> Result<(), Error> {
        while let Ok(b) = self.rx.try_recv() {
            fw.hear(&b);
        }
        let (Some(limit), Some(pair)) = (self.wait, pair) else {
            return Ok(());
        };
        if pair > 0 && !self.closed && fw.answers() == self.mark {
            // The host can only answer what it received.
            fw.flush()?;
            let deadline = Instant::now() + limit;
            while fw.answers() == self.mark {
                let left = deadline.saturating_duration_since(Instant::now());
                match self.rx.recv_timeout(left) {
                    Ok(b) => fw.hear(&b),
                    Err(RecvTimeoutError::Timeout) => {
                        self.timeouts += 1;
                        break;
                    }
                    Err(RecvTimeoutError::Disconnected) => {
                        self.closed = true;
                        break;
                    }
                }
            }
        }
        self.mark = fw.answers();
        Ok(())
    }
}

/// A firmware that hears the downlink between planes.
pub trait Hears {
    /// Takes downlink bytes (any chunking).
    fn hear(&mut self, bytes: &[u8]);
    /// The host's messages heard or refused so far: a change is an answer.
    fn answers(&self) -> u64;
    /// Pushes out what the uplink holds (the host can only answer what it
    /// received).
    fn flush(&mut self) -> Result<(), Error>;
}

impl<L: Link> Hears for Firmware<L> {
    fn hear(&mut self, bytes: &[u8]) {
        Firmware::hear(self, bytes);
    }
    fn answers(&self) -> u64 {
        let d = self.downlink();
        u64::from(d.heard) + u64::from(d.refused)
    }
    fn flush(&mut self) -> Result<(), Error> {
        Firmware::flush(self)
    }
}

impl<L: Link> Hears for LadderFirmware<L> {
    fn hear(&mut self, bytes: &[u8]) {
        LadderFirmware::hear(self, bytes);
    }
    fn answers(&self) -> u64 {
        let (heard, refused) = self.heard();
        heard + refused
    }
    fn flush(&mut self) -> Result<(), Error> {
        LadderFirmware::flush(self)
    }
}
