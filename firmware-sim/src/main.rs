//! `spiv-firmware-sim`: the sidecar, simulated. Spike planes from the
//! simulated sensor (`--scene`) or a `.dat` file (`--input`) go through
//! spiv-core's firmware loop; framed messages go to stdout, a file, or a
//! loopback TCP socket it listens on; faults can be injected on the way.
//! Control messages from the host (predicted motion, window caps) come back
//! on the TCP connection or from `--control` (a file, a FIFO or stdin).

use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

use clap::Parser;
use spiv_core::downlink::DownlinkStats;
use spiv_core::wire::{crc32, frame_crc, Encoding};
use spiv_core::Method;
use spiv_firmware_sim::downlink::ControlStream;
use spiv_firmware_sim::drive::{run_ladder_on_dat, run_ladder_on_scene, run_on_dat, run_on_scene};
use spiv_firmware_sim::firmware::{
    Config, Counters, FaultCounts, Faults, Faulty, Firmware, Plain, SentFrame,
};
use spiv_firmware_sim::ladder::LadderConfig;
use spiv_firmware_sim::scene::{SceneKind, SceneParams, TICK_HZ};
use spiv_firmware_sim::simulation::Request;
use spiv_formats::capture::Capture;
use spiv_formats::dat::DatOptions;
use spiv_formats::MAX_FRAME_PIXELS;

/// Largest pair separation accepted, ticks (as `spiv simulate --dt`).
const MAX_DT: u32 = 1_000_000;

#[derive(Debug, Parser)]
#[command(
    name = "spiv-firmware-sim",
    version,
    about = "The spiv sidecar, simulated: spike planes in, compressed frame pairs out over the wire protocol"
)]
struct Args {
    /// Simulate this scene (paper-linear, paper-quadratic, paper-log, blasius, uniform, vortex, turbulence, large-shift).
    #[arg(long, conflicts_with = "input", required_unless_present = "input")]
    scene: Option<String>,
    /// Or read spike planes from this .dat.
    #[arg(long)]
    input: Option<PathBuf>,
    /// Width of the .dat, px (else from scene.json beside it).
    #[arg(long)]
    width: Option<u16>,
    /// Height of the .dat, px.
    #[arg(long)]
    height: Option<u16>,
    /// Listen on this address (e.g. 127.0.0.1:7878) and send to the first host that connects.
    #[arg(long, conflicts_with = "out")]
    tcp: Option<String>,
    /// Write the messages to this file (stdout when neither --tcp nor --out).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Faults per message: drop=P,corrupt=P,truncate=P,stall=P,reorder=P,duplicate=P.
    #[arg(long)]
    fault: Option<String>,
    /// Seed of the scene and of the faults.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Frame pairs to send (scene: default 4; file: until it ends).
    #[arg(long)]
    pairs: Option<u32>,
    /// Ticks between the frames of a pair (scene: its pair_dt; file: scene.json or 13).
    #[arg(long)]
    dt: Option<u32>,
    /// Ticks between pairs (default 4·dt).
    #[arg(long)]
    every: Option<u32>,
    /// Tick of the first frame (default: n_max/2, the first with a whole
    /// window; ladder: the first pair's first frame, default its midpoint
    /// at tick 32).
    #[arg(long)]
    first: Option<u32>,
    /// Tile coding: rice (lossless, default), context (lossless,
    /// context-modelled: about half of rice's bytes), sparse (lossy),
    /// sparse-context (lossy, sparse's frames in fewer bytes), raw.
    #[arg(long, default_value = "rice")]
    encoding: String,
    /// Sparse mode: largest error of a background sample, gray levels.
    #[arg(long, default_value_t = 12)]
    tolerance: u16,
    /// Sparse mode: a block's tolerance is at most its contrast (brightest
    /// sample above background) over this, so dim particles stay exact; 0: off.
    #[arg(long, default_value_t = 4)]
    contrast: u16,
    /// Sparse mode: the contrast rule on motion-compensated frames (their
    /// particles are at full scale, so more noise may go).
    #[arg(long, default_value_t = 2)]
    contrast_mc: u16,
    /// Frame method: adaptive, tfp, tfi, mc (motion-compensated: needs
    /// the host's predicted motion over the downlink — `--tcp` or
    /// `--control` — and sends the paper's adaptive frames until it has one)
    /// or ladder (the live loop of `spiv flow`'s time ladder: each pair's
    /// events, or its rung frames along the flow the host asked for over
    /// the downlink; `spiv receive --piv --control` measures them).
    #[arg(long, default_value = "adaptive")]
    method: String,
    /// mc: how frames are made until the host's first motion arrives: tfp
    /// (8 ticks; default) or adaptive (the paper's).
    #[arg(long, default_value = "tfp")]
    bootstrap: String,
    /// Read the host's control messages from this file or FIFO (`-`:
    /// stdin). With `--tcp` they come back on the connection. With
    /// `--checksum` the whole stream (at most 4 MiB) is heard before the
    /// first plane, so the line is the same on every run.
    #[arg(long, value_name = "PATH", conflicts_with = "tcp")]
    control: Option<PathBuf>,
    /// Before each pair after the first, wait up to MS milliseconds for the
    /// host's answer to the previous pair (a simulation runs faster than
    /// the host's PIV; a real sensor never waits). 0: never wait.
    #[arg(long, value_name = "MS", default_value_t = 0)]
    control_wait: u64,
    /// Faults per control message on the downlink (as --fault).
    #[arg(long, value_name = "FAULTS")]
    control_fault: Option<String>,
    /// Adaptive/TFI window limit n_max, or the TFP window, ticks.
    #[arg(long)]
    window: Option<u16>,
    /// Do not print the throughput line.
    #[arg(long)]
    quiet: bool,
    /// Send nothing; print one line with the counts, the CRC-32 of the whole
    /// message stream and of every frame — the line the Cortex-M4 firmware
    /// (`firmware-sim/cortex-m4`) prints for the same input, to compare.
    #[arg(long, conflicts_with_all = ["tcp", "out", "fault"])]
    checksum: bool,
}

/// The message stream, kept for `--checksum`, and the TCP connection,
/// kept to end it gracefully ([`Shared::close`]).
#[derive(Debug, Clone, Default)]
struct Shared(
    std::rc::Rc<std::cell::RefCell<Vec<u8>>>,
    std::rc::Rc<std::cell::RefCell<Option<std::net::TcpStream>>>,
);

/// Longest wait, after the last message, for the host to read what it was
/// sent and close its end.
const CLOSE_WAIT: std::time::Duration = std::time::Duration::from_secs(600);

impl Shared {
    /// Ends a TCP link gracefully: no more messages, then the host's
    /// answers read (and dropped) until it closes its end. Closing with
    /// its answers unread would reset the connection, and the host would
    /// lose the messages still in flight.
    fn close(&self, control: Option<&mut ControlStream>) {
        let Some(s) = self.1.borrow_mut().take() else {
            return;
        };
        let _ = s.shutdown(std::net::Shutdown::Write);
        if let Some(c) = control {
            c.drain(CLOSE_WAIT);
        }
    }
}

impl Write for Shared {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.borrow_mut().extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[derive(Debug, thiserror::Error)]
enum Error {
    #[error("{0}")]
    Usage(String),
    #[error(transparent)]
    Sim(#[from] spiv_firmware_sim::Error),
    #[error(transparent)]
    Format(#[from] spiv_formats::FormatError),
    #[error("{0}")]
    Io(#[from] std::io::Error),
}

fn main() {
    let args: Args = spiv_args::parse_or_exit("spiv-firmware-sim");
    match run(&args) {
        Ok(()) => {}
        Err(Error::Sim(spiv_firmware_sim::Error::Link(e)))
            if e.kind() == std::io::ErrorKind::BrokenPipe =>
        {
            eprintln!("spiv-firmware-sim: error: the receiver closed the link");
            std::process::exit(1);
        }
        Err(e) => {
            eprintln!("spiv-firmware-sim: error: {e}");
            std::process::exit(1);
        }
    }
}

fn config(a: &Args, dt: u32) -> Result<Config, Error> {
    if !(1..=MAX_DT).contains(&dt) {
        return Err(Error::Usage(format!(
            "dt {dt}: expected 1..={MAX_DT} ticks between the frames of a pair"
        )));
    }
    let mut cfg = Config::new(0, dt);
    cfg.method = Method::from_name(&a.method).ok_or_else(|| {
        Error::Usage(format!(
            "unknown --method {} (adaptive, tfp, tfi, mc)",
            a.method
        ))
    })?;
    if cfg.method == Method::Mc {
        cfg.refine = Some(spiv_core::motion::Refine::default());
        cfg.bootstrap = match a.bootstrap.as_str() {
            "tfp" => Method::Tfp,
            "adaptive" => Method::Adaptive,
            b => {
                return Err(Error::Usage(format!(
                    "unknown --bootstrap {b} (tfp, adaptive)"
                )))
            }
        };
    }
    match (cfg.method, a.window) {
        (Method::Tfp, Some(n)) => cfg.tfp_window = n,
        (_, Some(n)) => cfg.params.n_max = n,
        (_, None) => {}
    }
    cfg.encoding = Encoding::from_name(&a.encoding).ok_or_else(|| {
        Error::Usage(format!(
            "unknown --encoding {} (rice, context, sparse, sparse-context, raw)",
            a.encoding
        ))
    })?;
    cfg.lossy.tolerance = a.tolerance;
    cfg.lossy.contrast = a.contrast;
    cfg.lossy.contrast_mc = a.contrast_mc;
    let window = cfg.window();
    if !(1..=255).contains(&window) {
        return Err(Error::Usage(format!("--window {window}: expected 1..=255")));
    }
    let s = &mut cfg.schedule;
    s.first = a.first.unwrap_or(u32::from(window / 2));
    s.every = a.every.unwrap_or(4 * dt);
    if s.every < dt {
        return Err(Error::Usage(format!(
            "--every {} must be at least dt = {dt}",
            s.every
        )));
    }
    s.pairs = a.pairs;
    Ok(cfg)
}

/// Where messages go: stdout, a file or the first TCP client; and where
/// the host's control messages come from, if anywhere.
fn open_link(a: &Args, shared: &Shared) -> Result<(Box<dyn Write>, Option<ControlStream>), Error> {
    let faults = match &a.control_fault {
        Some(f) => Faults::parse(f).map_err(|e| Error::Usage(format!("--control-fault: {e}")))?,
        None => Faults::default(),
    };
    let seed = a.seed ^ 0x00d0_117e;
    if a.checksum {
        // Deterministic: the whole control stream is heard before the first
        // plane (as the Cortex-M4 firmware hears its committed control).
        let control = match &a.control {
            Some(p) => Some(ControlStream::preloaded(&read_control(p)?, faults, seed)),
            None => None,
        };
        return Ok((Box::new(shared.clone()), control));
    }
    let paced = |c: ControlStream| match a.control_wait {
        0 => c,
        ms => c.wait(std::time::Duration::from_millis(ms)),
    };
    let mut control = match &a.control {
        Some(p) if p.as_os_str() == "-" => Some(paced(ControlStream::spawn(
            || Ok(std::io::stdin()),
            faults,
            seed,
        ))),
        Some(p) => {
            let p = p.clone();
            Some(paced(ControlStream::spawn(
                move || std::fs::File::open(p),
                faults,
                seed,
            )))
        }
        None => None,
    };
    let link: Box<dyn Write> = match (&a.tcp, &a.out) {
        (Some(addr), _) => {
            let l = std::net::TcpListener::bind(addr)
                .map_err(|e| Error::Usage(format!("--tcp {addr}: cannot listen ({e})")))?;
            if !a.quiet {
                eprintln!("spiv-firmware-sim: listening on {}", l.local_addr()?);
            }
            let (s, peer) = l.accept()?;
            if !a.quiet {
                eprintln!("spiv-firmware-sim: host {peer} connected");
            }
            let back = s.try_clone()?;
            *shared.1.borrow_mut() = Some(s.try_clone()?);
            control = Some(paced(ControlStream::spawn(move || Ok(back), faults, seed)));
            Box::new(std::io::BufWriter::with_capacity(1 << 16, s))
        }
        (None, Some(p)) => Box::new(std::io::BufWriter::new(
            std::fs::File::create(p)
                .map_err(|e| Error::Usage(format!("--out {}: {e}", p.display())))?,
        )),
        (None, None) => Box::new(std::io::BufWriter::with_capacity(
            1 << 16,
            std::io::stdout().lock(),
        )),
    };
    Ok((link, control))
}

/// Most bytes `--checksum` reads from `--control` (a few hundred control
/// messages of the largest size).
const MAX_CONTROL_FILE: u64 = 1 << 22;

/// The whole control stream at `path` (`-`: stdin), bounded.
fn read_control(path: &std::path::Path) -> Result<Vec<u8>, Error> {
    use std::io::Read;
    let mut bytes = Vec::new();
    let what = |e: std::io::Error| Error::Usage(format!("--control {}: {e}", path.display()));
    if path.as_os_str() == "-" {
        std::io::stdin()
            .lock()
            .take(MAX_CONTROL_FILE + 1)
            .read_to_end(&mut bytes)
            .map_err(what)?;
    } else {
        std::fs::File::open(path)
            .map_err(what)?
            .take(MAX_CONTROL_FILE + 1)
            .read_to_end(&mut bytes)
            .map_err(what)?;
    }
    if bytes.len() as u64 > MAX_CONTROL_FILE {
        return Err(Error::Usage(format!(
            "--control {}: more than {MAX_CONTROL_FILE} bytes",
            path.display()
        )));
    }
    Ok(bytes)
}

fn run(a: &Args) -> Result<(), Error> {
    let faults = match &a.fault {
        Some(f) => Faults::parse(f).map_err(|e| Error::Usage(format!("--fault: {e}")))?,
        None => Faults::default(),
    };
    let t0 = Instant::now();
    let shared = Shared::default();
    if a.method == "mc" && a.tcp.is_none() && a.control.is_none() && !a.quiet && !a.checksum {
        eprintln!(
            "spiv-firmware-sim: --method mc without a downlink (--tcp or --control): the paper's adaptive frames"
        );
    }
    if a.method == "ladder" {
        return run_ladder(a, &shared, faults, t0);
    }
    let mut run = match &a.scene {
        Some(name) => from_scene(a, name, &shared, faults)?,
        None => from_input(a, &shared, faults)?,
    };
    if a.checksum {
        let stream = shared.0.borrow();
        let frames: Vec<u32> = run.kept.iter().map(|f| frame_crc(&f.data)).collect();
        println!("{}", checksum_line(&run.counters, crc32(&stream), &frames));
        return Ok(());
    }
    if !a.quiet {
        let secs = t0.elapsed().as_secs_f64();
        report(&run.counters, run.width, run.height, run.tick_hz, secs);
        if faults != Faults::default() {
            report_faults(&run.faults);
        }
        if let (d, Some(c)) = &run.heard {
            report_downlink(d, c);
        }
    }
    shared.close(run.heard.1.as_mut());
    Ok(())
}

/// The live loop's schedule from the command line, pairs `dt` apart.
fn ladder_config(a: &Args, dt: u32) -> Result<LadderConfig, Error> {
    let mut cfg = LadderConfig::new(dt);
    cfg.every = a.every.unwrap_or(cfg.every);
    cfg.first = a.first.unwrap_or(cfg.first);
    cfg.pairs = a.pairs;
    cfg.check().map_err(|e| Error::Usage(e.to_string()))?;
    Ok(cfg)
}

/// The live loop of the time ladder on `--scene` or `--input`.
fn run_ladder(a: &Args, shared: &Shared, faults: Faults, t0: Instant) -> Result<(), Error> {
    if a.checksum {
        return Err(Error::Usage(
            "--checksum: the Cortex-M4 firmware does not run --method ladder".into(),
        ));
    }
    // The live loop's pairs have their own coding (lossless context
    // tiles) and frames (rung frames along the host's asks).
    for (given, what) in [
        (a.window.is_some(), "--window"),
        (a.encoding != "rice", "--encoding"),
        (a.bootstrap != "tfp", "--bootstrap"),
    ] {
        if given {
            return Err(Error::Usage(format!(
                "{what} does not apply to --method ladder (its pairs are rung frames and events, coded losslessly)"
            )));
        }
    }
    if a.tcp.is_none() && a.control.is_none() && !a.quiet {
        eprintln!(
            "spiv-firmware-sim: --method ladder without a downlink (--tcp or --control): every pair carries its events"
        );
    }
    let (out, mut control) = open_link(a, shared)?;
    let link = Faulty::new(Plain(out), faults, a.seed);
    let (fw, (w, h), tick_hz) = match &a.scene {
        Some(name) => {
            let p = scene_params(a, name)?;
            let (w, h) = (p.width, p.height);
            let mut cfg = ladder_config(a, p.pair_dt)?;
            cfg.pairs = Some(a.pairs.unwrap_or(4).max(1));
            let req = Request::new(p, a.seed);
            let fw = run_ladder_on_scene(&req, cfg, link, control.as_mut())?;
            (fw, (w, h), None)
        }
        None => {
            let (path, (w, h), dt, tick_hz) = input_layout(a)?;
            let cfg = ladder_config(a, dt)?;
            let opts = DatOptions::default();
            let fw = run_ladder_on_dat(&path, (w, h), opts, cfg, link, control.as_mut())?;
            (fw, (w, h), Some(tick_hz))
        }
    };
    if !a.quiet {
        let c = fw.counts();
        let secs = t0.elapsed().as_secs_f64().max(1e-9);
        let raw = f64::from(c.planes) * f64::from(w) * f64::from(h) / 8.0;
        let bytes = c.cost.head + c.cost.rung_frames + c.cost.events + c.cost.rates;
        eprintln!(
            "spiv-firmware-sim: {} planes, {} pairs ({} with rung frames), {} messages, {} bytes ({:.1}x less than the {:.0} raw spike bytes) in {:.2} s, {:.3}x real time at {:.0} kHz",
            c.planes,
            c.pairs,
            c.warm,
            c.messages,
            bytes,
            raw / bytes.max(1) as f64,
            raw,
            secs,
            f64::from(c.planes) / tick_hz.unwrap_or(TICK_HZ) / secs,
            tick_hz.unwrap_or(TICK_HZ) / 1e3,
        );
        if c.lost != (0, 0) {
            eprintln!(
                "spiv-firmware-sim: the event ring lost {} events and dropped {} ticks for room",
                c.lost.0, c.lost.1
            );
        }
        if faults != Faults::default() {
            report_faults(&fw.into_link().counts);
        }
        if let Some(c) = &control {
            report_asks(c);
        }
    }
    shared.close(control.as_mut());
    Ok(())
}

/// One line on the faults injected on the uplink.
fn report_faults(f: &FaultCounts) {
    eprintln!(
        "spiv-firmware-sim: faults: {} dropped, {} corrupted, {} truncated, {} stalled, {} reordered, {} duplicated",
        f.dropped, f.corrupted, f.truncated, f.stalled, f.reordered, f.duplicated
    );
}

/// One line on what the downlink of the live loop heard.
fn report_asks(c: &ControlStream) {
    let f = c.fault_counts();
    eprintln!(
        "spiv-firmware-sim: downlink: {} pairs began without an answer; faults: {} dropped, {} corrupted, {} truncated, {} reordered, {} duplicated",
        c.timeouts, f.dropped, f.corrupted, f.truncated, f.reordered, f.duplicated
    );
}

/// The scene `name` with the command line's pair separation and size.
fn scene_params(a: &Args, name: &str) -> Result<SceneParams, Error> {
    let kind = SceneKind::parse(name).map_err(|e| Error::Usage(e.to_string()))?;
    let mut p = SceneParams::new(kind);
    if let Some(dt) = a.dt {
        p.pair_dt = dt;
    }
    let (w, h) = (a.width.unwrap_or(p.width), a.height.unwrap_or(p.height));
    check_size(w, h)?;
    (p.width, p.height) = (w, h);
    Ok(p)
}

/// A simulated sensor's size, checked.
fn check_size(w: u16, h: u16) -> Result<(), Error> {
    if w < 8
        || h < 8
        || (usize::from(w) * usize::from(h)) % 8 != 0
        || u64::from(w) * u64::from(h) > MAX_FRAME_PIXELS
    {
        return Err(Error::Usage(format!(
            "--width {w} --height {h}: both at least 8, width*height a multiple of 8 and at most {MAX_FRAME_PIXELS}"
        )));
    }
    Ok(())
}

/// `--input`'s path, size, pair separation and tick rate (from the
/// scene.json beside it, or the command line).
fn input_layout(a: &Args) -> Result<(PathBuf, (u16, u16), u32, f64), Error> {
    let path = a
        .input
        .as_ref()
        .ok_or_else(|| Error::Usage("--scene or --input".into()))?;
    let meta = Capture::beside(path)?;
    let (w, h) = match (a.width, a.height, &meta) {
        (Some(w), Some(h), _) => (w, h),
        (None, None, Some(m)) => (m.width, m.height),
        _ => {
            return Err(Error::Usage(format!(
                "{}: give --width and --height (no scene.json beside it)",
                path.display()
            )))
        }
    };
    // scene.json is input too: a pair listed backwards is refused by the
    // schedule's range check, not wrapped.
    let dt =
        a.dt.or_else(|| meta.as_ref().map(|m| m.pair[1].saturating_sub(m.pair[0])))
            .unwrap_or(13);
    let tick_hz = meta.map_or(TICK_HZ, |m| m.tick_hz);
    Ok((path.clone(), (w, h), dt, tick_hz))
}

/// What one run of the firmware loop leaves for the report.
struct Run {
    counters: Counters,
    width: u16,
    height: u16,
    /// The recording's tick rate (`None`: simulated at [`TICK_HZ`]).
    tick_hz: Option<f64>,
    /// Faults injected on the uplink.
    faults: FaultCounts,
    /// The frames as the firmware made them.
    kept: Vec<SentFrame>,
    /// What the downlink heard, and the control stream if there was one.
    heard: (DownlinkStats, Option<ControlStream>),
}

impl Run {
    /// What firmware `fw` (over its faulty uplink) leaves, with the control
    /// stream it heard, the frames' size and the tick rate.
    fn of(
        mut fw: Firmware<Faulty<Plain<Box<dyn Write>>>>,
        control: Option<ControlStream>,
        (width, height): (u16, u16),
        tick_hz: Option<f64>,
    ) -> Run {
        Run {
            kept: fw.keep.take().unwrap_or_default(),
            counters: fw.counters(),
            heard: (fw.downlink(), control),
            faults: fw.into_link().counts,
            width,
            height,
            tick_hz,
        }
    }
}

/// The firmware loop on the simulated scene `name`.
fn from_scene(a: &Args, name: &str, shared: &Shared, faults: Faults) -> Result<Run, Error> {
    let p = scene_params(a, name)?;
    let (w, h) = (p.width, p.height);
    let mut cfg = config(a, p.pair_dt)?;
    cfg.schedule.pairs = Some(a.pairs.unwrap_or(4).max(1));
    let req = Request::new(p, a.seed);
    let (out, mut control) = open_link(a, shared)?;
    let link = Faulty::new(Plain(out), faults, a.seed);
    let (fw, _) = run_on_scene(&req, cfg, link, a.checksum, control.as_mut(), |_, _| {})?;
    Ok(Run::of(fw, control, (w, h), None))
}

/// The firmware loop on the recording `--input` (its size and pair from
/// the scene.json beside it, or the command line).
fn from_input(a: &Args, shared: &Shared, faults: Faults) -> Result<Run, Error> {
    let (path, (w, h), dt, tick_hz) = input_layout(a)?;
    let cfg = config(a, dt)?;
    let (out, mut control) = open_link(a, shared)?;
    let link = Faulty::new(Plain(out), faults, a.seed);
    let opts = DatOptions::default();
    let fw = run_on_dat(&path, w, h, opts, cfg, link, a.checksum, control.as_mut())?;
    Ok(Run::of(fw, control, (w, h), Some(tick_hz)))
}

/// One line on what the downlink heard, and its injected faults.
fn report_downlink(d: &DownlinkStats, c: &ControlStream) {
    let f = c.fault_counts();
    let faults = if f == Default::default() {
        String::new()
    } else {
        format!(
            "; faults: {} dropped, {} corrupted, {} truncated, {} reordered, {} duplicated",
            f.dropped, f.corrupted, f.truncated, f.reordered, f.duplicated
        )
    };
    eprintln!(
        "spiv-firmware-sim: downlink: {} controls heard, {} applied, {} refused; {} pairs began without an answer{faults}",
        d.heard, d.applied, d.refused, c.timeouts
    );
}

/// The parity line; `firmware-sim/cortex-m4` prints the same format.
fn checksum_line(c: &Counters, stream_crc: u32, frames: &[u32]) -> String {
    let frames: Vec<String> = frames.iter().map(|f| format!("{f:08x}")).collect();
    format!(
        "planes={} frames={} messages={} bytes={} stream_crc={stream_crc:08x} frame_crcs={}",
        c.planes,
        c.frames,
        c.messages,
        c.bytes,
        frames.join(",")
    )
}

/// The summary line. `tick_hz`: the recording's tick rate, for the
/// real-time factor (`None`: a simulated scene, whose time includes
/// simulating the sensor; the factor is then against the scene's 20 kHz
/// and said to include it).
fn report(c: &Counters, w: u16, h: u16, tick_hz: Option<f64>, secs: f64) {
    let px_ticks = f64::from(c.planes) * f64::from(w) * f64::from(h);
    let raw = px_ticks / 8.0;
    let secs = secs.max(1e-9);
    let rate = tick_hz.unwrap_or(TICK_HZ);
    eprintln!(
        "spiv-firmware-sim: {} planes, {} frames, {} messages, {} bytes ({:.1}x less than the {:.0} raw spike bytes) in {:.2} s: {:.2e} pixel-ticks/s, {:.3}x real time at {:.0} kHz{}",
        c.planes,
        c.frames,
        c.messages,
        c.bytes,
        raw / c.bytes.max(1) as f64,
        raw,
        secs,
        px_ticks / secs,
        f64::from(c.planes) / rate / secs,
        rate / 1e3,
        if tick_hz.is_none() { " (sensor simulation included)" } else { "" }
    );
}
