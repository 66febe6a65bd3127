//! Property tests of the static-light model, the warp and the rung frames
//! over random spike streams and flows (case count from
//! `PROPTEST_CASES`): no panic and no overflow on any input, every event
//! the ring holds comes back by its own tick, a still flow puts every
//! event on its own pixel, and every sample of a frame is the events and
//! rates that reached it.

use proptest::prelude::*;
use spiv_core::buffers::LightBuf;
use spiv_core::light::{Light, MAX_TOLERANCE};
use spiv_core::rungs::{rung_floor, rung_frames, EventRing, Rungs, MAX_RUNGS};
use spiv_core::warp::{scatter, Flow, Window, SCALE};
use spiv_core::PlaneView;

/// `ticks` planes of a `w × h` sensor, each pixel firing with its own rate
/// (some never, some every tick) from `seed`.
fn stream(w: u16, h: u16, ticks: usize, seed: u64) -> Vec<u8> {
    let px = usize::from(w) * usize::from(h);
    let bytes = px / 8;
    let mut s = seed | 1;
    let rate: Vec<u64> = (0..px)
        .map(|i| ((i as u64).wrapping_mul(2654435761) ^ seed) % 257)
        .collect();
    let mut out = vec![0u8; bytes * ticks];
    for t in 0..ticks {
        for (p, &r) in rate.iter().enumerate() {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            if (s >> 24) % 256 < r {
                out[t * bytes + p / 8] |= 1 << (p % 8);
            }
        }
    }
    out
}

fn cases() -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(64)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases()))]

    /// Any stream, any flow (velocities and accelerations to the ends of
    /// their ranges), any rungs: the model, the ring and the frames never
    /// panic; a full ring counts what it drops; every event comes back by
    /// its own tick.
    #[test]
    fn any_stream_flow_and_rungs(
        (w, h) in (1u16..5, 1u16..6).prop_map(|(a, b)| (8 * a, b)),
        ticks in 1usize..90,
        seed in any::<u64>(),
        cap in 1usize..4000,
        depth in 1usize..80,
        nodes in proptest::collection::vec(any::<(i16, i16, i16, i16)>(), 1..9),
        pitch in 16u16..600,
        x0 in -2000i32..2000,
        mid in 0u32..120,
        seps in proptest::collection::vec(2u16..255, 0..=MAX_RUNGS),
        reach in 0u16..64,
    ) {
        let px = usize::from(w) * usize::from(h);
        let data = stream(w, h, ticks, seed);
        let mut b = LightBuf::new(px);
        let mut light = Light::new(w, h, 0, b.state()).unwrap();
        let (mut entries, mut starts) = (vec![0u32; cap], vec![0u32; depth + 1]);
        let mut ring = EventRing::new(&mut entries, &mut starts, 0).unwrap();
        let mut all = Vec::new();
        for (t, plane) in data.chunks_exact(px / 8).enumerate() {
            let view = PlaneView::new(plane, w, h).unwrap();
            ring.push(&mut light, &view).unwrap();
            prop_assert_eq!(ring.ticks().end, t as u32 + 1);
        }
        ring.each(0, ticks as u32, |e| {
            all.push(e);
        });
        prop_assert!(all.len() <= cap);
        for e in &all {
            prop_assert!(ring.ticks().start <= e.tick + u32::from(MAX_TOLERANCE));
            prop_assert!((e.index as usize) < px && (e.sign == 1 || e.sign == -1));
        }
        let n = nodes.len();
        let nx = (1..=n).rev().find(|d| n % d == 0).unwrap_or(1);
        let (vx, vy, ax, ay): (Vec<i16>, Vec<i16>, Vec<i16>, Vec<i16>) = (
            nodes.iter().map(|t| t.0).collect(),
            nodes.iter().map(|t| t.1).collect(),
            nodes.iter().map(|t| t.2).collect(),
            nodes.iter().map(|t| t.3).collect(),
        );
        let flow = Flow {
            nx: nx as u16,
            ny: (n / nx) as u16,
            x0,
            y0: -x0,
            pitch,
            vx: &vx,
            vy: &vy,
            ax: &ax,
            ay: &ay,
        };
        let mut rungs = Rungs::events(reach);
        for (k, &s) in seps.iter().enumerate() {
            rungs.separations[k] = s;
        }
        rungs.count = seps.len() as u8;
        let mut frames = vec![0i16; 2 * MAX_RUNGS * px];
        // A refusal is fine (ticks not held, a pitch out of range); a
        // panic is not.
        if rung_frames(&ring, &light, &flow, mid, &rungs, &mut frames).is_ok() {
            // Whole spikes, 0 or at least the rung's floor.
            for (k, f) in frames.chunks_exact(px).take(2 * seps.len()).enumerate() {
                let least = rung_floor(seps[k / 2]) * SCALE;
                prop_assert!(f.iter().all(|&v| v % SCALE == 0 && (v == 0 || v >= least)));
            }
        }
        for d2 in [-1024, -7, 0, 9, 1024] {
            let _ = flow.displacement(w - 1, h - 1, d2);
        }
    }

    /// With no flow, every event of a window lands on its own pixel:
    /// the frame is each pixel's events, summed.
    #[test]
    fn a_still_frame_is_each_pixels_events(
        (w, h) in (1u16..4, 1u16..5).prop_map(|(a, b)| (8 * a, b)),
        seed in any::<u64>(),
        start in 0u32..40,
        len in 1u32..40,
    ) {
        let px = usize::from(w) * usize::from(h);
        let data = stream(w, h, 100, seed);
        let mut b = LightBuf::new(px);
        let mut light = Light::new(w, h, 0, b.state()).unwrap();
        let (mut entries, mut starts) = (vec![0u32; 100 * px], vec![0u32; 101]);
        let mut ring = EventRing::new(&mut entries, &mut starts, 0).unwrap();
        for plane in data.chunks_exact(px / 8) {
            ring.push(&mut light, &PlaneView::new(plane, w, h).unwrap()).unwrap();
        }
        let win = Window::new(start, len);
        let mut frame = vec![0i16; px];
        let mut want = vec![0i32; px];
        ring.each(start, start + len, |e| {
            scatter(&mut frame, w, h, &Flow::still(), &win, e);
            want[e.index as usize] += i32::from(SCALE) * i32::from(e.sign);
        });
        for (f, w) in frame.iter().zip(&want) {
            prop_assert_eq!(i32::from(*f), *w);
        }
    }
}
