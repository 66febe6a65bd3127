//! The sidecar's ear on arbitrary bytes: the downlink decoder and the
//! control checks (`spiv_core::downlink`), fed in chunks whose sizes the
//! input chooses, then motion-compensated frames made with whatever was
//! applied — any velocity, any caps, any `n_max` a control can carry. Never
//! a panic, and every chunk is counted as heard or refused.
//!
//! Run by the fuzz target of the same name (`fuzz/fuzz_targets`) and, over
//! the committed corpus, by `tests/tests/fuzz_corpora.rs`.

use spiv_core::buffers::SidecarBuf;
use spiv_core::sidecar::{Config, Sidecar};
use spiv_core::wire::sender::Link;
use spiv_core::Method;

const W: u16 = 128;
const H: u16 = 32;

struct Sink;
impl Link for Sink {
    type Error = ();
    fn send(&mut self, _m: &[u8]) -> Result<(), ()> {
        Ok(())
    }
}

/// One input: returns, or panics on a finding.
pub fn run(input: &[u8]) {
    let (head, data) = input.split_at(input.len().min(4));
    let mut cfg = Config::new(8, 3);
    cfg.method = Method::Mc;
    cfg.params.n_max = 16;
    cfg.schedule.every = 6;
    cfg.schedule.pairs = Some(3);
    cfg.refine =
        (head.first().is_some_and(|b| b & 1 == 1)).then(spiv_core::motion::Refine::default);
    let mut buf = SidecarBuf::<u8>::new(W, H, &cfg).expect("buffers");
    let mut sc = Sidecar::new(W, H, cfg).expect("configuration");
    let chunk = head.get(1).map_or(64, |&c| usize::from(c % 64) + 1);
    let mut parts = data.chunks(chunk);
    // Planes of a fixed pattern; downlink bytes heard between them.
    let plane: Vec<u8> = (0..usize::from(W) * usize::from(H) / 8)
        .map(|i| (i as u8).wrapping_mul(37) & 0x91)
        .collect();
    while !sc.done() {
        if let Some(p) = parts.next() {
            sc.hear(&mut buf.downlink(), p);
        }
        let mut mem = buf.memory(sc.next_tick()).expect("memory");
        sc.push_plane(&mut mem, &plane, &mut Sink, &mut ())
            .expect("a checked control never makes a frame fail");
    }
    for p in parts {
        sc.hear(&mut buf.downlink(), p);
    }
    let d = sc.downlink();
    assert!(d.applied <= d.heard);
}
