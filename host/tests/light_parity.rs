//! The core's static-light model, its events, its warp and its rung frames
//! against the `f64` reference (`spiv_host::reference::light`), within the
//! tolerance that module states, on a simulated scene with glare and on
//! random flows.

use spiv_core::buffers::LightBuf;
use spiv_core::light::Light;
use spiv_core::plane::PlaneView;
use spiv_core::rungs::{rung_frames, EventRing, Rungs};
use spiv_core::warp::{Flow, SCALE};
use spiv_firmware_sim::scene::{SceneKind, SceneParams};
use spiv_firmware_sim::simulation::{simulate_planes, Request};
use spiv_host::reference::light::{events, floor_of, floored, frame, NodeFlow};
use spiv_host::reference::SpikeVolume;

/// The vortex array over its glare band, 128 × 64 px, 400 ticks.
fn scene() -> (Vec<u8>, u16, u16) {
    let p = SceneParams {
        width: 128,
        height: 64,
        glare_sigma: 12.0,
        ..SceneParams::new(SceneKind::VortexArray)
    };
    let mut req = Request::new(p.clone(), 11);
    req.ticks = Some(400);
    let (data, _) = simulate_planes(&req).expect("simulates");
    (data, p.width, p.height)
}

/// A smooth rotating flow on 5 × 3 nodes 32 px apart (stored order),
/// velocities up to about 0.8 px per tick.
fn rotation() -> (Vec<i16>, Vec<i16>, Vec<i16>, Vec<i16>) {
    let (mut vx, mut vy, mut ax, mut ay) = (vec![], vec![], vec![], vec![]);
    for r in 0..3 {
        for c in 0..5 {
            let (x, y) = (8.0 + 32.0 * c as f64 - 72.0, 8.0 + 32.0 * r as f64 - 40.0);
            let w = 0.012;
            vx.push((-w * y * 4096.0) as i16);
            vy.push((w * x * 4096.0) as i16);
            ax.push((-w * w * x * 65536.0) as i16);
            ay.push((-w * w * y * 65536.0) as i16);
        }
    }
    (vx, vy, ax, ay)
}

#[test]
fn events_rates_and_rung_frames_hold_to_the_reference() {
    let (data, w, h) = scene();
    let px = usize::from(w) * usize::from(h);
    let mut b = LightBuf::new(px);
    let mut light = Light::new(w, h, 0, b.state()).unwrap();
    let (mut entries, mut starts) = (vec![0u32; 400 * px], vec![0u32; 401]);
    let mut ring = EventRing::new(&mut entries, &mut starts, 0).unwrap();
    for plane in data.chunks_exact(px / 8) {
        ring.push(&mut light, &PlaneView::new(plane, w, h).unwrap())
            .unwrap();
    }
    assert_eq!(ring.lost(), 0);
    let vol = SpikeVolume::from_packed(&data, usize::from(w), usize::from(h), 0);
    let (want, rates, periodic) = events(&vol);
    // Every event, identical (the last ticks' −1 events are not settled
    // yet in the core: compare up to the tolerance before the end).
    let settled = 400 - u32::from(spiv_core::light::MAX_TOLERANCE);
    let mut got = Vec::new();
    ring.each(0, settled, |e| got.push((e.index, e.tick, e.sign)));
    got.sort_by_key(|&(i, t, _)| (t, i));
    let want: Vec<_> = want.into_iter().filter(|e| e.1 < settled).collect();
    assert!(want.len() > 1000, "{} events", want.len());
    assert_eq!(got, want);
    for i in 0..px {
        assert_eq!(light.periodic(i), periodic[i], "pixel {i}");
        let core = f64::from(light.rate(i)) / 65536.0;
        let reference = if periodic[i] { 0.0 } else { rates[i] };
        assert!(
            (core - reference).abs() <= 1.0 / 4096.0,
            "pixel {i}: {core} against {reference}"
        );
    }
    rung_frames_hold_to_the_reference(&ring, &light);
}

/// The rung frames of 16, 32 and 64 ticks along a rotation, made from
/// `ring` and `light`, against the reference's frames rounded and floored
/// as the core sends them.
fn rung_frames_hold_to_the_reference(ring: &EventRing<'_>, light: &Light<'_>) {
    let (w, h) = (light.width(), light.height());
    let px = usize::from(w) * usize::from(h);
    let (vx, vy, ax, ay) = rotation();
    let flow = Flow {
        nx: 5,
        ny: 3,
        x0: 8 * 16,
        y0: 8 * 16,
        pitch: 32 * 16,
        vx: &vx,
        vy: &vy,
        ax: &ax,
        ay: &ay,
    };
    let mut rungs = Rungs::events(0);
    rungs.separations[..3].copy_from_slice(&[16, 32, 64]);
    rungs.count = 3;
    let mid = 300;
    let mut frames = vec![0i16; 6 * px];
    rung_frames(ring, light, &flow, mid, &rungs, &mut frames).unwrap();
    let nf = NodeFlow::of(&flow);
    let all: Vec<_> = {
        let mut v = Vec::new();
        ring.each(mid - 64, mid + 64, |e| v.push((e.index, e.tick, e.sign)));
        v
    };
    let rate = |i: usize| f64::from(light.rate(i)) / 65536.0;
    for (k, &s) in [16u32, 32, 64].iter().enumerate() {
        for (j, (start, centre)) in [
            (mid - s, f64::from(mid) - f64::from(s) / 2.0),
            (mid, f64::from(mid) + f64::from(s) / 2.0),
        ]
        .into_iter()
        .enumerate()
        {
            let want = frame(
                &all,
                (usize::from(w), usize::from(h)),
                &nf,
                (start, s, centre),
                rate,
            );
            let got = &frames[(2 * k + j) * px..(2 * k + j + 1) * px];
            let sent = floored(&want, s);
            // Each rate block rounds to 1/64 spike; a few blocks of
            // neighbours can land on one pixel. A sample whose reference
            // lies within that of a half spike may round either way (and
            // across the floor); every other sample is the reference's,
            // exactly, in whole spikes.
            let tol = f64::from(s.div_ceil(spiv_core::warp::RATE_BLOCK)) * 2.0 / 64.0;
            let (mut moved, mut near, mut kept) = (0, 0, 0);
            for ((g, r), want) in got.iter().zip(&want).zip(&sent) {
                assert_eq!(g % SCALE, 0, "rung {s}: {g} is not whole spikes");
                let g = f64::from(*g) / f64::from(SCALE);
                kept += usize::from(g != 0.0);
                let d = (g - want).abs();
                if ((r + 0.5) - (r + 0.5).round()).abs() <= tol {
                    near += 1;
                    assert!(d <= floor_of(s) + 1.0, "rung {s}: {g} against {r}");
                } else if d > 0.0 {
                    // An event on a tie, a pixel over: one spike (and the
                    // floor).
                    moved += 1;
                    assert!(d <= floor_of(s) + 1.0, "rung {s}: {g} against {r}");
                }
            }
            assert!(
                moved * 1000 <= px && near * 20 <= px,
                "rung {s}: {moved} samples off by an event, {near} near a half spike"
            );
            assert!(kept * 20 >= px, "rung {s}: {kept} samples above the floor");
        }
    }
}

#[test]
fn displacements_round_the_references_exact_value() {
    let mut s = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = |m: u64| {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s % m
    };
    let mut ties = 0;
    let mut n = 0;
    for _ in 0..200 {
        let k = 12;
        let vals = |m: u64, next: &mut dyn FnMut(u64) -> u64| -> Vec<i16> {
            (0..k)
                .map(|_| (next(2 * m) as i64 - m as i64) as i16)
                .collect()
        };
        let (vx, vy) = (vals(12000, &mut next), vals(12000, &mut next));
        let (ax, ay) = (vals(3000, &mut next), vals(3000, &mut next));
        let flow = Flow {
            nx: 4,
            ny: 3,
            x0: next(800) as i32 - 400,
            y0: next(800) as i32 - 400,
            pitch: 16 + next(900) as u16,
            vx: &vx,
            vy: &vy,
            ax: &ax,
            ay: &ay,
        };
        let nf = NodeFlow::of(&flow);
        for _ in 0..50 {
            let (x, y) = (next(300) as u16, next(200) as u16);
            let d2 = next(1025) as i32 - 512;
            let (cx, cy) = flow.displacement(x, y, d2);
            let (rx, ry) = nf.displacement(f64::from(x), f64::from(y), f64::from(d2) / 2.0);
            for (c, r) in [(cx, rx), (cy, ry)] {
                n += 1;
                let half = (r - r.floor() - 0.5).abs() < 1e-9;
                if half {
                    ties += 1;
                    assert!((f64::from(c) - r).abs() <= 0.5 + 1e-9);
                } else {
                    assert_eq!(f64::from(c), (r + 0.5).floor(), "({x}, {y}) d2 {d2}: {r}");
                }
            }
        }
    }
    assert!(ties * 1000 < n, "{ties} ties of {n}");
}
