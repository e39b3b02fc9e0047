//! MD5 (RFC 1321), only for the checksums ISO 25178-72 requires in an X3P container
//! (`MD5ChecksumPointData` and `md5checksum.hex`). Not used for anything security related. The digest is
//! RustCrypto's `md-5`; this module gives it the two forms the X3P code uses.

use ::md5::Digest;

/// Incremental MD5.
#[derive(Debug, Clone, Default)]
pub struct Md5(::md5::Md5);

impl Md5 {
    /// Feed bytes.
    pub fn update(&mut self, data: &[u8]) {
        self.0.update(data);
    }

    /// The 16-byte digest.
    pub fn finish(self) -> [u8; 16] {
        self.0.finalize().into()
    }
}

/// Lower-case hex MD5 of `data`.
pub fn md5_hex(data: &[u8]) -> String {
    let mut h = Md5::default();
    h.update(data);
    h.finish().iter().map(|b| format!("{b:02x}")).collect()
}

#[cfg(test)]
mod tests {
    use super::md5_hex;

    /// The test suite of RFC 1321 appendix A.5 (an independent source).
    #[test]
    fn rfc1321_vectors() {
        let cases = [
            ("", "d41d8cd98f00b204e9800998ecf8427e"),
            ("a", "0cc175b9c0f1b6a831c399e269772661"),
            ("abc", "900150983cd24fb0d6963f7d28e17f72"),
            ("message digest", "f96b697d7cb7938d525a2f31aaf161d0"),
            ("abcdefghijklmnopqrstuvwxyz", "c3fcd3d76192e4007dfb496cca67e13b"),
            ("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789", "d174ab98d277d9f5a5611c2c9f419d9f"),
            ("12345678901234567890123456789012345678901234567890123456789012345678901234567890", "57edf4a22be3c955ac49da2e2107b67a"),
        ];
        for (input, want) in cases {
            assert_eq!(md5_hex(input.as_bytes()), want, "md5({input:?})");
        }
    }

    /// Many blocks fed in uneven pieces: a million `a` and a byte pattern, against the digests Python's
    /// `hashlib.md5` gives for the same bytes.
    #[test]
    fn long_inputs_in_pieces() {
        let a = vec![b'a'; 1_000_000];
        let mut h = super::Md5::default();
        for piece in a.chunks(777) {
            h.update(piece);
        }
        let got: String = h.finish().iter().map(|b| format!("{b:02x}")).collect();
        assert_eq!(got, "7707d6ae4e027c70eea2a935c2296f21");
        let pattern: Vec<u8> = (0..300_000u32).map(|k| (k.wrapping_mul(2_654_435_761) >> 13) as u8).collect();
        assert_eq!(md5_hex(&pattern), "384d43b457e4391d851b65dec6507b1e");
    }
}
