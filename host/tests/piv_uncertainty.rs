//! Every vector's uncertainty (Wieneke 2015, correlation statistics) on
//! frame-camera pairs with known truth: it follows the true error — about
//! as large as the errors are, larger on noisier images — and a vector PIV
//! could not measure has none (infinite).

mod common;

use common::{errors, pair, params};
use ndarray::Array2;
use spiv_firmware_sim::scene::{SceneKind, SceneParams};
use spiv_host::piv::{piv, Settings, State};

/// (share of error components within 1σ, median σ, RMS error) over the
/// valid vectors.
fn coverage(noise: f32, seed: u64) -> (f64, f64, f64) {
    let p = SceneParams {
        shift: (3.3, -1.7),
        ..params(SceneKind::Uniform)
    };
    let mut pr = pair(p, seed);
    // Deterministic pixel noise of the given amplitude (gray levels).
    let mut s = 0x9e37_79b9u64 ^ seed;
    let mut next = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((s >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 2.0 * noise
    };
    for img in [&mut pr.a, &mut pr.b] {
        img.mapv_inplace(|x| x + next());
    }
    let f = piv(&pr.a, &pr.b, None, &Settings::default()).expect("piv");
    let e = errors(&f, &pr);
    let (mut inside, mut all, mut sq) = (0usize, 0usize, 0.0f64);
    let mut sig = Vec::new();
    for ((eu, ev, st), &(su, sv)) in e.iter().zip(f.sigma.iter()) {
        if *st != State::Valid {
            continue;
        }
        assert!(su.is_finite() && sv.is_finite() && su > 0.0 && sv > 0.0);
        inside += usize::from(eu.abs() <= su) + usize::from(ev.abs() <= sv);
        all += 2;
        sq += eu * eu + ev * ev;
        sig.push(su.hypot(sv) / 2f64.sqrt());
    }
    sig.sort_by(f64::total_cmp);
    (
        inside as f64 / all.max(1) as f64,
        sig[sig.len() / 2],
        (sq / all.max(1) as f64).sqrt(),
    )
}

#[test]
fn the_uncertainty_follows_the_error() {
    let clean = coverage(0.0, 3);
    let noisy = coverage(600.0, 3);
    eprintln!(
        "clean: cover {:.2} median σ {:.4} rms {:.4}",
        clean.0, clean.1, clean.2
    );
    eprintln!(
        "noisy: cover {:.2} median σ {:.4} rms {:.4}",
        noisy.0, noisy.1, noisy.2
    );
    for (cov, sig, rms) in [clean, noisy] {
        assert!((0.45..=0.97).contains(&cov), "coverage {cov}");
        assert!(
            sig > 0.3 * rms && sig < 4.0 * rms,
            "σ {sig} against rms {rms}"
        );
    }
    assert!(
        noisy.2 > 1.5 * clean.2,
        "the noise must matter: {noisy:?} {clean:?}"
    );
    assert!(noisy.1 > 1.5 * clean.1, "σ must grow with the noise");
}

#[test]
fn unmeasured_vectors_have_no_uncertainty() {
    let (h, w) = (96, 96);
    let flat = Array2::from_elem((h, w), 100.0f32);
    let f = piv(&flat, &flat, None, &Settings::default()).expect("piv");
    for (st, &(su, sv)) in f.state.iter().zip(f.sigma.iter()) {
        assert_eq!(*st, State::Invalid);
        assert!(su.is_infinite() && sv.is_infinite());
    }
}

/// Without `uncertainty` (what `spiv piv` and Python's `piv` run, whose
/// outputs carry none) the field is the same, vector for vector, and no
/// vector claims an uncertainty.
#[test]
fn skipping_the_uncertainty_leaves_the_vectors() {
    let p = SceneParams {
        shift: (3.3, -1.7),
        ..params(SceneKind::Uniform)
    };
    let pr = pair(p, 4);
    let with = piv(&pr.a, &pr.b, None, &Settings::default()).expect("piv");
    let s = Settings {
        uncertainty: false,
        ..Settings::default()
    };
    let without = piv(&pr.a, &pr.b, None, &s).expect("piv");
    assert_eq!(with.u, without.u);
    assert_eq!(with.v, without.v);
    assert_eq!(with.state, without.state);
    assert!(with.sigma.iter().any(|s| s.0.is_finite()));
    assert!(without.sigma.iter().all(|&s| s == spiv_host::piv::NO_SIGMA));
}
