//! Dense flow on a simulated pair against its dense truth:
//! `cargo run --release -p spiv-host --example dense_probe DIR [alpha levels warps iterations median init_level div_weight]`
//! (DIR from `spiv simulate`: frame_a.png, frame_b.png, truth.flo). Prints
//! the EPE of the PIV field interpolated to every pixel and of the dense
//! stage from rest and from that field, with times.

use std::path::PathBuf;
use std::time::Instant;

use spiv_formats::dense::{read_dense, DenseField};
use spiv_host::piv::dense::{dense_flow, DenseSettings, Flow};
use spiv_host::piv::{deform, load_image, piv, Settings, Validation};

fn field(f: &Flow) -> DenseField {
    let (h, w) = f.u.dim();
    DenseField {
        width: w,
        height: h,
        u: f.u.iter().copied().collect(),
        v: f.v.iter().copied().collect(),
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let dir = PathBuf::from(args.get(1).map_or("/tmp/turb", String::as_str));
    let num = |i: usize, d: f64| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let s = DenseSettings {
        alpha: num(2, 0.5) as f32,
        levels: num(3, 5.0) as usize,
        warps: num(4, 4.0) as usize,
        iterations: num(5, 60.0) as usize,
        median: num(6, 5.0) as usize,
        init_level: num(7, 1.0) as usize,
        div_weight: num(8, 0.0) as f32,
    };
    let a = load_image(&dir.join("frame_a.png")).expect("frame_a");
    let b = load_image(&dir.join("frame_b.png")).expect("frame_b");
    let truth = read_dense(&dir.join("truth.flo")).expect("truth.flo");
    let (h, w) = a.dim();
    let set = Settings {
        validation: Validation {
            min_peak_ratio: 1.0,
            ..Validation::default()
        },
        ..Settings::default()
    };
    let t0 = Instant::now();
    let p = piv(&a, &b, None, &set).expect("piv");
    let (du, dv) = deform::dense(&p.grid, &p.u, &p.v, h, w);
    let pf = Flow { u: du, v: dv };
    println!(
        "PIV (peak ratio off) interpolated: EPE {:.3} px, {:.0} ms",
        field(&pf).epe(&truth, None).unwrap_or(f64::NAN),
        t0.elapsed().as_secs_f64() * 1e3
    );
    // Pixels at least 16 px from the edge.
    let inner: Vec<bool> = (0..h * w)
        .map(|k| {
            let (i, j) = (k / w, k % w);
            i >= 16 && j >= 16 && i + 16 < h && j + 16 < w
        })
        .collect();
    for (name, init) in [("from rest", None), ("from PIV", Some(&pf))] {
        let t0 = Instant::now();
        let f = dense_flow(&a, &b, init, &s);
        println!(
            "dense {name}: EPE {:.3} px (inner {:.3}), {:.0} ms",
            field(&f).epe(&truth, None).unwrap_or(f64::NAN),
            field(&f).epe(&truth, Some(&inner)).unwrap_or(f64::NAN),
            t0.elapsed().as_secs_f64() * 1e3
        );
    }
}
