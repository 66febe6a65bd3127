//! The live loop's payloads on arbitrary bytes: the asks of the downlink
//! (`spiv_core::wire::ask`), parsed and put together part by part, and the
//! pair heads of the uplink (`spiv_core::wire::pair`). An error or a value
//! in range, never a panic: a whole ask's flow passes the warp's own check,
//! and a head's parts fit the frame end's member byte.
//!
//! Input: a selector byte (even: asks, odd: a pair head), then for asks a
//! sequence of parts, each a little-endian u16 length and that many bytes.
//!
//! Run by the fuzz target of the same name (`fuzz/fuzz_targets`) and, over
//! the committed corpus, by `tests/tests/fuzz_corpora.rs`.

use spiv_core::wire::ask::{AskAssembly, AskView, Part};
use spiv_core::wire::pair::{PairHead, MAX_EVENT_TICKS};

/// Nodes the assembly holds (a flow of more is refused whole).
const STORE: usize = 4096;

/// One input: returns, or panics on a finding.
pub fn run(input: &[u8]) {
    let Some((&sel, mut data)) = input.split_first() else {
        return;
    };
    if sel & 1 == 1 {
        if let Ok(h) = PairHead::parse(data) {
            assert!(h.check().is_ok());
            assert!(h.parts() <= 2 * 8 + MAX_EVENT_TICKS + 1);
            assert_eq!(PairHead::parse(&h.to_bytes()), Ok(h));
        }
        return;
    }
    let (mut vx, mut vy, mut ax, mut ay) = (
        vec![0i16; STORE],
        vec![0i16; STORE],
        vec![0i16; STORE],
        vec![0i16; STORE],
    );
    let mut asm = AskAssembly::new(&mut vx, &mut vy, &mut ax, &mut ay);
    while data.len() >= 2 {
        let n = usize::from(u16::from_le_bytes([data[0], data[1]]));
        let part = &data[2..(2 + n).min(data.len())];
        data = &data[(2 + n).min(data.len())..];
        let Ok(view) = AskView::parse(part) else {
            continue;
        };
        assert!(view.nodes() <= spiv_core::wire::ask::MAX_ASK_NODES);
        if asm.take(&view) == Part::Whole {
            let flow = asm.flow();
            assert!(flow.check().is_ok());
            let head = asm.head().expect("a whole ask has a head");
            assert!(usize::from(head.rungs.count) <= 8);
        }
    }
}
