//! The reader against every reference number of `data/spike/README.md`.
//! Data: `SPIV_DATA`, else the repository's `data/`; missing data fails loudly.

use std::path::PathBuf;

use spiv_formats::dat::{count_upright, DatOptions, DatReader};
use spiv_formats::image::read_gray;
use spiv_formats::npz::read_npz_spikes;
use spiv_formats::reference_data_dir;

fn data_dir() -> PathBuf {
    let dir = reference_data_dir();
    assert!(
        dir.join("spike").is_dir(),
        "reference data not found at {} (set SPIV_DATA)",
        dir.display()
    );
    dir.join("spike")
}

fn pearson(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma).powi(2);
        sbb += (y - mb).powi(2);
    }
    sab / (saa * sbb).sqrt()
}

#[test]
fn vidar_dat_reference_numbers() {
    let path = data_dir().join("spikezoo_base_reds_400x250_301f.dat");
    let mut r = DatReader::open(&path, 400, 250, DatOptions::default()).unwrap();
    assert_eq!(r.planes(), 301);
    let mut plane = vec![0u8; r.out_plane_bytes()];
    let mut total = 0u64;
    let mut first = None;
    while r.read_plane(&mut plane).unwrap() {
        let n: u64 = plane.iter().map(|b| u64::from(b.count_ones())).sum();
        first.get_or_insert(n);
        total += n;
    }
    assert_eq!(first, Some(27_978));
    assert_eq!(total, 8_658_838);
    let rate = total as f64 / (400.0 * 250.0 * 301.0);
    assert!((rate - 0.287669).abs() < 5e-7, "{rate}");
}

#[test]
fn tfp_at_plane_150_matches_the_ground_truth_only_when_flipped() {
    let dir = data_dir();
    let gt = read_gray(&dir.join("spikezoo_base_reds_400x250_gt.png")).unwrap();
    assert_eq!((gt.width, gt.height, gt.bits), (400, 250, 8));
    let gt: Vec<f64> = gt.data.iter().map(|&v| f64::from(v)).collect();
    let mut r = DatReader::open(
        &dir.join("spikezoo_base_reds_400x250_301f.dat"),
        400,
        250,
        DatOptions::default(),
    )
    .unwrap();
    // 41 planes centred on 150.
    let planes = r.read_range(130, 41).unwrap();
    let flipped: Vec<f64> = count_upright(&planes, 400, 250, true)
        .iter()
        .map(|&c| f64::from(c))
        .collect();
    let unflipped: Vec<f64> = count_upright(&planes, 400, 250, false)
        .iter()
        .map(|&c| f64::from(c))
        .collect();
    let (cf, cu) = (pearson(&flipped, &gt), pearson(&unflipped, &gt));
    assert!(cf > 0.98, "flipped correlation {cf}");
    assert!(cu < 0.0 && cu > -0.2, "unflipped correlation {cu}");
}

#[test]
fn real_capture_npz_reference_numbers() {
    let s = read_npz_spikes(&data_dir().join("spikezoo_uhsr_real_250x250_200f.npz")).unwrap();
    assert_eq!((s.width, s.height, s.ticks), (250, 250, 200));
    let total: u64 = s.planes.iter().map(|b| u64::from(b.count_ones())).sum();
    assert_eq!(total, 392_297);
    let rate = total as f64 / (250.0 * 250.0 * 200.0);
    assert!((rate - 0.031384).abs() < 5e-7, "{rate}");
}
