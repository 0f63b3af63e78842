//! The zlib streams of compressed frames: the blocks of a `.vtu` (`vtu.rs`) and the chunks of
//! `solution.vtkhdf` (`vtkhdf.rs`), each one zlib stream (RFC 1950) that any inflater reads.
//!
//! # What there is to compress, and why this module encodes it itself
//!
//! A frame's values are doubles whose bytes are close to random, except exact zeros: the z
//! components of vectors in 2D, the out-of-plane stress components, the contact fields away
//! from Γ3. Those zero runs are all that deflate finds in them. zlib-rs at level 1 (its
//! fastest, `deflate_quick`: fixed Huffman codes and a hash search for matches) spends its
//! time hashing bytes that never match: on a fine frame it was slower than the time loop's
//! step, so a run writing every step waited for its writer thread; its RLE and Huffman-only
//! strategies and fdeflate (the PNG encoder of image-rs) were slower or much larger.
//!
//! This encoder keeps the zero runs and drops the search: one deflate block per stream, every
//! byte a literal, except the zero words — the data are read as 8-byte words, and a run of
//! words that are zero goes out as matches at distance 1 (≤ 258 bytes a match), after a
//! literal 0 unless the byte before is a zero. The block's Huffman code is its own (a
//! dynamic block, the same header in every stream, see `code`): the literals 0..=253 take
//! 8 bits with the code of a byte its own value, so a word without a 254 or 255 — almost
//! every non-zero double — goes out as its bytes with their bits reversed, one store and no
//! table, whatever zero bytes it holds; 254, 255, the end of block and the lengths take 12
//! bits. (The fixed code of RFC 1951 §3.2.6 takes 9 bits for half the bytes, each looked
//! up; runs of zero bytes inside words cost a branch each for a little size, and were
//! slower.) A zero double between non-zero ones costs 21 bits instead of 64; a block of
//! zeros about 14 bits per 258 bytes. A stream that would not shrink (von Mises stress,
//! say) is written as stored blocks instead, so compression never grows a frame by more
//! than the few bytes of the headers. It is about seven times as fast as zlib-rs's fastest
//! level, for 61.0% of the size against 54.5%: the points zlib gains come from matching the
//! leading bytes of neighbouring values of smooth fields, which is the search that costs
//! it the time. Every figure, measured by examples/bench_output.rs: docs/performance.md,
//! "The measurements behind the code's constants", and docs/output.md, "Output of run".

use std::io::Write as _;

/// The literal/length code of every block (a dynamic Huffman code, RFC 1951 §3.2.7, the same
/// in every block): the literals 0..=253 take 8 bits, and canonical codes give literal b the
/// code b itself; the literals 254 and 255, the end of block 256 and the lengths 257..=285
/// take 12 bits (codes 4064..=4095, which complete the code). So a word of eight bytes
/// without a 254 or 255 — almost every non-zero double — is coded as its bytes with each
/// byte's bits reversed (deflate packs a code from its most significant bit into a
/// stream read from the least significant bit of each byte), without a table.
/// Returns the reversed code and its length.
const fn code(symbol: u32) -> (u32, u32) {
    let (code, len) = if symbol < 254 {
        (symbol, 8)
    } else {
        (4064 + symbol - 254, 12)
    };
    (code.reverse_bits() >> (32 - len), len)
}

/// The literal codes: `code | len << 16`, one table lookup per byte.
const LITERALS: [u32; 256] = {
    let mut t = [0; 256];
    let mut b = 0;
    while b < 256 {
        let (code, len) = code(b as u32);
        t[b] = code | len << 16;
        b += 1;
    }
    t
};

/// The bits of a match of length 3..=258 at distance 1, index length − 3: the length's
/// symbol code, its extra bits (the length above the symbol's base) and the distance code
/// 0, as `bits | count << 32`. The distance code has that one symbol, of one bit.
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
        let (code, n) = code(symbol);
        let bits = code as u64 | ((len - base) as u64) << n;
        // The distance code 0 (distance 1) is one zero bit.
        t[len as usize - 3] = bits | ((n + extra + 1) as u64) << 32;
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

    /// Up to four literals (at most 48 bits) in one put.
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

    /// Eight literals, the bytes of `w` (none of them 254 or 255, whose codes are not their
    /// values): each byte's bits reversed, one 8-byte store.
    #[inline(always)]
    fn word(&mut self, w: u64) {
        let r = reverse_bits_in_bytes(w);
        self.acc |= r << self.n;
        self.out[self.pos..self.pos + 8].copy_from_slice(&self.acc.to_le_bytes());
        self.pos += 8;
        // The n bits of r that did not fit (none when n = 0).
        self.acc = (r >> 1) >> (63 - self.n);
    }

    /// The header of a block with the code of [`code`]: BFINAL = 1, BTYPE = 10, then the
    /// code lengths (RFC 1951 §3.2.7), themselves coded with a 2-bit code for the four
    /// symbols used — 1, 8, 12 and 16 ("repeat the previous length 3–6 times").
    fn header(&mut self) {
        // The code-length code: canonical 2-bit codes 00, 01, 10, 11 for the symbols 1, 8,
        // 12, 16 (reversed: 00, 10, 01, 11).
        let cl = |symbol: u32| match symbol {
            1 => 0b00,
            8 => 0b10,
            12 => 0b01,
            _ => 0b11,
        };
        self.put(0b101, 3); // BFINAL, BTYPE = 2
        self.put(29, 5); // HLIT: 286 literal/length codes
        self.put(0, 5); // HDIST: 1 distance code
        self.put(14, 4); // HCLEN: 18 code-length code lengths
                         // In RFC order (16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1): 2 bits
                         // for 16, 8, 12 and 1, none for the others.
        for symbol in [16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1] {
            let len = if matches!(symbol, 1 | 8 | 12 | 16) {
                2
            } else {
                0
            };
            self.put(len, 3);
        }
        // The lengths: 254 × 8, 32 × 12 (literal/length), then 1 (the distance code).
        for (len, count) in [(8, 254), (12, 32), (1, 1)] {
            self.put(cl(len), 2);
            let mut left = count - 1;
            while left >= 3 {
                let r = left.min(6);
                self.put(cl(16) | (r - 3) << 2, 4);
                left -= r;
            }
            for _ in 0..left {
                self.put(cl(len), 2);
            }
        }
    }

    /// `r` zero bytes (none, or r ≥ 8): matches at distance 1 when the byte before is a zero
    /// (`after_zero`), else a literal 0 and matches for the other r − 1.
    #[inline(always)]
    fn zeros(&mut self, r: usize, after_zero: bool) {
        if r == 0 {
            return;
        }
        if after_zero {
            self.repeat(r);
        } else if r <= 3 + MATCHES.len() {
            // The literal 0 (code 0, eight bits) and one match, in one put.
            let m = MATCHES[r - 1 - 3];
            self.put((m & 0xffff_ffff) << 8, 8 + (m >> 32) as u32);
        } else {
            self.literals([0]);
            self.repeat(r - 1);
        }
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
        let (code, len) = code(256);
        self.put(code as u64, len);
        self.pos + self.n.div_ceil(8) as usize
    }
}

/// Appends one zlib stream of `data` to `out` (public for examples/bench_output.rs).
pub fn compress(data: &[u8], out: &mut Vec<u8>) {
    thread_local! {
        /// Where a stream is encoded before it is copied to `out`: zeroed once, where
        /// encoding at the end of `out` zeroed its room first (3 MB a frame at h = 1/128).
        static ROOM: std::cell::RefCell<Vec<u8>> = const { std::cell::RefCell::new(Vec::new()) };
    }
    // The stream is stored if it would be longer than this, which is checked before each
    // non-zero word. Slack for what goes out past it: the word (12 bytes at most), the
    // zeros before it (at most 3 bytes per match of 258), the end of block, a put's store.
    let limit = stored_size(data.len());
    let encoded = ROOM.with_borrow_mut(|room| {
        let need = limit + 64 + data.len() / 64;
        if room.len() < need {
            room.resize(need, 0);
        }
        let len = encode(data, limit, room)?;
        out.extend_from_slice(&room[..len]);
        Some(())
    });
    match encoded {
        Some(()) => out.extend_from_slice(&zlib_rs::adler32::adler32(1, data).to_be_bytes()),
        None => store(data, out),
    }
}

/// The zlib header and deflate block of `data` at the start of `room`: their length, or
/// None if they would take more than `limit` bytes (then the stream is stored).
fn encode(data: &[u8], limit: usize, room: &mut [u8]) -> Option<usize> {
    room[..2].copy_from_slice(&HEADER);
    let mut bits = Bits {
        out: &mut room[2..],
        pos: 0,
        acc: 0,
        n: 0,
    };
    bits.header();
    // Whole zero words wait in `zeros` until the next non-zero word; `after_zero`: the last
    // byte coded is a zero, so a run can go out as matches alone.
    let (mut zeros, mut after_zero) = (0, false);
    let mut words = data.chunks_exact(8);
    for word in words.by_ref() {
        let w = u64::from_le_bytes(word.try_into().expect("8 bytes"));
        if w == 0 {
            zeros += 8;
            continue;
        }
        if bits.pos > limit {
            return None;
        }
        bits.zeros(zeros, after_zero);
        zeros = 0;
        // A byte b ≥ 254 has b | 1 = 255, and !(b | 1) a zero byte.
        if !has_zero_byte(!(w | 0x0101_0101_0101_0101)) {
            bits.word(w);
        } else {
            let [a, b, c, d, e, f, g, h] = w.to_le_bytes();
            bits.literals([a, b, c, d]);
            bits.literals([e, f, g, h]);
        }
        after_zero = w >> 56 == 0;
    }
    let done = bits.pos <= limit;
    bits.zeros(zeros, after_zero);
    for &b in words.remainder() {
        bits.literals([b]);
    }
    let len = 2 + bits.finish();
    (done && len + 4 <= limit).then_some(len)
}

/// Appends one zlib stream of `data` compressed by zlib itself (flate2, level 6): for what
/// is compressed once and written many times — the mesh of every `.vtu` frame, where the
/// search pays (points and connectivity shrink to 11–15% with it, to about 45% here).
pub(super) fn compress_once(data: &[u8], out: &mut Vec<u8>) {
    let mut z = flate2::write::ZlibEncoder::new(out, flate2::Compression::default());
    z.write_all(data).expect("writing to memory cannot fail");
    z.finish().expect("writing to memory cannot fail");
}

/// `w` with the bits of each byte in reverse order.
#[inline(always)]
fn reverse_bits_in_bytes(w: u64) -> u64 {
    let w = (w >> 1 & 0x5555_5555_5555_5555) | (w & 0x5555_5555_5555_5555) << 1;
    let w = (w >> 2 & 0x3333_3333_3333_3333) | (w & 0x3333_3333_3333_3333) << 2;
    (w >> 4 & 0x0f0f_0f0f_0f0f_0f0f) | (w & 0x0f0f_0f0f_0f0f_0f0f) << 4
}

/// Whether a word has a zero byte (the classic bit trick: exact, no false positives).
#[inline(always)]
fn has_zero_byte(w: u64) -> bool {
    const LO: u64 = 0x0101_0101_0101_0101;
    const HI: u64 = 0x8080_8080_8080_8080;
    w.wrapping_sub(LO) & !w & HI != 0
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
        // Nothing: the code's header would be longer than an empty stored block.
        assert_eq!(round_trip(&[]), stored_size(0));
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
            // a literal 0 and a match at distance 1, and its literals take 8.4 bits.
            (ours as f64) < 1.06 * reference as f64,
            "{ours} bytes against zlib level 1's {reference}"
        );
        // 16 literal bytes (8.03 bits on average) and 21 bits for the zero: 0.78 of the raw size.
        assert!(ours < raw.len() * 80 / 100, "{ours} of {}", raw.len());
    }

    #[test]
    fn long_zero_runs_after_an_incompressible_start_stay_in_bounds() {
        // 12-bit literals up to about the stored size, then a third of a block of zeros:
        // the zeros go out after the last check against the stored size.
        for ones in (21_000..22_600).step_by(8) {
            let mut data = vec![255u8; ones];
            data.resize(32_768, 0);
            round_trip(&data);
        }
    }

    #[test]
    fn every_byte_value_in_every_position_round_trips() {
        // Words of one byte value b at position k among non-zero bytes (the word path, the
        // 12-bit literals 254 and 255, zeros inside words), each followed by a zero double
        // so that the stream compresses rather than falling back to stored blocks.
        let mut data = Vec::new();
        for b in 0..=255u8 {
            for k in 0..8 {
                let mut w = [0x5a_u8; 8];
                w[k] = b;
                data.extend(w);
                data.extend([0; 8]);
            }
        }
        assert!(round_trip(&data) < stored_size(data.len()));
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

        #[test]
        fn any_words_between_zero_runs_round_trip(
            parts in proptest::collection::vec((any::<u64>(), 0usize..20, 0usize..8), 0..300)
        ) {
            // Random words (every byte value, any alignment) and zero runs of any length.
            let data: Vec<u8> = parts
                .iter()
                .flat_map(|&(w, zeros, cut)| {
                    w.to_le_bytes()[cut..].to_vec().into_iter().chain(std::iter::repeat_n(0, zeros))
                })
                .collect();
            round_trip(&data);
        }
    }
}
