//! Window counts of 64 pixels at once, as eight bit planes (vertical
//! counters): bit `i` of plane `b` is bit `b` of pixel `i`'s count. Adding
//! a spike plane is a handful of logic operations for 64 pixels, and so is
//! asking which pixels count at least `t` — the segmentation asks that of
//! every pixel at every level and reads bytes only for the few that
//! answer yes. An FPGA keeps its counters the same way.
//!
//! Hand-written (no crate does bit-sliced counters in `no_std`), exact,
//! with counts below 256 (a window holds at most 255 ticks).

/// The counts of 64 pixels, plane `b` holding bit `b` of each.
pub type Counter = [u64; 8];

/// `SPREAD[b]` has byte `i` equal to bit `i` of `b`.
pub(crate) const SPREAD: [u64; 256] = {
    let mut t = [0u64; 256];
    let mut b = 0;
    while b < 256 {
        let mut i = 0;
        while i < 8 {
            if (b >> i) & 1 == 1 {
                t[b] |= 1 << (8 * i);
            }
            i += 1;
        }
        b += 1;
    }
    t
};

/// Adds one spike word per item of `items` (`word(item)`, bit `i` a spike
/// of pixel `i`) to `c`, as [`add_fn`] does. The caller keeps every count
/// below 256.
#[inline(always)]
pub fn add<T: Copy>(c: &mut Counter, items: &[T], word: impl Fn(T) -> u64) {
    for chunk in items.chunks(15) {
        let mut s = [0u64; 4];
        for &item in chunk {
            csa(&mut s, word(item));
        }
        add_nibble(c, s);
    }
}

/// Adds the words `word(0..n)` to `c`: 15 words at a time are summed into
/// 4-bit carry-save counters, two at a time ([`csa2`]: a full adder and
/// its carry's ripple, five logic operations per word), then added to the
/// 8-bit counters with a ripple of full adders that stops where the carry
/// dies. The caller keeps every count below 256.
#[inline(always)]
pub fn add_fn(c: &mut Counter, n: usize, word: impl Fn(usize) -> u64) {
    let mut i = 0;
    while i < n {
        let e = (i + 15).min(n);
        add_nibble(c, nibble(i..e, &word));
        i = e;
    }
}

/// Adds one word to a 4-bit carry-save counter `s` (bit planes 0..4), for
/// any type with the bit operations: `u64`, or two words in a vector.
#[inline(always)]
pub fn csa<T>(s: &mut [T; 4], x: T)
where
    T: Copy + core::ops::BitAnd<Output = T> + core::ops::BitXorAssign,
{
    let c0 = s[0] & x;
    s[0] ^= x;
    let c1 = s[1] & c0;
    s[1] ^= c0;
    let c2 = s[2] & c1;
    s[2] ^= c1;
    s[3] ^= c2;
}

/// The words `word(q)` for `q` in `range` (at most 15 of them) summed
/// into a 4-bit carry-save nibble, two at a time through [`csa2`].
#[inline(always)]
pub fn nibble(range: core::ops::Range<usize>, word: impl Fn(usize) -> u64) -> [u64; 4] {
    let mut s = [0u64; 4];
    let mut q = range.start;
    while q + 1 < range.end {
        csa2(&mut s, word(q), word(q + 1));
        q += 2;
    }
    if q < range.end {
        csa(&mut s, word(q));
    }
    s
}

/// Adds two words to a 4-bit carry-save counter `s`: a full adder on the
/// low plane (five operations), its carry rippled through the others.
#[inline(always)]
pub fn csa2<T>(s: &mut [T; 4], x: T, y: T)
where
    T: Copy
        + core::ops::BitAnd<Output = T>
        + core::ops::BitOr<Output = T>
        + core::ops::BitXor<Output = T>
        + core::ops::BitXorAssign,
{
    let u = s[0] ^ x;
    let c = (s[0] & x) | (u & y);
    s[0] = u ^ y;
    let c1 = s[1] & c;
    s[1] ^= c;
    let c2 = s[2] & c1;
    s[2] ^= c1;
    s[3] ^= c2;
}

/// Adds a 4-bit bit-sliced number to `c`.
#[inline(always)]
pub(crate) fn add_nibble(c: &mut Counter, p: [u64; 4]) {
    if p[0] | p[1] | p[2] | p[3] == 0 {
        return;
    }
    let mut carry = 0u64;
    for (cb, &pb) in c.iter_mut().zip(&p) {
        let x = *cb ^ pb;
        let s = x ^ carry;
        carry = (*cb & pb) | (carry & x);
        *cb = s;
    }
    for cb in c.iter_mut().skip(4) {
        if carry == 0 {
            break;
        }
        let s = *cb ^ carry;
        carry &= *cb;
        *cb = s;
    }
}

/// The pixels whose count is at least `t` (all for 0, none above 255).
#[inline]
pub fn at_least(c: &Counter, t: u32) -> u64 {
    at_least_live(c, t, 8)
}

/// Planes a count of at most `max` can set (`max` < 256): the bit length
/// of `max`. A window's counts are at most its length, so the planes above
/// stay zero and need not be read.
#[inline]
pub fn live_planes(max: u32) -> usize {
    (32 - max.min(255).leading_zeros()) as usize
}

/// [`at_least`] where only the low `live` planes (at most 8) can be set,
/// as [`live_planes`] gives them: the others are not read.
#[inline]
pub fn at_least_live(c: &Counter, t: u32, live: usize) -> u64 {
    let live = live.min(8);
    if t == 0 {
        return u64::MAX;
    }
    if t >= 1 << live {
        // Above every count the live planes can hold (t > 255 included).
        return 0;
    }
    if t == 2 {
        // The segmentation's first filter at every level: any bit from 1
        // up. All seven planes (those past `live` are zero): a fixed OR
        // costs half what a loop over the live ones does.
        return c[1] | c[2] | c[3] | c[4] | c[5] | c[6] | c[7];
    }
    if t.is_power_of_two() {
        // At least 2^m: any bit from m up.
        return c[t.trailing_zeros() as usize..live]
            .iter()
            .fold(0, |a, &p| a | p);
    }
    // From the top bit down: `gt` already greater, `eq` equal so far.
    let (mut gt, mut eq) = (0u64, u64::MAX);
    for b in (0..live).rev() {
        if (t >> b) & 1 == 1 {
            eq &= c[b];
        } else {
            gt |= eq & c[b];
            eq &= !c[b];
        }
        if eq == 0 {
            break;
        }
    }
    gt | eq
}

/// The count of pixel `i` (0..64).
#[inline]
pub fn count(c: &Counter, i: u32) -> u8 {
    let mut v = 0u8;
    for (b, &p) in c.iter().enumerate() {
        v |= (((p >> i) & 1) as u8) << b;
    }
    v
}

/// The counts of pixels `8g..8g + 8` (`g` in 0..8), one per byte (byte
/// `i` is pixel `8g + i`): each plane's byte `g` read as a byte (one load,
/// not a load and a shift) and spread by [`SPREAD`].
#[inline]
pub fn bytes8(c: &Counter, g: u32) -> [u8; 8] {
    let bytes: &[u8; 64] = bytemuck::cast_ref(c);
    let g = (g % 8) as usize;
    // Byte g of a plane holds pixels 8g..8g + 8 in memory order on a
    // little-endian target, from the other end on a big-endian one.
    let at = if cfg!(target_endian = "little") {
        g
    } else {
        7 - g
    };
    spread(bytes, at, cfg!(target_pointer_width = "32"))
}

/// Bits of a native word: loops over a word's set bits take it in halves
/// of this size on a 32-bit core, where a `u64` bit scan is several
/// instructions.
pub(crate) const WORD: usize = usize::BITS as usize;

/// The runs of set bits of `m` (within a native word, [`WORD`]) whose
/// first bit `i` has `keep(i)`, asked in increasing order: for a mask
/// whose runs each share one answer (a row's pixels of one region), one
/// question per run instead of one per bit.
#[inline(always)]
pub(crate) fn select_runs(m: u64, mut keep: impl FnMut(u32) -> bool) -> u64 {
    let mut out = 0u64;
    for h in 0..64 / WORD {
        let mut x = (m >> (h * WORD)) as usize;
        let mut kept = 0usize;
        while x != 0 {
            let s = x.trailing_zeros();
            // The run's length: the ones from `s` up (all of them when
            // the word is all ones).
            let len = (!(x >> s)).trailing_zeros();
            let run = if len as usize >= WORD {
                usize::MAX
            } else {
                ((1usize << len) - 1) << s
            };
            if keep((h * WORD) as u32 + s) {
                kept |= run;
            }
            x &= !run;
        }
        out |= (kept as u64) << (h * WORD);
    }
    out
}

/// Calls `f(i)` for each set bit `i` of `m`, in increasing order, scanned
/// in native words ([`WORD`]).
#[inline(always)]
pub(crate) fn for_each_bit(m: u64, mut f: impl FnMut(u32)) {
    for h in 0..64 / WORD {
        let mut x = (m >> (h * WORD)) as usize;
        while x != 0 {
            f((h * WORD) as u32 + x.trailing_zeros());
            x &= x - 1;
        }
    }
}

/// The counts of all 64 pixels, one per byte (byte `i` is pixel `i`).
/// On x86-64 an SSE2 transpose (hand-written: no crate transposes bit
/// matrices in `no_std`): three rounds of byte interleaves put each byte
/// group's 8×8 bit block in one `u64` lane (byte `b` from plane `b`), and
/// three rounds of masked swaps transpose each block (Hacker's Delight,
/// 7-3), about 125 instructions for the 64 pixels against about 290 for
/// eight [`bytes8`]. Elsewhere eight [`bytes8`].
#[inline]
pub fn bytes64(c: &Counter) -> [u8; 64] {
    #[cfg(target_arch = "x86_64")]
    {
        use wide::{u64x2, u8x16};
        let pair = |b: usize| -> u8x16 { bytemuck::cast(u64x2::new([c[b], c[b + 1]])) };
        let (x0, x2, x4, x6) = (pair(0), pair(2), pair(4), pair(6));
        // Byte g of the lanes below: (plane, plane) pairs, then quads.
        let (p04, p15) = (u8x16::unpack_low(x0, x4), u8x16::unpack_high(x0, x4));
        let (p26, p37) = (u8x16::unpack_low(x2, x6), u8x16::unpack_high(x2, x6));
        let (e_lo, e_hi) = (u8x16::unpack_low(p04, p26), u8x16::unpack_high(p04, p26));
        let (o_lo, o_hi) = (u8x16::unpack_low(p15, p37), u8x16::unpack_high(p15, p37));
        let blocks = [
            u8x16::unpack_low(e_lo, o_lo),
            u8x16::unpack_high(e_lo, o_lo),
            u8x16::unpack_low(e_hi, o_hi),
            u8x16::unpack_high(e_hi, o_hi),
        ];
        let mut out = [u64x2::ZERO; 4];
        for (o, q) in out.iter_mut().zip(blocks) {
            let mut x: u64x2 = bytemuck::cast(q);
            for (s, m) in [
                (7, 0x00AA_00AA_00AA_00AA_u64),
                (14, 0x0000_CCCC_0000_CCCC),
                (28, 0x0000_0000_F0F0_F0F0),
            ] {
                let t = (x ^ (x >> s)) & u64x2::splat(m);
                x = x ^ t ^ (t << s);
            }
            *o = x;
        }
        bytemuck::cast(out)
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let mut out = [0u8; 64];
        for (g, o) in out.chunks_exact_mut(8).enumerate() {
            o.copy_from_slice(&bytes8(c, g as u32));
        }
        out
    }
}

/// [`bytes8`]'s gather of byte `at` of each plane (`bytes`: the planes'
/// bytes in memory order). `halves`: in two `u32`s — a byte of SPREAD is
/// 0 or 1, so a shift by b < 8 never carries out of it and the halves
/// shift apart, one 32-bit operation each (a `u64` shift is three on a
/// 32-bit target; on a 64-bit one the split is the slower).
#[inline(always)]
fn spread(bytes: &[u8; 64], at: usize, halves: bool) -> [u8; 8] {
    if halves {
        let (mut lo, mut hi) = (0u32, 0u32);
        for b in 0..8 {
            let s = SPREAD[usize::from(bytes[8 * b + at])];
            lo |= (s as u32) << b;
            hi |= ((s >> 32) as u32) << b;
        }
        return (u64::from(hi) << 32 | u64::from(lo)).to_le_bytes();
    }
    let mut v = 0u64;
    for b in 0..8 {
        v |= SPREAD[usize::from(bytes[8 * b + at])] << b;
    }
    v.to_le_bytes()
}

/// The counts of a counter's pixels asked in increasing order, read out
/// of the bit planes a byte group (8 px, [`bytes8`]) at a time.
pub(crate) struct Groups<'a> {
    c: &'a Counter,
    group: u32,
    bytes: [u8; 8],
}

impl<'a> Groups<'a> {
    pub(crate) fn new(c: &'a Counter) -> Groups<'a> {
        Groups {
            c,
            group: u32::MAX,
            bytes: [0; 8],
        }
    }

    /// The count of pixel `i` (0..64).
    #[inline]
    pub(crate) fn count(&mut self, i: u32) -> u8 {
        if self.group != i / 8 {
            self.group = i / 8;
            self.bytes = bytes8(self.c, i / 8);
        }
        self.bytes[(i % 8) as usize]
    }
}

/// The sum over the 64 pixels of their squared counts, from the bit
/// planes: `c² = Σ_a 4^a·c_a + Σ_{a<b} 2^(a+b+1)·c_a·c_b`, so the sum is
/// popcounts of the planes and of their pairwise ANDs (planes above the
/// highest non-zero one skipped). Exact: at most 64·255² < 2^22.
#[inline]
pub fn sum_squares(c: &Counter) -> u64 {
    let top = c.iter().rposition(|&p| p != 0).map_or(0, |t| t + 1);
    let mut sum = 0u64;
    for a in 0..top {
        let pa = c[a];
        if pa == 0 {
            continue;
        }
        sum += u64::from(pa.count_ones()) << (2 * a);
        for (b, &pb) in c.iter().enumerate().take(top).skip(a + 1) {
            sum += u64::from((pa & pb).count_ones()) << (a + b + 1);
        }
    }
    sum
}

/// Bit `i` set where `i < n` (0..=64).
#[inline]
pub fn low_bits(n: usize) -> u64 {
    if n >= 64 {
        u64::MAX
    } else {
        (1u64 << n) - 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs selected by their first bit equal bits selected one by one
    /// when every run shares one answer: random masks (runs of every
    /// length, across the halves' boundary, a word all ones) with a
    /// random answer per run.
    #[test]
    fn runs_select_like_their_bits() {
        let mut rnd = crate::testing::rng(0x2545_f491_4f6c_dd1d);
        let mut masks: std::vec::Vec<u64> = (0..2000)
            .map(|i| match i % 4 {
                0 => rnd(u64::MAX),
                1 => rnd(u64::MAX) & rnd(u64::MAX),
                2 => rnd(u64::MAX) | rnd(u64::MAX),
                _ => low_bits(rnd(65) as usize) << rnd(64),
            })
            .collect();
        masks.extend([
            0,
            u64::MAX,
            1,
            1 << 63,
            0xffff_ffff_0000_0000,
            0x0000_0001_8000_0000,
        ]);
        for m in masks {
            // A run's answer: a label per bit, the same along each run.
            let mut label = [0u64; 64];
            let mut cur = rnd(u64::MAX);
            for (i, l) in label.iter_mut().enumerate() {
                if i == 0 || (m >> (i - 1)) & 1 == 0 {
                    cur = rnd(2);
                }
                *l = cur;
            }
            let mut asked = 0u32;
            let got = select_runs(m, |i| {
                asked += 1;
                label[i as usize] == 1
            });
            let want = (0..64).fold(0u64, |w, i| {
                w | (u64::from((m >> i) & 1 == 1 && label[i] == 1) << i)
            });
            assert_eq!(got, want, "{m:#x}");
            // One question per run (a run across the halves is two on a
            // 32-bit core).
            let runs = (m & !(m << 1)).count_ones();
            assert!(
                asked >= runs && asked <= runs + 1,
                "{m:#x}: {asked} for {runs}"
            );
        }
    }

    #[test]
    fn a_whole_counter_reads_back_pixel_by_pixel() {
        // Random planes (xorshift), then planes with one bit, one pixel,
        // all ones: each pixel's byte is its count read bit by bit.
        let mut rnd = crate::testing::rng(0x9E37_79B9_7F4A_7C15);
        let mut cases: [Counter; 300] =
            core::array::from_fn(|_| core::array::from_fn(|_| rnd(u64::MAX)));
        for (k, c) in cases.iter_mut().enumerate().take(64) {
            *c = [0; 8];
            c[k % 8] = 1 << k;
        }
        cases[64] = [u64::MAX; 8];
        for c in &cases {
            let all = bytes64(c);
            for i in 0..64u32 {
                let want: u8 = (0..8).map(|b| (((c[b] >> i) & 1) as u8) << b).sum();
                assert_eq!(all[i as usize], want, "pixel {i} of {c:x?}");
            }
        }
    }

    #[test]
    fn counts_compare_and_read_back() {
        // Pixel i fires at ticks t where (t * (i + 1)) % 7 < 3, 200 ticks.
        let words: [u64; 200] = core::array::from_fn(|t| {
            let mut w = 0u64;
            for i in 0..64u64 {
                if (t as u64 * (i + 1)) % 7 < 3 {
                    w |= 1 << i;
                }
            }
            w
        });
        let mut c = Counter::default();
        add(&mut c, &words[..37], |w| w);
        add(&mut c, &words[37..], |w| w);
        for i in 0..64u32 {
            let want = words.iter().filter(|&&w| (w >> i) & 1 == 1).count() as u8;
            assert_eq!(count(&c, i), want);
            assert_eq!(bytes8(&c, i / 8)[(i % 8) as usize], want);
            assert_eq!(bytes64(&c)[i as usize], want);
            // Both gathers, whichever this target uses.
            let at = if cfg!(target_endian = "little") {
                i / 8
            } else {
                7 - i / 8
            } as usize;
            for halves in [false, true] {
                let got = spread(bytemuck::cast_ref(&c), at, halves);
                assert_eq!(got[(i % 8) as usize], want, "{i} {halves}");
            }
            for t in [
                0u32, 1, 2, 4, 8, 16, 32, 64, 85, 86, 87, 128, 199, 200, 255, 256,
            ] {
                assert_eq!(
                    (at_least(&c, t) >> i) & 1 == 1,
                    u32::from(want) >= t,
                    "{i} {t}"
                );
            }
        }
        // Counters of the first n words hold counts of at most n: only
        // their live planes are read, and the answers stay exact.
        for n in [0usize, 1, 2, 3, 5, 7, 15, 16, 37, 127, 128, 200] {
            let mut c = Counter::default();
            add(&mut c, &words[..n], |w| w);
            let live = live_planes(n as u32);
            assert!(c[live.min(8)..].iter().all(|&p| p == 0), "{n}");
            for t in 0u32..=257 {
                let got = at_least_live(&c, t, live);
                for i in 0..64u32 {
                    let want = words[..n].iter().filter(|&&w| (w >> i) & 1 == 1).count();
                    assert_eq!((got >> i) & 1 == 1, want >= t as usize, "{n} {t} {i}");
                }
            }
        }
        // Pairs through the full adder, the odd one through `csa`.
        for n in [0usize, 1, 2, 7, 14, 15] {
            let mut s = [0u64; 4];
            for pr in words[..n].chunks(2) {
                match *pr {
                    [x, y] => csa2(&mut s, x, y),
                    [x] => csa(&mut s, x),
                    _ => {}
                }
            }
            let mut c = Counter::default();
            add_nibble(&mut c, s);
            for i in 0..64u32 {
                let want = words[..n].iter().filter(|&&w| (w >> i) & 1 == 1).count();
                assert_eq!(usize::from(count(&c, i)), want, "{n} {i}");
            }
        }
        let squares: u64 = (0..64).map(|i| u64::from(count(&c, i)).pow(2)).sum();
        assert_eq!(sum_squares(&c), squares);
        assert_eq!(sum_squares(&Counter::default()), 0);
        assert_eq!(sum_squares(&[u64::MAX; 8]), 64 * 255 * 255);
    }
}
