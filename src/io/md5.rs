//! MD5 (RFC 1321), only for the checksums ISO 25178-72 requires in an X3P container
//! (`MD5ChecksumPointData` and `md5checksum.hex`). Not used for anything security related.

/// RFC 1321 section 3.4: `K[i] = floor(2^32 |sin(i + 1)|)` (checked by `k_is_the_sine_table`).
const K: [u32; 64] = [
    0xd76aa478, 0xe8c7b756, 0x242070db, 0xc1bdceee, 0xf57c0faf, 0x4787c62a, 0xa8304613, 0xfd469501, 0x698098d8, 0x8b44f7af, 0xffff5bb1,
    0x895cd7be, 0x6b901122, 0xfd987193, 0xa679438e, 0x49b40821, 0xf61e2562, 0xc040b340, 0x265e5a51, 0xe9b6c7aa, 0xd62f105d, 0x02441453,
    0xd8a1e681, 0xe7d3fbc8, 0x21e1cde6, 0xc33707d6, 0xf4d50d87, 0x455a14ed, 0xa9e3e905, 0xfcefa3f8, 0x676f02d9, 0x8d2a4c8a, 0xfffa3942,
    0x8771f681, 0x6d9d6122, 0xfde5380c, 0xa4beea44, 0x4bdecfa9, 0xf6bb4b60, 0xbebfbc70, 0x289b7ec6, 0xeaa127fa, 0xd4ef3085, 0x04881d05,
    0xd9d4d039, 0xe6db99e5, 0x1fa27cf8, 0xc4ac5665, 0xf4292244, 0x432aff97, 0xab9423a7, 0xfc93a039, 0x655b59c3, 0x8f0ccc92, 0xffeff47d,
    0x85845dd1, 0x6fa87e4f, 0xfe2ce6e0, 0xa3014314, 0x4e0811a1, 0xf7537e82, 0xbd3af235, 0x2ad7d2bb, 0xeb86d391,
];
/// Incremental MD5.
#[derive(Debug, Clone)]
pub struct Md5 {
    state: [u32; 4],
    buf: [u8; 64],
    buf_len: usize,
    total: u64,
}

impl Default for Md5 {
    fn default() -> Self {
        Md5 { state: [0x6745_2301, 0xefcd_ab89, 0x98ba_dcfe, 0x1032_5476], buf: [0; 64], buf_len: 0, total: 0 }
    }
}

impl Md5 {
    /// Feed bytes.
    pub fn update(&mut self, mut data: &[u8]) {
        self.total = self.total.wrapping_add(data.len() as u64);
        if self.buf_len > 0 {
            let n = (64 - self.buf_len).min(data.len());
            self.buf[self.buf_len..self.buf_len + n].copy_from_slice(&data[..n]);
            self.buf_len += n;
            data = &data[n..];
            if self.buf_len == 64 {
                let block = self.buf;
                self.block(&block);
                self.buf_len = 0;
            }
        }
        while data.len() >= 64 {
            let (b, rest) = data.split_at(64);
            let mut block = [0u8; 64];
            block.copy_from_slice(b);
            self.block(&block);
            data = rest;
        }
        self.buf[..data.len()].copy_from_slice(data);
        self.buf_len += data.len();
    }

    /// The 16-byte digest.
    pub fn finish(mut self) -> [u8; 16] {
        let bits = self.total.wrapping_mul(8);
        let mut pad = vec![0x80u8];
        let padlen = if self.buf_len < 56 { 55 - self.buf_len } else { 119 - self.buf_len };
        pad.extend(std::iter::repeat_n(0u8, padlen));
        pad.extend_from_slice(&bits.to_le_bytes());
        let total = self.total;
        self.update(&pad);
        self.total = total;
        let mut out = [0u8; 16];
        for (i, w) in self.state.iter().enumerate() {
            out[i * 4..i * 4 + 4].copy_from_slice(&w.to_le_bytes());
        }
        out
    }

    /// One 64-byte block (RFC 1321 section 3.4), unrolled so that every message index, shift and
    /// constant is known at compile time.
    fn block(&mut self, block: &[u8; 64]) {
        let mut m = [0u32; 16];
        for (i, w) in m.iter_mut().enumerate() {
            *w = u32::from_le_bytes([block[i * 4], block[i * 4 + 1], block[i * 4 + 2], block[i * 4 + 3]]);
        }
        let [mut a, mut b, mut c, mut d] = self.state;
        // The four auxiliary functions F, G, H, I of section 3.4 (F and G in their xor forms).
        let f = |b: u32, c: u32, d: u32| d ^ (b & (c ^ d));
        let g = |b: u32, c: u32, d: u32| c ^ (d & (b ^ c));
        let h = |b: u32, c: u32, d: u32| b ^ c ^ d;
        let i = |b: u32, c: u32, d: u32| c ^ (b | !d);
        macro_rules! step {
            ($fn:expr, $a:ident, $b:ident, $c:ident, $d:ident, $k:expr, $g:expr, $s:expr) => {
                $a = $b.wrapping_add($fn($b, $c, $d).wrapping_add($a).wrapping_add(K[$k]).wrapping_add(m[$g]).rotate_left($s));
            };
        }
        // Four steps from step `k`; the message word of step `k` is `(mul k + add) mod 16`.
        macro_rules! four {
            ($fn:expr, $k:expr, $mul:expr, $add:expr, $s:expr) => {
                step!($fn, a, b, c, d, $k, ($mul * $k + $add) % 16, $s[0]);
                step!($fn, d, a, b, c, $k + 1, ($mul * ($k + 1) + $add) % 16, $s[1]);
                step!($fn, c, d, a, b, $k + 2, ($mul * ($k + 2) + $add) % 16, $s[2]);
                step!($fn, b, c, d, a, $k + 3, ($mul * ($k + 3) + $add) % 16, $s[3]);
            };
        }
        const S1: [u32; 4] = [7, 12, 17, 22];
        const S2: [u32; 4] = [5, 9, 14, 20];
        const S3: [u32; 4] = [4, 11, 16, 23];
        const S4: [u32; 4] = [6, 10, 15, 21];
        four!(f, 0, 1, 0, S1);
        four!(f, 4, 1, 0, S1);
        four!(f, 8, 1, 0, S1);
        four!(f, 12, 1, 0, S1);
        four!(g, 16, 5, 1, S2);
        four!(g, 20, 5, 1, S2);
        four!(g, 24, 5, 1, S2);
        four!(g, 28, 5, 1, S2);
        four!(h, 32, 3, 5, S3);
        four!(h, 36, 3, 5, S3);
        four!(h, 40, 3, 5, S3);
        four!(h, 44, 3, 5, S3);
        four!(i, 48, 7, 0, S4);
        four!(i, 52, 7, 0, S4);
        four!(i, 56, 7, 0, S4);
        four!(i, 60, 7, 0, S4);
        self.state[0] = self.state[0].wrapping_add(a);
        self.state[1] = self.state[1].wrapping_add(b);
        self.state[2] = self.state[2].wrapping_add(c);
        self.state[3] = self.state[3].wrapping_add(d);
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

    /// The table is RFC 1321's `floor(2^32 |sin(i + 1)|)`.
    #[test]
    fn k_is_the_sine_table() {
        for (i, k) in super::K.iter().enumerate() {
            assert_eq!(*k, ((i as f64 + 1.0).sin().abs() * 4_294_967_296.0) as u32, "K[{i}]");
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
