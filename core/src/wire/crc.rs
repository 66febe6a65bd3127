//! The link's CRC-32/ISO-HDLC (zlib's `crc32`): of each message's header
//! and payload, and of each frame's samples ([`super::frame_crc`]).
//!
//! On 64-bit hosts the `crc32fast` crate: with the `std` feature it picks
//! the carry-less-multiply (PCLMULQDQ) folding at run time where the CPU
//! has it, else slice-by-16 tables, several times cheaper per byte than
//! the `crc` crate's tables, which were a fifth of the firmware
//! simulator's sending. On 32-bit MCUs the `crc` crate's one 1 KiB table: the Cortex-M4 sends
//! in the same count with slice-by-16 (measured with
//! `firmware-sim/cost.sh`) and the flash is better kept. Both compute the
//! same function, tested against zlib's check value.

/// A CRC-32/ISO-HDLC computed over bytes given in any number of parts.
#[derive(Clone)]
pub struct Crc32(Inner);

#[cfg(target_pointer_width = "64")]
type Inner = crc32fast::Hasher;

#[cfg(not(target_pointer_width = "64"))]
type Inner = crc::Digest<'static, u32>;

#[cfg(not(target_pointer_width = "64"))]
static TABLE: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

impl Crc32 {
    /// The CRC of no bytes yet.
    pub fn new() -> Self {
        #[cfg(target_pointer_width = "64")]
        return Crc32(crc32fast::Hasher::new());
        #[cfg(not(target_pointer_width = "64"))]
        return Crc32(TABLE.digest());
    }

    /// Adds `bytes` after those given so far.
    #[inline]
    pub fn update(&mut self, bytes: &[u8]) {
        self.0.update(bytes);
    }

    /// The CRC of all the bytes given.
    pub fn finalize(self) -> u32 {
        self.0.finalize()
    }
}

impl core::fmt::Debug for Crc32 {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("Crc32")
    }
}

impl Default for Crc32 {
    fn default() -> Self {
        Crc32::new()
    }
}

/// The CRC-32/ISO-HDLC of `bytes`.
///
/// ```
/// assert_eq!(spiv_core::wire::crc32(b"123456789"), 0xCBF4_3926);
/// ```
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut d = Crc32::new();
    d.update(bytes);
    d.finalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// zlib's check value, and the same CRC however the bytes are split.
    #[test]
    fn is_zlibs_crc_in_any_parts() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
        // Long enough for the folding path (it takes 64 bytes and more).
        let bytes: [u8; 1000] = core::array::from_fn(|i| (i * 31 + i / 7) as u8);
        let reference = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&bytes);
        assert_eq!(crc32(&bytes), reference);
        for cut in [0, 1, 15, 64, 513, 999, 1000] {
            let mut d = Crc32::new();
            d.update(&bytes[..cut]);
            d.update(&bytes[cut..]);
            assert_eq!(d.finalize(), reference);
        }
    }
}
