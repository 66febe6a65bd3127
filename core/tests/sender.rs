//! The sender: tile sizes, the pair schedule, and a frame through the
//! decoder.

use spiv_core::error::LinkError;
use spiv_core::wire::codec::Lossy;
use spiv_core::wire::sender::{tile_rows, FrameInfo, Link, Schedule, SendBuffers, Sender, Slot};
use spiv_core::wire::{
    frame_crc, Decoder, Encoding, FrameEnd, Kind, WireError, MAX_ENCODED, MAX_PAYLOAD,
};

#[test]
fn tile_rows_fit_one_payload() {
    assert_eq!(tile_rows(400, 250, false, 8), 40);
    assert_eq!(tile_rows(400, 250, true, 8), 16); // 20 rows fit, block 8
    assert_eq!(tile_rows(64, 10, false, 8), 10); // the whole frame
    assert_eq!(tile_rows(20_000, 10, true, 8), 0); // a row does not fit
    assert_eq!(tile_rows(0, 10, false, 8), 0);
}

#[test]
fn schedule_slots_and_readiness() {
    let s = Schedule {
        first: 64,
        dt: 13,
        every: 52,
        pairs: Some(2),
    };
    let slots: Vec<_> = (0..5).map(|n| s.slot(n)).collect();
    assert_eq!(
        slots[..4]
            .iter()
            .map(|x| x.unwrap().tick)
            .collect::<Vec<_>>(),
        [64, 77, 116, 129]
    );
    assert_eq!(slots[3].unwrap().pair, 1);
    assert_eq!(slots[3].unwrap().member, 1);
    assert_eq!(slots[4], None);
    // A window of 128 centred on 64 ends at tick 127.
    assert!(!Schedule::ready(64, 128, 126));
    assert!(Schedule::ready(64, 128, 127));
    assert!(Schedule::ready(u32::MAX, 255, u32::MAX));
    let far = Schedule {
        first: u32::MAX - 1,
        dt: 5,
        every: 5,
        pairs: None,
    };
    assert_eq!(far.slot(1), None, "a tick past u32 is the end");
}

struct Memory(Vec<u8>);
impl Link for Memory {
    type Error = ();
    fn send(&mut self, m: &[u8]) -> Result<(), ()> {
        self.0.extend_from_slice(m);
        Ok(())
    }
}

#[test]
fn a_frame_arrives_as_tiles_and_an_end_with_its_crc() {
    let (w, h) = (64u16, 40u16);
    let mut frame: Vec<u8> = (0..usize::from(w) * usize::from(h))
        .map(|i| (i * 7 % 13) as u8)
        .collect();
    let original = frame.clone();
    let (mut payload, mut wire) = (vec![0u8; MAX_PAYLOAD], vec![0u8; MAX_ENCODED]);
    let mut buf = SendBuffers {
        payload: &mut payload,
        wire: &mut wire,
        scratch: &mut [],
    };
    let mut sender = Sender::new(w, h, 16).unwrap();
    let mut link = Memory(Vec::new());
    let info = FrameInfo {
        slot: Slot {
            tick: 9,
            pair: 0,
            member: 1,
        },
        method: spiv_core::Method::Adaptive,
        full_scale: 255,
        dt: 13,
    };
    sender
        .send_frame(
            &mut buf,
            &mut frame,
            &info,
            Encoding::Rice,
            &Lossy::default(),
            &mut link,
        )
        .unwrap();
    sender.send_status(&mut buf, &mut link).unwrap();
    assert_eq!(frame, original, "lossless leaves the frame alone");
    assert_eq!(sender.sent.messages, 5); // 3 tiles (16+16+8 rows), end, status
    assert_eq!(sender.sent.tiles[2], 3);
    assert_eq!(sender.sent.bytes, link.0.len() as u64);
    let mut rx = vec![0u8; MAX_ENCODED];
    let mut dec = Decoder::new(&mut rx);
    let mut input = &link.0[..];
    let mut kinds = Vec::new();
    while let Some(m) = dec.feed(&mut input) {
        let m = m.unwrap();
        assert_eq!(m.header.seq as usize, kinds.len());
        if m.header.kind == Kind::FrameEnd {
            let end = FrameEnd::parse(m.payload).unwrap();
            assert_eq!(end.frame_crc, frame_crc(&original[..]));
            assert_eq!((end.tiles, end.member, end.dt), (3, 1, 13));
        }
        kinds.push(m.header.kind);
    }
    assert_eq!(
        kinds,
        [
            Kind::FrameTile,
            Kind::FrameTile,
            Kind::FrameTile,
            Kind::FrameEnd,
            Kind::Status
        ]
    );
    // A frame shorter than its dimensions is refused, never indexed.
    let mut short = [0u8; 10];
    assert_eq!(
        sender.send_frame(
            &mut buf,
            &mut short,
            &info,
            Encoding::Rice,
            &Lossy::default(),
            &mut link
        ),
        Err(LinkError::from(WireError::Payload))
    );
}
