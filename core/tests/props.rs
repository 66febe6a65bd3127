//! Property tests of the core over random planes and parameters (case count
//! from `PROPTEST_CASES`): no panic, no overflow, outputs within range, and
//! the monotone facts of saturation timing and window counts.

// Pixel loops index several parallel arrays; an index reads clearest.
#![allow(clippy::needless_range_loop)]

use proptest::prelude::*;
use spiv_core::q::{Beta, KSig, Sigma};
use spiv_core::region::Region;
use spiv_core::segment::saturation_times;
use spiv_core::state::Buffers;
use spiv_core::window::{tfi, tfp, Window};
use spiv_core::{
    reconstruct_adaptive, reconstruct_rows, History, Params, PlaneView, Workspace, WorkspaceSizes,
};

/// How a random stream is made: every pixel fires with its own rate, or the
/// whole stream is all zero / all one.
#[derive(Debug, Clone)]
enum Fill {
    Rates(u64),
    Zero,
    One,
}

/// A history over the whole frame in `hb`, with every plane of `planes`
/// pushed.
fn filled<'a>(hb: &'a mut [u64], w: u16, h: u16, depth: u16, planes: &[u8]) -> History<'a> {
    let plane = usize::from(w) * usize::from(h) / 8;
    let mut hist = History::new(hb, w, h, 0, h, depth).unwrap();
    for bytes in planes.chunks_exact(plane) {
        hist.push(&PlaneView::new(bytes, w, h).unwrap()).unwrap();
    }
    hist
}

fn stream(w: u16, h: u16, ticks: usize, fill: &Fill) -> Vec<u8> {
    let bytes = usize::from(w) * usize::from(h) / 8;
    match fill {
        Fill::Zero => vec![0; bytes * ticks],
        Fill::One => vec![0xff; bytes * ticks],
        Fill::Rates(seed) => {
            // xorshift; per-pixel rate from a hash of the pixel, so some
            // pixels are dark, some glare, some saturate at one spike per tick.
            let mut s = seed | 1;
            let px = usize::from(w) * usize::from(h);
            let rate: Vec<u32> = (0..px)
                .map(|i| (((i as u64 * 2654435761) ^ seed) % 257) as u32)
                .collect();
            let mut out = vec![0u8; bytes * ticks];
            for t in 0..ticks {
                for p in 0..px {
                    s ^= s << 13;
                    s ^= s >> 7;
                    s ^= s << 17;
                    if ((s >> 24) % 256) < u64::from(rate[p]) {
                        out[t * bytes + p / 8] |= 1 << (p % 8);
                    }
                }
            }
            out
        }
    }
}

fn fill() -> impl Strategy<Value = Fill> {
    prop_oneof![6 => any::<u64>().prop_map(Fill::Rates), 1 => Just(Fill::Zero), 1 => Just(Fill::One)]
}

/// Parameters in the ranges the algorithm is meant for, with their edges.
fn sane_params() -> impl Strategy<Value = Params> {
    (
        1u16..=255,
        1u16..=8,
        prop_oneof![Just(1u16), 1u16..=300, Just(u16::MAX)],
        1u16..=u16::MAX,
        prop_oneof![Just(1u16), 1u16..=u16::MAX],
        any::<u16>(),
        prop_oneof![Just(1u16), 1u16..=u16::MAX],
        prop_oneof![Just(255u16), Just(65535u16), 1u16..=u16::MAX],
        0u16..=20,
    )
        .prop_map(|(n_max, n0_div, n_fs, beta, k, s, g, fs, margin)| {
            from_fields([
                (n_max / n0_div).max(1),
                n_max,
                n_fs,
                beta,
                k,
                s,
                g,
                fs,
                margin,
            ])
        })
}

/// Parameters from raw fields: n0, n_max, n_fs, β, k_sig and σ_fpn (as
/// fixed-point bits), g, full scale, margin.
fn from_fields([n0, n_max, n_fs, beta, k, s, g, fs, margin]: [u16; 9]) -> Params {
    Params {
        n0,
        n_max,
        n_fs,
        beta: Beta::from_bits(beta),
        k_sig: KSig::from_bits(k),
        sigma_fpn: Sigma::from_bits(s),
        electrons_per_spike: g,
        full_scale: fs,
        margin,
    }
}

/// Sane parameters with one field drawn from its type's whole range (often
/// out of its documented range, with the others valid, so the refusal of
/// that one field is what is tested), or every field drawn so.
fn any_params() -> impl Strategy<Value = Params> {
    let edge = || {
        prop_oneof![
            any::<u16>(),
            Just(0u16),
            Just(u16::MAX),
            Just(spiv_core::params::MAX_MARGIN + 1)
        ]
    };
    prop_oneof![
        (sane_params(), 0usize..9, edge()).prop_map(|(mut p, field, v)| {
            match field {
                0 => p.n0 = v,
                1 => p.n_max = v,
                2 => p.n_fs = v,
                3 => p.beta = Beta::from_bits(v),
                4 => p.k_sig = KSig::from_bits(v),
                5 => p.sigma_fpn = Sigma::from_bits(v),
                6 => p.electrons_per_spike = v,
                7 => p.full_scale = v,
                _ => p.margin = v,
            }
            p
        }),
        any::<[u16; 9]>().prop_map(from_fields),
    ]
}

fn params() -> impl Strategy<Value = Params> {
    prop_oneof![3 => sane_params(), 1 => any_params()]
}

/// The ranges `Params`'s documentation states, written out independently of
/// `Params::validate`.
fn documented(p: &Params, depth: u16) -> bool {
    (1..=255).contains(&p.n_max)
        && p.n_max <= depth
        && (1..=p.n_max).contains(&p.n0)
        && p.n_fs >= 1
        && p.beta.to_bits() > 0
        && p.k_sig.to_bits() > 0
        && p.electrons_per_spike >= 1
        && p.full_scale >= 1
        && 2 * u32::from(p.margin) < u32::from(u16::MAX)
}

struct Owned {
    counts: Vec<u64>,
    c_t: Vec<u8>,
    class: Vec<u8>,
    labels: Vec<u16>,
    masks: Vec<u64>,
    tiles: Vec<u8>,
    parents: Vec<u16>,
    regions: Vec<Region>,
    sizes: WorkspaceSizes,
}

impl Owned {
    fn new(sizes: WorkspaceSizes) -> Owned {
        let px = sizes.pixels();
        Owned {
            counts: vec![0; sizes.count_words()],
            c_t: vec![0; px],
            class: vec![0; px],
            labels: vec![0; px],
            masks: vec![0; sizes.mask_words()],
            tiles: vec![0; sizes.tiles()],
            parents: vec![0; sizes.parents()],
            regions: vec![Region::default(); usize::from(sizes.max_regions)],
            sizes,
        }
    }
    fn ws(&mut self) -> Workspace<'_> {
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
        .unwrap()
    }
}

fn dims() -> impl Strategy<Value = (u16, u16)> {
    prop_oneof![
        (1u16..=9).prop_map(|a| (8 * a, 5)),
        (1u16..=12, 1u16..=12).prop_map(|(a, b)| (8 * a, b)),
        Just((72, 40))
    ]
}

proptest! {
    #[test]
    fn adaptive_frames_never_panic_and_stay_in_range(
        (w, h) in dims(),
        fill in fill(),
        p in params(),
        ticks in 1usize..300,
        k_frac in 0.0f64..1.0,
        strip_rows in 1u16..=40,
        max_regions in 0u16..8,
        max_prov in 0u16..40,
        wide in any::<bool>(),
    ) {
        let depth = (ticks.min(256) as u16).max(p.n_max.min(256));
        let planes = stream(w, h, ticks, &fill);
        let mut hb = vec![0u64; History::words_needed(w, h, depth).unwrap()];
        let hist = filled(&mut hb, w, h, depth, &planes);
        let (old, new) = (hist.oldest().unwrap(), hist.newest().unwrap());
        let k = old + ((new - old) as f64 * k_frac) as u32;
        let mut sizes = WorkspaceSizes::for_strip(w, strip_rows.min(h + 3));
        if max_regions > 0 { sizes.max_regions = max_regions; }
        if max_prov > 0 { sizes.max_provisional = max_prov; }
        let mut owned = Owned::new(sizes);
        let mut ws = owned.ws();
        let px = usize::from(w) * usize::from(h);
        let fs = if wide { p.full_scale } else { p.full_scale.min(255) };
        let res = if wide {
            let mut out = vec![0u16; px];
            reconstruct_adaptive(&hist, k, &p, &mut ws, &mut out).map(|s| (s, out.iter().all(|&g| g <= fs)))
        } else {
            let mut out = vec![0u8; px];
            reconstruct_adaptive(&hist, k, &p, &mut ws, &mut out).map(|s| (s, out.iter().all(|&g| u16::from(g) <= fs)))
        };
        match res {
            Ok((stats, in_range)) => {
                prop_assert!(in_range);
                prop_assert!(stats.strips >= 1);
                prop_assert!(stats.regions_out == 0 || stats.n_star_sum >= u64::from(stats.regions_out));
                prop_assert!(stats.n_star_sum <= u64::from(stats.regions_out) * u64::from(p.n_max));
            }
            // Refusals: parameters out of their documented ranges, or a
            // strip too short for its margins.
            Err(spiv_core::Error::BadParam(_)) => prop_assert!(!documented(&p, depth)),
            Err(e) => prop_assert!(matches!(e, spiv_core::Error::BufferTooSmall { .. }), "{e:?}"),
        }
        prop_assert_eq!(p.validate(depth).is_ok(), documented(&p, depth));
    }

    /// A row range: no panic, rows outside it untouched, rows inside in
    /// range; the whole range is the whole frame.
    #[test]
    fn row_ranges_touch_only_their_rows(
        (w, h) in dims(),
        fill in fill(),
        p in params(),
        ticks in 1usize..200,
        r0 in 0u16..48,
        len in 0u16..48,
    ) {
        let depth = (ticks.min(256) as u16).max(p.n_max.min(256));
        let planes = stream(w, h, ticks, &fill);
        let mut hb = vec![0u64; History::words_needed(w, h, depth).unwrap()];
        let hist = filled(&mut hb, w, h, depth, &planes);
        let k = hist.newest().unwrap();
        let px = usize::from(w) * usize::from(h);
        let mut owned = Owned::new(WorkspaceSizes::for_strip(w, h));
        let mut out = vec![7777u16; px];
        let (a, b) = (r0.min(h), r0.saturating_add(len).min(h));
        let fs = p.full_scale;
        match reconstruct_rows(&hist, k, &p, &mut owned.ws(), (r0, r0.saturating_add(len)), &mut out) {
            Ok(_) => {
                for (i, &g) in out.iter().enumerate() {
                    let row = (i / usize::from(w)) as u16;
                    if row >= a && row < b {
                        prop_assert!(g <= fs);
                    } else {
                        prop_assert_eq!(g, 7777);
                    }
                }
            }
            Err(spiv_core::Error::BadParam(_)) => prop_assert!(!documented(&p, depth)),
            Err(e) => prop_assert!(matches!(e, spiv_core::Error::BufferTooSmall { .. }), "{e:?}"),
        }
    }

    #[test]
    fn counts_never_exceed_their_window_and_tfi_is_bounded(
        (w, h) in dims(),
        fill in fill(),
        n in 1u16..=255,
        ticks in 1usize..300,
        k_frac in 0.0f64..1.0,
    ) {
        let depth = 256u16;
        let planes = stream(w, h, ticks, &fill);
        let mut hb = vec![0u64; History::words_needed(w, h, depth).unwrap()];
        let hist = filled(&mut hb, w, h, depth, &planes);
        let (old, new) = (hist.oldest().unwrap(), hist.newest().unwrap());
        let k = old + ((new - old) as f64 * k_frac) as u32;
        let px = usize::from(w) * usize::from(h);
        let mut counts = vec![0u8; px];
        let mut out = vec![0u8; px];
        let win = tfp(&hist, k, n, 255, &mut counts, &mut out).unwrap();
        prop_assert_eq!(win, Window::in_history(&hist, k, n));
        prop_assert!(win.len <= n && win.len >= 1);
        for i in 0..px {
            prop_assert!(u16::from(counts[i]) <= win.len);
            let exact = (0..win.len).filter(|&d| hist.bit(win.start + u32::from(d), (i / usize::from(w)) as u16, (i % usize::from(w)) as u16)).count();
            prop_assert_eq!(usize::from(counts[i]), exact);
        }
        if matches!(fill, Fill::One) { prop_assert!(out.iter().all(|&g| g == 255)); }
        if matches!(fill, Fill::Zero) { prop_assert!(out.iter().all(|&g| g == 0)); }
        let n_max = n.max(2);
        let mut isi = vec![0u16; px];
        tfi(&hist, k, n_max, 65535, &mut isi).unwrap();
        let floor = (65535 + u32::from(n_max) / 2) / u32::from(n_max);
        prop_assert!(isi.iter().all(|&g| u32::from(g) >= floor.min(65535)));
    }

    #[test]
    fn more_spikes_never_lengthen_t_bgmax(
        (w, h) in dims(),
        seed_a in any::<u64>(),
        seed_b in any::<u64>(),
        p in sane_params(),
        ticks in 1usize..260,
        k_frac in 0.0f64..1.0,
    ) {
        let a = stream(w, h, ticks, &Fill::Rates(seed_a));
        let extra = stream(w, h, ticks, &Fill::Rates(seed_b));
        let b: Vec<u8> = a.iter().zip(&extra).map(|(x, y)| x | y).collect();
        let px = usize::from(w) * usize::from(h);
        let depth = (ticks.min(256) as u16).max(p.n_max.min(256));
        let t_bgmax = |planes: &[u8]| {
            let mut hb = vec![0u64; History::words_needed(w, h, depth).unwrap()];
            let hist = filled(&mut hb, w, h, depth, planes);
            let (old, new) = (hist.oldest().unwrap(), hist.newest().unwrap());
            let k = old + ((new - old) as f64 * k_frac) as u32;
            let mut counts = vec![0u8; px];
            let mut out = vec![0u16; px];
            saturation_times(&hist, k, &p, &mut counts, &mut out).unwrap();
            out
        };
        let (ta, tb) = (t_bgmax(&a), t_bgmax(&b));
        for i in 0..px {
            prop_assert!(tb[i] <= ta[i], "pixel {}: superset {} > subset {}", i, tb[i], ta[i]);
            prop_assert!(ta[i] >= 1 && ta[i] <= p.n_max);
        }
    }

    #[test]
    fn plane_views_of_any_bytes_never_panic(
        bytes in proptest::collection::vec(any::<u8>(), 0..200),
        w in 0u16..100,
        h in 0u16..100,
        row in 0u16..110,
    ) {
        if let Ok(v) = PlaneView::new(&bytes, w, h) {
            let mut words = [0u64; 2];
            if v.row_words(row, &mut words) {
                for c in 0..w {
                    prop_assert_eq!((words[usize::from(c) / 64] >> (c % 64)) & 1 == 1, v.get(row, c));
                }
            }
            prop_assert_eq!(v.count_ones() as usize, bytes.iter().map(|b| b.count_ones() as usize).sum::<usize>());
        }
    }
}

#[test]
fn longest_window_extreme_parameters_all_one_planes() {
    let (w, h) = (64u16, 32u16);
    let planes = stream(w, h, 256, &Fill::One);
    let mut hb = vec![0u64; History::words_needed(w, h, 256).unwrap()];
    let hist = filled(&mut hb, w, h, 256, &planes);
    let p = Params {
        n0: 1,
        n_max: 255,
        n_fs: u16::MAX,
        beta: Beta::from_bits(1),
        ..Params::default()
    };
    let mut owned = Owned::new(WorkspaceSizes::for_strip(w, h));
    let mut out = vec![0u16; usize::from(w) * usize::from(h)];
    reconstruct_adaptive(
        &hist,
        128,
        &Params {
            full_scale: 65535,
            ..p
        },
        &mut owned.ws(),
        &mut out,
    )
    .unwrap();
    // One spike per tick everywhere, never N_fs = 65535 spikes: background at
    // n_max = 255 with rate 1: FS·255/(β·N_fs) = 65535·255·256/65535 = 65280.
    assert!(out.iter().all(|&g| g == 65280), "{:?}", &out[..8]);
}

#[test]
fn a_tick_outside_the_history_is_refused() {
    let (w, h) = (8u16, 8u16);
    let mut hb = vec![0u64; History::words_needed(w, h, 128).unwrap()];
    let hist = History::new(&mut hb, w, h, 0, h, 128).unwrap();
    let mut owned = Owned::new(WorkspaceSizes::for_strip(w, h));
    let mut out = vec![0u8; 64];
    let e =
        reconstruct_adaptive(&hist, 0, &Params::default(), &mut owned.ws(), &mut out).unwrap_err();
    assert_eq!(e, spiv_core::Error::TickUnavailable);
}

#[test]
fn a_full_region_table_leaves_regions_as_background_and_counts_them() {
    // Ten separate bright 3×3 blobs on a dark field, a table of four regions.
    let (w, h) = (96u16, 16u16);
    let plane = usize::from(w) * usize::from(h) / 8;
    let mut bytes = vec![0u8; plane];
    for b in 0..10usize {
        for r in 6..9usize {
            for c in 4 + 9 * b..7 + 9 * b {
                let p = r * usize::from(w) + c;
                bytes[p / 8] |= 1 << (p % 8);
            }
        }
    }
    let mut hb = vec![0u64; History::words_needed(w, h, 128).unwrap()];
    let mut hist = History::new(&mut hb, w, h, 0, h, 128).unwrap();
    for _ in 0..128 {
        hist.push(&PlaneView::new(&bytes, w, h).unwrap()).unwrap();
    }
    let mut sizes = WorkspaceSizes::for_strip(w, h);
    sizes.max_regions = 4;
    let mut owned = Owned::new(sizes);
    let mut out = vec![0u8; usize::from(w) * usize::from(h)];
    let stats =
        reconstruct_adaptive(&hist, 64, &Params::default(), &mut owned.ws(), &mut out).unwrap();
    assert_eq!(stats.labels.regions, 4);
    assert_eq!(stats.labels.overflow_regions, 6);
    assert_eq!(stats.labels.noise_regions, 0);
    // The first four blobs are regions at full scale; the rest stay background.
    let centre = |b: usize| out[7 * usize::from(w) + 5 + 9 * b];
    assert!(
        (0..4).all(|b| centre(b) == 255),
        "{:?}",
        (0..10).map(centre).collect::<Vec<_>>()
    );
    assert!((4..10).all(|b| centre(b) < 255));
}

#[test]
fn particle_pixels_outside_any_region_are_suppressed_like_background_not_pits() {
    // A background firing every third tick and a 2-px blob firing every
    // tick: the blob is segmented as particle but is too small for a region
    // (noise, < 3 px). It must render as suppressed background (between
    // FS/β and 2·FS/β, like every saturated pixel), not at the count of its
    // detection window (≈ 3 gray: a dark pit in a background of 33).
    let (w, h) = (64u16, 32u16);
    let plane = usize::from(w) * usize::from(h) / 8;
    let blob = [10 * usize::from(w) + 20, 10 * usize::from(w) + 21];
    let mut planes = Vec::new();
    for t in 0..128usize {
        let mut bytes = vec![0u8; plane];
        for p in 0..usize::from(w) * usize::from(h) {
            if (t + p * 7) % 3 == 0 || blob.contains(&p) {
                bytes[p / 8] |= 1 << (p % 8);
            }
        }
        planes.extend(bytes);
    }
    let mut hb = vec![0u64; History::words_needed(w, h, 128).unwrap()];
    let hist = filled(&mut hb, w, h, 128, &planes);
    let mut owned = Owned::new(WorkspaceSizes::for_strip(w, h));
    let mut out = vec![0u8; usize::from(w) * usize::from(h)];
    let p = Params::default();
    let stats = reconstruct_adaptive(&hist, 64, &p, &mut owned.ws(), &mut out).unwrap();
    assert!(stats.labels.noise_regions >= 1, "{stats:?}");
    assert_eq!(stats.labels.regions, 0, "{stats:?}");
    // Background pixel (5, 5) fires at t ≡ 2 (mod 3): 42 spikes over
    // t_bgmax = 128, 255·42/(10·32) = 33.5 → 33.
    assert_eq!(out[5 * usize::from(w) + 5], 33);
    // The blob saturates at n = 32 with 32 spikes: 255/10 = 25.5.
    for &i in &blob {
        assert_eq!(out[i], 26, "blob pixel {i}");
    }
}
