//! The host's receiver on arbitrary bytes: the core's COBS/CRC stream
//! decoder, frame reassembly (with the tile decoders) and pairing, fed in
//! chunks whose sizes the input chooses. Never a panic, never more memory
//! than the frame limit allows, and the counts stay consistent.
//!
//! Run by the fuzz target of the same name (`fuzz/fuzz_targets`) and, over
//! the committed corpus, by `tests/tests/fuzz_corpora.rs`.

use spiv_host::receive::{receive, Event, FrameLimit, Source};
use spiv_host::Error;

/// Bytes handed out in chunks of 1..=64 sizes drawn from the input's head.
struct Chunks<'a> {
    data: &'a [u8],
    sizes: &'a [u8],
    i: usize,
}

impl Source for Chunks<'_> {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Error> {
        let want = self
            .sizes
            .get(self.i % self.sizes.len().max(1))
            .map_or(4096, |&s| usize::from(s % 64) + 1);
        self.i += 1;
        let n = want.min(buf.len()).min(self.data.len());
        buf[..n].copy_from_slice(&self.data[..n]);
        self.data = &self.data[n..];
        Ok(n)
    }
    fn name(&self) -> String {
        "fuzz".into()
    }
}

/// One input: returns, or panics on a finding.
pub fn run(input: &[u8]) {
    let (sizes, data) = input.split_at(input.len().min(8));
    let mut src = Chunks { data, sizes, i: 0 };
    // Small frames (the binaries accept 8192 × 8192): larger ones take the
    // same refusal path, and each input costs microseconds, not zeroing
    // megabytes.
    let limit = FrameLimit {
        width: 128,
        height: 128,
    };
    let mut frames = 0u64;
    let report = receive::<Error>(
        &mut src,
        limit,
        |e| {
            if let Event::Frame(f) = e {
                assert!(limit.admits(f.width, f.height));
                assert_eq!(f.data.len(), usize::from(f.width) * usize::from(f.height));
                frames += 1;
            }
            Ok(())
        },
        |_| {},
    )
    .expect("a memory source never fails");
    assert_eq!(report.frames, frames);
    assert_eq!(report.bytes, data.len() as u64);
}
