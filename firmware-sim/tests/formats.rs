//! Round trips of every format, and each bad file's clear error.

use spiv_firmware_sim::meta::SceneMeta;
use spiv_firmware_sim::scene::{SceneKind, SceneParams};
use spiv_firmware_sim::simulation::{simulate_to_dir, Request};
use spiv_formats::dat::{pack_row, unpack_upright, DatOptions, DatReader, DatWriter};
use spiv_formats::image::{read_gray, write_gray16, write_gray8};
use spiv_formats::vectors::{read_vectors, write_vectors, State, Vector};
use spiv_formats::FormatError;

fn planes(w: u16, h: u16, n: usize) -> Vec<u8> {
    let pb = usize::from(w) * usize::from(h) / 8;
    (0..pb * n)
        .map(|i| (i as u32).wrapping_mul(2654435761).rotate_left(7) as u8)
        .collect()
}

#[test]
fn dat_round_trip_streams_and_seeks() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.dat");
    let data = planes(24, 10, 7);
    let mut w = DatWriter::create(&path, 24, 10).unwrap();
    w.write_planes(&data[..30 * 3]).unwrap();
    w.write_planes(&data[30 * 3..]).unwrap();
    assert_eq!(w.finish().unwrap(), 7);
    let mut r = DatReader::open(&path, 24, 10, DatOptions::default()).unwrap();
    assert_eq!(r.planes(), 7);
    assert_eq!(r.read_range(0, 100).unwrap(), data);
    assert_eq!(r.read_range(5, 1).unwrap(), &data[150..180]);
    let mut p = vec![0u8; 30];
    r.seek_plane(7).unwrap();
    assert!(!r.read_plane(&mut p).unwrap());
}

#[test]
fn flip_and_head_stripping() {
    // A 16x2 file with a 8-column head: stored row 0 = image row 1.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("h.dat");
    // stored row 0: columns 0 and 9 set; stored row 1: column 3 set.
    let mut plane = vec![0u8; 4];
    pack_row(&[1 | 1 << 9], 0, 16, &mut plane);
    pack_row(&[1 << 3], 1, 16, &mut plane);
    std::fs::write(&path, &plane).unwrap();
    let opts = DatOptions {
        strip_head: 8,
        ..DatOptions::default()
    };
    let mut r = DatReader::open(&path, 16, 2, opts).unwrap();
    assert_eq!((r.width(), r.height()), (8, 2));
    let p = r.read_range(0, 1).unwrap();
    assert_eq!(p, vec![0b0000_0001, 0b0000_1000]);
    // Upright: image row 0 is stored row 1.
    let up = unpack_upright(&p, 8, 2, true);
    assert_eq!(&up[..8], &[0, 0, 0, 1, 0, 0, 0, 0]);
    assert_eq!(&up[8..], &[1, 0, 0, 0, 0, 0, 0, 0]);
    assert_eq!(unpack_upright(&p, 8, 2, false)[0], 1);
}

#[test]
fn bad_dat_files_give_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("empty.dat");
    std::fs::write(&empty, b"").unwrap();
    let e = DatReader::open(&empty, 8, 8, DatOptions::default()).unwrap_err();
    assert!(matches!(e, FormatError::Empty(_)), "{e}");
    let trunc = dir.path().join("t.dat");
    std::fs::write(&trunc, vec![0u8; 8 * 3 + 5]).unwrap();
    let e = DatReader::open(&trunc, 8, 8, DatOptions::default()).unwrap_err();
    assert!(
        e.to_string().contains("truncated last plane") && e.to_string().contains("5 bytes"),
        "{e}"
    );
    let r = DatReader::open(
        &trunc,
        8,
        8,
        DatOptions {
            allow_truncated: true,
            ..DatOptions::default()
        },
    )
    .unwrap();
    assert_eq!((r.planes(), r.truncated_bytes()), (3, 5));
    let e = DatReader::open(&trunc, 5, 5, DatOptions::default()).unwrap_err();
    assert!(matches!(e, FormatError::NotWholeBytes { .. }), "{e}");
    let e = DatReader::open(
        &trunc,
        8,
        8,
        DatOptions {
            strip_head: 8,
            ..DatOptions::default()
        },
    )
    .unwrap_err();
    assert!(matches!(e, FormatError::HeadTooWide { .. }), "{e}");
    let short = dir.path().join("s.dat");
    std::fs::write(&short, vec![0u8; 5]).unwrap();
    let e = DatReader::open(
        &short,
        8,
        8,
        DatOptions {
            allow_truncated: true,
            ..DatOptions::default()
        },
    )
    .unwrap_err();
    assert!(matches!(e, FormatError::Truncated { planes: 0, .. }), "{e}");
    let e =
        DatReader::open(&dir.path().join("missing.dat"), 8, 8, DatOptions::default()).unwrap_err();
    assert!(matches!(e, FormatError::Io { .. }), "{e}");
}

#[test]
fn images_round_trip_in_8_and_16_bit() {
    let dir = tempfile::tempdir().unwrap();
    let d8: Vec<u8> = (0..12 * 7).map(|i| (i * 3) as u8).collect();
    for ext in ["png", "tif", "bmp"] {
        let p = dir.path().join(format!("a.{ext}"));
        write_gray8(&p, 12, 7, &d8).unwrap();
        let g = read_gray(&p).unwrap();
        assert_eq!((g.width, g.height, g.bits), (12, 7, 8), "{ext}");
        assert_eq!(
            g.data,
            d8.iter().map(|&v| u16::from(v)).collect::<Vec<_>>(),
            "{ext}"
        );
    }
    let d16: Vec<u16> = (0..12 * 7).map(|i| (i * 771) as u16).collect();
    for ext in ["png", "tif"] {
        let p = dir.path().join(format!("b.{ext}"));
        write_gray16(&p, 12, 7, &d16).unwrap();
        let g = read_gray(&p).unwrap();
        assert_eq!((g.bits, g.data.clone()), (16, d16.clone()), "{ext}");
    }
    let bad = dir.path().join("bad.png");
    std::fs::write(&bad, b"not a png").unwrap();
    assert!(matches!(read_gray(&bad), Err(FormatError::Image { .. })));
}

#[test]
fn vectors_round_trip_and_bad_csv_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("v.csv");
    let v = vec![
        Vector {
            x: 15.5,
            y: 15.5,
            u: 1.25,
            v: -0.5,
            state: State::Valid,
        },
        Vector {
            x: 31.5,
            y: 15.5,
            u: 9.0,
            v: 9.0,
            state: State::Invalid,
        },
    ];
    write_vectors(&p, &v).unwrap();
    let back = read_vectors(&p).unwrap();
    assert_eq!(back[0], v[0]);
    assert_eq!(
        (back[1].u, back[1].v, back[1].state),
        (0.0, 0.0, State::Invalid),
        "flag 2 is written as u = v = 0"
    );
    std::fs::write(&p, "x,y,u,v,flag\n1,2,3,4,7\n").unwrap();
    assert!(read_vectors(&p).is_err());
    std::fs::write(&p, "a,b\n").unwrap();
    assert!(read_vectors(&p).is_err());
}

#[test]
fn a_simulation_writes_every_file_and_scene_json_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let scene = SceneParams {
        width: 96,
        height: 64,
        ..SceneParams::new(SceneKind::Vortex)
    };
    let mut req = Request::new(scene, 4);
    req.margin = 8;
    let sim = simulate_to_dir(&req, dir.path(), |_, _| {}).unwrap();
    for f in [
        "spikes.dat",
        "scene.json",
        "frame_a.png",
        "frame_b.png",
        "truth.csv",
        "profile.csv",
    ] {
        assert!(dir.path().join(f).is_file(), "{f}");
    }
    let meta = SceneMeta::read(&dir.path().join("scene.json")).unwrap();
    assert_eq!(meta, sim.meta);
    assert_eq!(
        (meta.capture.planes, meta.capture.pair),
        (13 + 16 + 1, [8, 21])
    );
    let r = DatReader::open(
        &dir.path().join("spikes.dat"),
        meta.capture.width,
        meta.capture.height,
        DatOptions::default(),
    )
    .unwrap();
    assert_eq!(r.planes(), meta.capture.planes);
    let truth = read_vectors(&dir.path().join("truth.csv")).unwrap();
    assert_eq!(truth.len(), 5 * 3);
    let peak = truth.iter().map(|v| v.u.hypot(v.v)).fold(0.0, f64::max);
    assert!(peak > 1.0 && peak <= 6.0 + 1e-9, "vortex truth peak {peak}");
    let frame = read_gray(&dir.path().join("frame_a.png")).unwrap();
    assert_eq!((frame.width, frame.height, frame.bits), (96, 64, 16));
}
