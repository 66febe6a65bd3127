//! The dwell cap has one implementation (`firmware::capped_frame`): the
//! in-process reconstruction `spiv bench speed` uses and the sidecar firmware
//! `spiv run` drives give the same frame, pixel for pixel.

use spiv_firmware_sim::firmware::{run_on_planes, Config};
use spiv_firmware_sim::scene::{SceneKind, SceneParams};
use spiv_firmware_sim::simulation::simulate_planes;
use spiv_host::pipeline::{adaptive_banded, Job};
use spiv_host::reconstruct::{upright, Planes};

#[test]
fn in_process_and_firmware_capped_frames_are_identical() {
    let mut sp = SceneParams::new(SceneKind::PaperLinear);
    sp.width = 160;
    sp.height = 112;
    let job = Job::new(sp, 2);
    let (w, h) = (job.request.scene.width, job.request.scene.height);
    let (data, sim) = simulate_planes(&job.request).expect("simulate");
    let [ka, kb] = sim.meta.pair;
    // Four bands (the last one short), one without a cap (n_max).
    let caps = vec![6u16, 12, 40];
    let planes = Planes::simulated(w, h, data.clone());
    let mut cfg = Config::new(ka, kb - ka);
    cfg.params = job.core;
    cfg.pairs = Some(1);
    cfg.caps = caps.clone();
    let mut fw = run_on_planes(&data, w, h, cfg, Vec::new(), true).expect("firmware");
    let sent = fw.keep.take().expect("kept");
    for (k, f) in [ka, kb].into_iter().zip(&sent) {
        let here = adaptive_banded(&planes, u64::from(k), &job.core, &caps).expect("banded");
        assert!(
            here == upright(&f.data, w, true),
            "frame at tick {k} differs"
        );
        assert!(here.iter().any(|&g| g > 0), "an empty frame proves nothing");
    }
}
