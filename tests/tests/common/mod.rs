//! What the end-to-end tests share: `spiv flow` with its defaults on a
//! simulated recording.

use spiv_firmware_sim::scene::SceneParams;
use spiv_firmware_sim::simulation::{simulate_planes, Request, Simulated};
use spiv_host::flow::{run_flow, FlowOptions, FlowOutcome, Recording};

/// `spiv flow` with its defaults on `ticks` planes of scene `p` from
/// `seed`, with `dense` as asked and, with it, the joint fit unless
/// `joint` is off: the simulation, the pair's separation and the outcome.
pub fn flow_of(
    p: &SceneParams,
    seed: u64,
    ticks: u32,
    dense: bool,
    joint: bool,
) -> (Simulated, u32, FlowOutcome) {
    let mut req = Request::new(p.clone(), seed);
    req.ticks = Some(ticks);
    let (data, sim) = simulate_planes(&req).expect("simulates");
    let pair = sim.meta.capture.pair;
    let dt = pair[1] - pair[0];
    let rec = Recording::simulated(p.width, p.height, data, dt);
    let mut opts = FlowOptions::new(&rec, dt);
    opts.dense = dense;
    if !joint {
        opts.joint = None;
    }
    let out = run_flow(&rec, &opts, |_, _| {}).expect("runs");
    (sim, dt, out)
}
