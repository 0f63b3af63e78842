//! The zlib streams of compressed frames: the blocks of a `.vtu` (`vtu.rs`) and the chunks of
//! `solution.vtkhdf` (`vtkhdf.rs`), each one zlib stream (RFC 1950) that any inflater reads.
//!
//! # What there is to compress, and why this module encodes it itself
//!
//! A frame's values are doubles whose bytes are close to random, except exact zeros: the z
//! components of vectors in 2D, the out-of-plane stress components, the contact fields away
//! from Γ3. Those zero runs are all that deflate finds in them. zlib-rs at level 1 (its
//! fastest, `deflate_quick`: fixed Huffman codes and a hash search for matches) spends its
//! time hashing bytes that never match: on the fields of an h = 1/128 frame of
//! examples/paper.toml (3.03 MB) it took 10.4 ms (290 MB/s) for 55.6% of the size, slower
//! than the time loop's step, so a run writing every step waited for its writer thread.
//! zlib-rs's RLE strategy took 18 ms (54.5%), Huffman-only 23 ms (60.5%); fdeflate (the PNG
//! encoder of image-rs, fixed tables tuned for filtered pixels) took 2.9 ms but wrote 78.9%
//! (9–10 bits for a byte ≥ 128).
//!
//! This encoder keeps the zero runs and drops the search: one fixed-Huffman block (RFC 1951
//! §3.2.6) where every byte is a literal, except a run of r ≥ 4 zero bytes, which is one
//! literal 0 followed by matches at distance 1 covering the other r − 1 (≤ 258 bytes a
//! match). A zero double between non-zero ones costs 20 bits instead of 64; a block of zeros
//! about 13 bits per 258 bytes. Eight bytes without a zero (most of a double's words) go out
//! through the literal table three at a time, without a branch. A stream that would not shrink (von Mises
//! stress, say: literals ≥ 144 take 9 bits) is written as stored blocks instead, so
//! compression never grows a frame by more than the few bytes of the headers. On the same
//! fields: 3.2 ms (950 MB/s) for 62.8% of the size — the 7 points zlib gains come from
//! matching the leading bytes of neighbouring values of smooth fields, which is the search
//! that costs it three times the time.
//!
//! Measured by examples/bench_output.rs on the last frame of its run (figures in the README's
//! output section).

use std::io::Write as _;

/// Bits of the fixed literal/length code (RFC 1951 §3.2.6), reversed (deflate packs Huffman
/// codes from their most significant bit, into a stream read from the least significant bit
/// of each byte), and their lengths.
const fn fixed_code(symbol: u32) -> (u32, u32) {
    let (code, len) = match symbol {
        0..=143 => (0x30 + symbol, 8),
        144..=255 => (0x190 + symbol - 144, 9),
        256..=279 => (symbol - 256, 7),
        _ => (0xc0 + symbol - 280, 8),
    };
    (code.reverse_bits() >> (32 - len), len)
}

/// The literal codes: `code | len << 16`, one table lookup per byte.
const LITERALS: [u32; 256] = {
    let mut t = [0; 256];
    let mut b = 0;
    while b < 256 {
        let (code, len) = fixed_code(b as u32);
        t[b] = code | len << 16;
        b += 1;
    }
    t
};

/// The bits of a match of length 3..=258 at distance 1, index length − 3: the length's
/// symbol code, its extra bits (the length above the symbol's base) and the 5-bit distance
/// code 0, as `bits | count << 32`.
const MATCHES: [u64; 256] = {
    // (first length, extra bits) of symbols 257..=284; 285 is length 258 alone.
    const BASE: [(u32, u32); 28] = [
        (3, 0),
        (4, 0),
        (5, 0),
        (6, 0),
        (7, 0),
        (8, 0),
        (9, 0),
        (10, 0),
        (11, 1),
        (13, 1),
        (15, 1),
        (17, 1),
        (19, 2),
        (23, 2),
        (27, 2),
        (31, 2),
        (35, 3),
        (43, 3),
        (51, 3),
        (59, 3),
        (67, 4),
        (83, 4),
        (99, 4),
        (115, 4),
        (131, 5),
        (163, 5),
        (195, 5),
        (227, 5),
    ];
    let mut t = [0; 256];
    let mut len = 3;
    while len <= 258 {
        let (symbol, base, extra) = if len == 258 {
            (285, 258, 0)
        } else {
            let mut s = 27;
            while BASE[s].0 > len {
                s -= 1;
            }
            (257 + s as u32, BASE[s].0, BASE[s].1)
        };
        let (code, n) = fixed_code(symbol);
        let bits = code as u64 | ((len - base) as u64) << n;
        // The distance code 0 (distance 1) is five zero bits.
        t[len as usize - 3] = bits | ((n + extra + 5) as u64) << 32;
        len += 1;
    }
    t
};

/// Bytes of zlib header: deflate with a 32 KiB window, "fastest" level, no dictionary.
const HEADER: [u8; 2] = [0x78, 0x01];

/// The bits of a deflate stream under construction, written without a branch: every put
/// stores the whole 64-bit accumulator at the current byte and moves on by the bytes it
/// completed, keeping at most 7 bits (`out` holds 8 bytes of slack past any position).
struct Bits<'a> {
    out: &'a mut [u8],
    pos: usize,
    acc: u64,
    n: u32,
}

impl Bits<'_> {
    /// Appends the `count` ≤ 56 low bits of `bits`.
    #[inline(always)]
    fn put(&mut self, bits: u64, count: u32) {
        self.acc |= bits << self.n;
        self.n += count;
        self.out[self.pos..self.pos + 8].copy_from_slice(&self.acc.to_le_bytes());
        let bytes = self.n / 8;
        self.pos += bytes as usize;
        self.acc >>= 8 * bytes;
        self.n %= 8;
    }

    /// Up to six literals (at most 54 bits) in one put.
    #[inline(always)]
    fn literals<const N: usize>(&mut self, b: [u8; N]) {
        let mut bits = 0u64;
        let mut count = 0;
        for byte in b {
            let c = LITERALS[byte as usize];
            bits |= ((c & 0xffff) as u64) << count;
            count += c >> 16;
        }
        self.put(bits, count);
    }

    /// `r` more copies of the byte before (r ≥ 3), as matches at distance 1.
    fn repeat(&mut self, mut r: usize) {
        while r > 0 {
            // A match is 3..=258 long: never leave a tail of 1 or 2.
            let mut take = r.min(258);
            if (1..3).contains(&(r - take)) {
                take = r - 3;
            }
            let m = MATCHES[take - 3];
            self.put(m & 0xffff_ffff, (m >> 32) as u32);
            r -= take;
        }
    }

    /// The end-of-block symbol 256, padded to a byte boundary: the stream's length in bytes.
    fn finish(mut self) -> usize {
        let (code, len) = fixed_code(256);
        self.put(code as u64, len);
        self.pos + self.n.div_ceil(8) as usize
    }
}

/// Appends one zlib stream of `data` to `out` (public for examples/bench_output.rs).
pub fn compress(data: &[u8], out: &mut Vec<u8>) {
    let start = out.len();
    // The stream is stored if it would be longer than this; slack for the puts past it (an
    // iteration adds at most 9 bytes, a put stores 8).
    let limit = stored_size(data.len());
    out.resize(start + limit + 32, 0);
    out[start..start + 2].copy_from_slice(&HEADER);
    let mut bits = Bits {
        out: &mut out[start + 2..],
        pos: 0,
        acc: 0,
        n: 0,
    };
    // BFINAL = 1, BTYPE = 01 (fixed Huffman codes).
    bits.put(0b011, 3);
    let mut i = 0;
    while i < data.len() && bits.pos <= limit {
        if let Some(w) = word(data, i) {
            let zeros = zero_bytes(w);
            if zeros == 0 {
                let [a, b, c, d, e, f, g, h] = w.to_le_bytes();
                bits.literals([a, b, c, d]);
                bits.literals([e, f, g, h]);
                i += 8;
                continue;
            }
            // The bytes before the word's first zero.
            let first = (zeros.trailing_zeros() / 8) as usize;
            for &b in &data[i..i + first] {
                bits.literals([b]);
            }
            i += first;
        }
        let b = data[i];
        i += 1;
        bits.literals([b]);
        if b == 0 {
            let run = zero_run(&data[i..]);
            if run >= 3 {
                bits.repeat(run);
            } else {
                for _ in 0..run {
                    bits.literals([0]);
                }
            }
            i += run;
        }
    }
    let len = 2 + bits.finish();
    if i < data.len() || len + 4 > limit {
        out.truncate(start);
        store(data, out);
    } else {
        out.truncate(start + len);
        out.extend_from_slice(&zlib_rs::adler32::adler32(1, data).to_be_bytes());
    }
}

/// Appends one zlib stream of `data` compressed by zlib itself (flate2, level 6): for what
/// is compressed once and written many times — the mesh of every `.vtu` frame, where the
/// search pays (points and connectivity shrink to 11–15% with it, to about 45% here).
pub(super) fn compress_once(data: &[u8], out: &mut Vec<u8>) {
    let mut z = flate2::write::ZlibEncoder::new(out, flate2::Compression::default());
    z.write_all(data).expect("writing to memory cannot fail");
    z.finish().expect("writing to memory cannot fail");
}

/// The 8 bytes of `data` at `i`, little-endian, if there are 8.
#[inline(always)]
fn word(data: &[u8], i: usize) -> Option<u64> {
    let bytes = data.get(i..i + 8)?;
    Some(u64::from_le_bytes(bytes.try_into().expect("8 bytes")))
}

/// The high bit of every zero byte of `w` set, others clear, except that bits above the
/// first zero byte may be set too (the classic bit trick: the lowest set bit is exact).
#[inline(always)]
fn zero_bytes(w: u64) -> u64 {
    const LO: u64 = 0x0101_0101_0101_0101;
    const HI: u64 = 0x8080_8080_8080_8080;
    w.wrapping_sub(LO) & !w & HI
}

/// The number of leading zero bytes of `data`, a word at a time.
#[inline(always)]
fn zero_run(data: &[u8]) -> usize {
    let mut r = 0;
    while let Some(w) = word(data, r) {
        if w != 0 {
            return r + (w.trailing_zeros() / 8) as usize;
        }
        r += 8;
    }
    r + data[r..].iter().take_while(|&&x| x == 0).count()
}

/// Bytes of a zlib stream of `n` bytes in stored blocks.
fn stored_size(n: usize) -> usize {
    HEADER.len() + 5 * n.div_ceil(STORED).max(1) + n + 4
}

/// Most bytes of a stored block.
const STORED: usize = 65535;

/// Appends `data` as a zlib stream of stored blocks (RFC 1951 §3.2.4).
fn store(data: &[u8], out: &mut Vec<u8>) {
    out.extend_from_slice(&HEADER);
    let blocks = data.len().div_ceil(STORED).max(1);
    for b in 0..blocks {
        let block = &data[(b * STORED).min(data.len())..((b + 1) * STORED).min(data.len())];
        let last = u8::from(b + 1 == blocks);
        out.push(last); // BFINAL, BTYPE = 00, padded to the byte
        let len = block.len() as u16;
        out.extend_from_slice(&len.to_le_bytes());
        out.extend_from_slice(&(!len).to_le_bytes());
        out.extend_from_slice(block);
    }
    out.extend_from_slice(&zlib_rs::adler32::adler32(1, data).to_be_bytes());
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::io::Read;

    fn inflate(z: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        flate2::read::ZlibDecoder::new(z)
            .read_to_end(&mut out)
            .expect("a valid zlib stream");
        out
    }

    /// splitmix64's output function: bits without repeats.
    fn mix(i: u64) -> u64 {
        let mut z = i.wrapping_mul(0x9e37_79b9_7f4a_7c15);
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        (z ^ (z >> 31)) | 0x0101_0101_0101_0101
    }

    fn round_trip(data: &[u8]) -> usize {
        let mut z = vec![7, 7]; // compress appends
        compress(data, &mut z);
        assert_eq!(inflate(&z[2..]), data);
        z.len() - 2
    }

    #[test]
    fn zero_runs_of_every_length_round_trip() {
        for run in 0..600 {
            for lead in [&[][..], &[1u8][..], &[0u8, 5][..]] {
                let mut data = lead.to_vec();
                data.extend(std::iter::repeat_n(0u8, run));
                data.extend([9u8, 0, 0, 3]);
                round_trip(&data);
            }
        }
    }

    #[test]
    fn zeros_shrink_and_random_bytes_are_stored() {
        assert!(round_trip(&[0; 1 << 16]) < 600);
        // Header, 3 + 7 bits (block header, end of block), Adler-32.
        assert_eq!(round_trip(&[]), 2 + 2 + 4);
        // Bytes without repeats do not shrink: stored, at most 5 bytes a block more.
        let noise: Vec<u8> = (0..25_000).flat_map(|i| mix(i).to_le_bytes()).collect();
        assert_eq!(round_trip(&noise), stored_size(noise.len()));
    }

    #[test]
    fn zero_components_compress_about_as_with_zlib_level_1() {
        // 2-D vectors as a frame holds them: x, y, 0, with random bits in x and y (where
        // zlib finds nothing but the zeros either; on smooth fields it also matches the
        // leading bytes of neighbours: 12% smaller on a real frame, see the module doc).
        let values: Vec<f64> = (0..30_000u64)
            .map(|i| match i % 3 {
                2 => 0.0,
                _ => f64::from_bits(mix(i)),
            })
            .collect();
        let raw: Vec<u8> = values.iter().flat_map(|x| x.to_le_bytes()).collect();
        let ours = round_trip(&raw);
        let mut zlib = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
        std::io::Write::write_all(&mut zlib, &raw).unwrap();
        let reference = zlib.finish().unwrap().len();
        assert!(
            // zlib codes a zero word as a match at distance 24 (the word before), here it is
            // a literal 0 and a match at distance 1: 5 bits more a word, 2.6% here.
            (ours as f64) < 1.06 * reference as f64,
            "{ours} bytes against zlib level 1's {reference}"
        );
        // 16 literal bytes (8.5 bits on average) and 20 bits for the zero: 0.81 of the raw size.
        assert!(ours < raw.len() * 83 / 100, "{ours} of {}", raw.len());
    }

    proptest! {
        #[test]
        fn any_bytes_round_trip(
            parts in proptest::collection::vec((any::<u8>(), 0usize..300), 0..60)
        ) {
            let data: Vec<u8> = parts
                .iter()
                .flat_map(|&(b, n)| std::iter::repeat_n(b % 3, n % 7).chain(std::iter::repeat_n(0, n)))
                .collect();
            round_trip(&data);
        }
    }
}
