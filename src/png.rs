//! A fast PNG encoder specialised for masks: 8-bit grayscale, filter 0, one fixed-Huffman
//! deflate block whose back-references are runs (distance 1) and copies of one of the
//! eight rows above (zone-compensated masks repeat rows, `zlib_rows`); the work grows with
//! the number of runs, not of pixels. The same runs give the image's lit pixels ([`Lit`]:
//! count, sum, box), so the slicer's record of a mask takes no pass of its own.
//!
//! Invariants: a standard PNG; the bytes are deterministic and independent of the lit box
//! the caller gives; a test pins the stream to an obvious bit-by-bit encoder of the same rule.

use std::ops::Range;

/// A rectangle of an image's pixels: rows `r0..r1` (row 0 at the top) and columns
/// `c0..c1`, both half-open. A mask's lit box is one: the mask is zero outside it, so the
/// passes after the rasterizer (compensation, lit area, PNG encoding) visit only the box.
/// The default is [`PixelBox::EMPTY`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PixelBox {
    /// First row.
    pub r0: usize,
    /// One past the last row.
    pub r1: usize,
    /// First column.
    pub c0: usize,
    /// One past the last column.
    pub c1: usize,
}

impl PixelBox {
    /// The box of no pixel.
    pub const EMPTY: PixelBox = PixelBox::new(0, 0, 0, 0);
    /// Every pixel of any image, for passes that clip the box to the image.
    pub const ALL: PixelBox = PixelBox::new(0, usize::MAX, 0, usize::MAX);

    /// Rows `r0..r1`, columns `c0..c1`.
    pub const fn new(r0: usize, r1: usize, c0: usize, c1: usize) -> PixelBox {
        PixelBox { r0, r1, c0, c1 }
    }

    /// Every pixel of a `width × height` image.
    pub fn whole(width: usize, height: usize) -> PixelBox {
        PixelBox::new(0, height, 0, width)
    }

    /// The rows `r0..r1`.
    pub fn rows(&self) -> Range<usize> {
        self.r0..self.r1
    }

    /// The columns `c0..c1`.
    pub fn cols(&self) -> Range<usize> {
        self.c0..self.c1
    }
}

/// Encodes `data` (row-major, `width × height` bytes) as an 8-bit grayscale PNG.
pub fn encode_gray8(width: u32, height: u32, data: &[u8]) -> Vec<u8> {
    encode_gray8_in(width, height, data, PixelBox::ALL).0
}

/// Like [`encode_gray8`] for a mask known to be zero outside `lit_box`: only the box is
/// scanned. The bytes are the same as `encode_gray8`'s; with them come the image's
/// [`Lit`] pixels, counted from the runs the encoder codes.
pub fn encode_gray8_in(width: u32, height: u32, data: &[u8], lit_box: PixelBox) -> (Vec<u8>, Lit) {
    assert_eq!(data.len(), width as usize * height as usize, "mask size");
    let w = width as usize;
    encode_rows(width, height, |r| &data[r * w..(r + 1) * w], lit_box)
}

/// The nonzero pixels of an image: how many, the sum of all its values and their box.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Lit {
    /// Number of nonzero pixels.
    pub count: u64,
    /// Sum of the pixel values.
    pub sum: u64,
    /// The box of the nonzero pixels, `[c0, r0, c1, r1]` (ends exclusive); `None` when no
    /// pixel is lit.
    pub lit_box: Option<[u32; 4]>,
}

/// The nonzero pixels of one row: count, value sum, first and one past the last column
/// (`first == end` when none).
#[derive(Clone, Copy, Default)]
struct RowLit {
    count: u64,
    sum: u64,
    first: usize,
    end: usize,
}

impl Lit {
    /// Adds row `r`'s pixels.
    #[inline(always)]
    fn add(&mut self, r: usize, row: RowLit) {
        if row.count == 0 {
            return;
        }
        self.count += row.count;
        self.sum += row.sum;
        let (r, c0, c1) = (r as u32, row.first as u32, row.end as u32);
        self.lit_box = Some(match self.lit_box {
            None => [c0, r, c1, r + 1],
            Some([a0, b0, a1, _]) => [a0.min(c0), b0, a1.max(c1), r + 1],
        });
    }
}

/// [`encode_gray8`] of the image whose row `r` (`width` bytes) is `row(r)`, without the
/// image in one piece (the same bytes).
pub fn encode_gray8_rows<'a>(width: u32, height: u32, row: impl Fn(usize) -> &'a [u8]) -> Vec<u8> {
    encode_rows(width, height, row, PixelBox::ALL).0
}

#[inline(always)]
fn encode_rows<'a>(
    width: u32,
    height: u32,
    row: impl Fn(usize) -> &'a [u8],
    lit_box: PixelBox,
) -> (Vec<u8>, Lit) {
    let (idat, lit) = zlib_rows(width as usize, height as usize, row, lit_box);
    let mut out = Vec::with_capacity(idat.len() + 64);
    out.extend_from_slice(b"\x89PNG\r\n\x1a\n");
    let mut ihdr = Vec::with_capacity(13);
    ihdr.extend_from_slice(&width.to_be_bytes());
    ihdr.extend_from_slice(&height.to_be_bytes());
    ihdr.extend_from_slice(&[8, 0, 0, 0, 0]); // bit depth 8, grayscale, deflate, filter 0, no interlace
    chunk(&mut out, b"IHDR", &ihdr);
    chunk(&mut out, b"IDAT", &idat);
    chunk(&mut out, b"IEND", &[]);
    (out, lit)
}

/// The Adler-32 of an image's PNG scanlines of filter type 0 (each row of `width` bytes
/// after a 0 byte): what a zlib stream of the unfiltered image ends with, so what the
/// IDAT of [`encode_gray8`] ends with ([`scanlines_adler32_of`]). Vectorized
/// (`simd-adler32`): a compensated mask's rows are runs of a few equal grays at most.
pub fn scanlines_adler32(width: u32, data: &[u8]) -> u32 {
    let mut ad = simd_adler32::Adler32::new();
    for row in data.chunks(width.max(1) as usize) {
        // The filter byte 0: b += a.
        let (a, b) = (ad.finish() & 0xffff, ad.finish() >> 16);
        ad = simd_adler32::Adler32::from_checksum(((b + a) % ADLER_MOD as u32) << 16 | a);
        ad.write(row);
    }
    ad.finish()
}

/// The Adler-32 at the end of the zlib stream of `png`, a PNG as [`encode_gray8`] writes
/// it (one IDAT, then IEND): [`scanlines_adler32`] of its pixels, read from its bytes.
pub fn scanlines_adler32_of(png: &[u8]) -> u32 {
    // The Adler-32, the IDAT's CRC, then the 12 bytes of IEND.
    let at = png.len() - 20;
    u32::from_be_bytes(png[at..at + 4].try_into().expect("4 bytes"))
}

fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], body: &[u8]) {
    out.extend_from_slice(&(body.len() as u32).to_be_bytes());
    let start = out.len();
    out.extend_from_slice(kind);
    out.extend_from_slice(body);
    let crc = crc32(&out[start..]);
    out.extend_from_slice(&crc.to_be_bytes());
}

fn crc32(bytes: &[u8]) -> u32 {
    // crc32fast picks a carry-less-multiply (PCLMULQDQ) kernel when the CPU has one.
    crc32fast::hash(bytes)
}

/// The Adler-32 modulus: the largest prime below 2¹⁶.
const ADLER_MOD: u64 = 65521;

/// Adler-32 state updated by runs of one byte value.
struct Adler {
    a: u64,
    b: u64,
    /// Bytes added since the last reduction modulo 65521.
    pending: u32,
}

impl Adler {
    /// The state before any byte.
    const NEW: Adler = Adler {
        a: 1,
        b: 0,
        pending: 0,
    };
    /// Bytes between reductions modulo 65521: with a, b reduced below 2¹⁶ and at most
    /// `REDUCE + BIG` bytes since, a < 2³² and b < 2⁵⁵, so nothing overflows.
    const REDUCE: u32 = 1 << 22;
    /// Runs at least this long use the modular formula (k² would overflow for huge k).
    const BIG: u64 = 1 << 20;

    fn run(&mut self, v: u8, k: u64) {
        let v = v as u64;
        if k < Self::BIG {
            // After k bytes of value v: a' = a + k·v, b' = b + k·a + v·k(k+1)/2, in plain
            // integers, reduced every few million bytes.
            self.b += k * self.a + v * (k * (k + 1) / 2);
            self.a += k * v;
            self.pending += k as u32;
            if self.pending >= Self::REDUCE {
                self.a %= ADLER_MOD;
                self.b %= ADLER_MOD;
                self.pending = 0;
            }
            return;
        }
        self.a %= ADLER_MOD;
        self.b %= ADLER_MOD;
        self.pending = 0;
        let k_m = k % ADLER_MOD;
        let tri = if k.is_multiple_of(2) {
            (k / 2 % ADLER_MOD) * ((k + 1) % ADLER_MOD)
        } else {
            (k % ADLER_MOD) * (k.div_ceil(2) % ADLER_MOD)
        } % ADLER_MOD;
        self.b = (self.b + k_m * self.a + v * tri) % ADLER_MOD;
        self.a = (self.a + k_m * v) % ADLER_MOD;
    }

    /// Adds the bytes of a scanline from its [`AdlerDelta`].
    fn add(&mut self, d: AdlerDelta) {
        let (a, b) = (self.a % ADLER_MOD, self.b % ADLER_MOD);
        self.a = (a + d.s1) % ADLER_MOD;
        self.b = (b + d.len % ADLER_MOD * a + d.s2) % ADLER_MOD;
        self.pending = 0;
    }
}

/// What a scanline adds to an Adler-32 whatever comes before it: its length `L`, its byte
/// sum and `Σ (L − i)·x_i` (the sum of its running sums), modulo 65521.
#[derive(Clone, Copy)]
struct AdlerDelta {
    len: u64,
    s1: u64,
    s2: u64,
}

impl AdlerDelta {
    /// Of the scanline: filter byte 0, `c0` zeros, `row` (the box), zeros up to `w`.
    fn of_row(w: usize, c0: usize, row: &[u8]) -> AdlerDelta {
        let len = (w + 1) as u64;
        let (mut s1, mut s2, mut p) = (0u64, 0u64, (1 + c0) as u64);
        let mut i = 0;
        while i < row.len() {
            let v = row[i] as u64;
            let k = run_len(&row[i..], row[i]) as u64;
            // Σ over the run of (len − q) for q = p .. p + k − 1
            s1 += v * k;
            s2 += v * (k * (len - p) - k * (k - 1) / 2);
            p += k;
            i += k as usize;
        }
        AdlerDelta {
            len,
            s1: s1 % ADLER_MOD,
            s2: s2 % ADLER_MOD,
        }
    }
}

/// The deflate bit stream being written.
struct Bits {
    /// The bytes written so far.
    out: Vec<u8>,
    /// Bits not yet in `out`, the first in the lowest bit.
    acc: u64,
    /// How many bits `acc` holds (fewer than 32 between calls).
    n: u32,
    /// The fixed-Huffman code tables.
    codes: &'static Codes,
}

impl Bits {
    /// Appends the low `bits` bits of `value` (at most 32) in deflate's LSB-first order.
    #[inline(always)]
    fn put(&mut self, value: u32, bits: u32) {
        self.acc |= (value as u64) << self.n;
        self.n += bits;
        if self.n >= 32 {
            self.out.extend_from_slice(&(self.acc as u32).to_le_bytes());
            self.acc >>= 32;
            self.n -= 32;
        }
    }

    /// Writes the pending whole bytes and the last partial byte (zero-padded).
    fn finish(mut self) -> Vec<u8> {
        while self.n > 0 {
            self.out.push(self.acc as u8);
            self.acc >>= 8;
            self.n = self.n.saturating_sub(8);
        }
        self.out
    }

    /// A back-reference of `len` (3..=258) bytes at distance 1.
    #[inline(always)]
    fn repeat(&mut self, len: usize) {
        let (code, bits) = self.codes.repeat[len];
        self.put(code, bits as u32);
    }
}

/// Fixed-Huffman codes, already bit-reversed into deflate's order.
struct Codes {
    /// Literal byte -> (code, length).
    literal: [(u16, u8); 256],
    /// Match length 3..=258 at distance 1 -> (length code + extra bits + distance code,
    /// total bits).
    repeat: [(u32, u8); 259],
}

fn codes() -> &'static Codes {
    static CODES: std::sync::OnceLock<Codes> = std::sync::OnceLock::new();
    CODES.get_or_init(|| {
        let rev = |code: u32, len: u32| code.reverse_bits() >> (32 - len);
        let mut c = Codes {
            literal: [(0, 0); 256],
            repeat: [(0, 0); 259],
        };
        for b in 0..256u32 {
            c.literal[b as usize] = if b < 144 {
                (rev(0x30 + b, 8) as u16, 8)
            } else {
                (rev(0x190 + (b - 144), 9) as u16, 9)
            };
        }
        for len in 3..=258 {
            let (sym, extra_bits, extra) = length_code(len);
            let (code, n) = if sym < 280 {
                (rev(sym - 256, 7), 7)
            } else {
                (rev(0xC0 + (sym - 280), 8), 8)
            };
            // then the extra bits, then distance code 0 (distance 1): five zero bits
            let v = code | extra << n;
            c.repeat[len] = (v, (n + extra_bits + 5) as u8);
        }
        c
    })
}

/// The deflate length code of a copy of `len` bytes (3..=258, RFC 1951 §3.2.5): (symbol,
/// number of extra bits, value of the extra bits).
fn length_code(len: usize) -> (u32, u32, u32) {
    /// The shortest length of each length symbol 257..=285.
    const BASE: [u16; 29] = [
        3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 15, 17, 19, 23, 27, 31, 35, 43, 51, 59, 67, 83, 99, 115,
        131, 163, 195, 227, 258,
    ];
    /// The number of extra bits of each length symbol.
    const EXTRA: [u8; 29] = [
        0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0,
    ];
    let i = BASE.partition_point(|&b| b as usize <= len) - 1;
    (
        257 + i as u32,
        EXTRA[i] as u32,
        (len - BASE[i] as usize) as u32,
    )
}

/// Emits `k` copies of byte `v` (the literal is the first copy, then distance-1 repeats).
#[inline(always)]
fn emit_run(bits: &mut Bits, v: u8, k: usize) {
    let (lit, lit_len) = bits.codes.literal[v as usize];
    let (lit, lit_len) = (lit as u32, lit_len as u32);
    if k < 4 {
        for _ in 0..k {
            bits.put(lit, lit_len);
        }
        return;
    }
    let k = k - 1;
    if k <= 258 {
        // One write: the literal (≤ 9 bits) then the repeat (≤ 18 bits).
        let (rep, rep_len) = bits.codes.repeat[k];
        bits.put(lit | rep << lit_len, lit_len + rep_len as u32);
        return;
    }
    bits.put(lit, lit_len);
    long_repeat(bits, k);
}

/// `k` (> 258) copies of the previous byte as distance-1 back-references: 258 long ones
/// two per write (the 13-bit code of length 258 twice), then at most three to finish.
#[inline(never)]
fn long_repeat(bits: &mut Bits, mut k: usize) {
    let (code, len) = bits.codes.repeat[258];
    let (two, two_len) = (code | code << len, 2 * len as u32);
    // Never leave 1 or 2 bytes: a repeat is at least 3 long.
    while k >= 2 * 258 + 3 {
        bits.put(two, two_len);
        k -= 2 * 258;
    }
    while k > 258 {
        let l = if k - 258 < 3 { k - 3 } else { 258 };
        bits.repeat(l);
        k -= l;
    }
    bits.repeat(k);
}

/// Length of the run of byte `v` starting at `s[0]`: eight bytes per step, the first
/// different byte from the lowest set bit of the XOR (a plain loop: the typical run is a
/// few words long).
#[inline(always)]
fn run_len(s: &[u8], v: u8) -> usize {
    let pat = u64::from_ne_bytes([v; 8]);
    let mut words = s.chunks_exact(8);
    let mut i = 0;
    for w in &mut words {
        let x = u64::from_le_bytes(w.try_into().expect("8 bytes")) ^ pat;
        if x != 0 {
            return i + (x.trailing_zeros() / 8) as usize;
        }
        i += 8;
    }
    i + words.remainder().iter().take_while(|&&b| b == v).count()
}

/// The pending run of the stream (it spans row boundaries: filter bytes are 0, like empty
/// pixels) and where finished runs go.
struct Runs {
    bits: Bits,
    adler: Adler,
    /// Value and length of the pending run.
    v: u8,
    k: usize,
}

impl Runs {
    /// Appends `k` (> 0) bytes of value `v`.
    #[inline(always)]
    fn push(&mut self, v: u8, k: usize) {
        if v == self.v {
            self.k += k;
        } else {
            self.end();
            self.v = v;
            self.k = k;
        }
    }

    /// Writes the pending run (if any).
    #[inline(always)]
    fn end(&mut self) {
        if self.k > 0 {
            emit_run(&mut self.bits, self.v, self.k);
            self.adler.run(self.v, self.k as u64);
        }
    }
}

/// Rows with at least this many runs (of the scanline with its filter byte, equal
/// neighbours merged) equal to one of the [`COPY_ROWS`] rows above are coded as a copy of
/// the nearest one. A copy of a 1024-pixel row costs 88 to 100 bits, a run 20 to 45: a row
/// of four or more runs is cheaper copied, a row of zeros (52 bits) or one lit run is not.
const COPY_MIN_RUNS: usize = 4;

/// How many rows above a row may be its copy's source. Zone-compensated masks repeat rows
/// with a period of 1, 2, 4, … (mixing zones' ordered dither, [`crate::optics::compensate`]):
/// on `box` in zone mode 19 % of the lit rows equal the row above, 70 % one of the 2 above,
/// 91 % of 4, 95 % of 8, and no more of 16.
const COPY_ROWS: usize = 8;

/// What rows are compared by before their bytes: the number of runs and where the lit
/// part begins and ends (from the filter byte), 16 bits each (rows are copied only when
/// `w + 1 ≤ 32768`); 0 for a row of zeros. Equal rows have equal signatures, whatever box
/// they were scanned in.
#[inline(always)]
fn signature(runs: usize, first: usize, end: usize) -> u64 {
    (runs as u64) << 32 | (first as u64) << 16 | end as u64
}

/// The largest distance deflate can refer back to.
const MAX_DISTANCE: usize = 32768;

/// Deflate's distance code of `d` (1..=32768) as bits ready to write (the 5-bit fixed
/// code reversed, then its extra bits) and their count.
fn distance_bits(d: usize) -> (u32, u32) {
    assert!((1..=MAX_DISTANCE).contains(&d), "distance {d}");
    let e = d as u32 - 1;
    let (code, extra_bits, extra) = if e < 4 {
        (e, 0, 0)
    } else {
        let k = 31 - e.leading_zeros(); // floor(log2(d − 1)) ≥ 2
        let n = k - 1;
        (2 * k + (e >> n & 1), n, e & ((1 << n) - 1))
    };
    let rev = code.reverse_bits() >> 27;
    (rev | extra << 5, 5 + extra_bits)
}

/// `k` (≥ 3) bytes copied from `d` bytes back (`dist` = [`distance_bits`] of `d`): matches
/// of 258, never leaving 1 or 2 bytes for the last one.
#[inline(never)]
fn emit_copy(bits: &mut Bits, mut k: usize, dist: (u32, u32)) {
    debug_assert!(k >= 3);
    while k > 0 {
        let l = if k <= 258 {
            k
        } else if k - 258 < 3 {
            k - 3
        } else {
            258
        };
        // The length's code and extra bits are the distance-1 repeat's without its five
        // zero bits of distance code 0.
        let (rep, rep_len) = bits.codes.repeat[l];
        let len_bits = rep_len as u32 - 5;
        bits.put(rep | dist.0 << len_bits, len_bits + dist.1);
        k -= l;
    }
}

/// Codes one image row as runs: its filter byte and the zeros left of the box `c0..c1`,
/// the box's bytes `row`, the zeros right of it (runs merge exactly as if the whole row
/// had been scanned, so the stream does not depend on the box). Returns the row's
/// [`signature`] when it has at least [`COPY_MIN_RUNS`] runs, and its lit pixels.
#[inline(always)]
fn push_row(runs: &mut Runs, row: &[u8], w: usize, c0: usize, c1: usize) -> (Option<u64>, RowLit) {
    runs.push(0, 1 + c0);
    // The box's runs, and the value and length of its last one.
    let (mut inbox, mut lv, mut lk) = (0usize, 0u8, 0usize);
    let mut lit = RowLit::default();
    let mut i = 0;
    while i < row.len() {
        let v = row[i];
        let k = run_len(&row[i..], v);
        runs.push(v, k);
        if v != 0 {
            if lit.count == 0 {
                lit.first = c0 + i;
            }
            (lit.count, lit.sum, lit.end) = (
                lit.count + k as u64,
                lit.sum + (v as u64) * k as u64,
                c0 + i + k,
            );
        }
        (inbox, lv, lk) = (inbox + 1, v, k);
        i += k;
    }
    if w > c1 {
        runs.push(0, w - c1);
    }
    // The row's runs: the zeros up to the box, the box's, the zeros after it, less
    // the zero runs of the box that merge with those.
    let lead = row.first() == Some(&0);
    let runs_in_row = 1 + inbox + (w > c1) as usize - lead as usize - (w > c1 && lv == 0) as usize;
    let sig = (runs_in_row >= COPY_MIN_RUNS).then(|| {
        signature(
            runs_in_row,
            1 + c0 + if lead { run_len(row, 0) } else { 0 },
            1 + c1 - if lv == 0 { lk } else { 0 },
        )
    });
    (sig, lit)
}

/// The zlib stream of the PNG scanlines (each row preceded by filter byte 0); row `r` of
/// the image is `row_of(r)` (`w` bytes). Scanlines are coded as runs (a run goes on
/// across row ends), except that a row with at least [`COPY_MIN_RUNS`] runs equal to one
/// of the [`COPY_ROWS`] rows above is a copy of the nearest such row.
///
/// A row is coded as runs while it is scanned; when its [`signature`] and bytes equal a
/// row above, its codes are taken back and the copy written instead. After a copy the
/// next row is first compared with the rows above as it is (rows repeat in stretches). A
/// copy adds its bytes to the Adler-32 from its source row's [`AdlerDelta`], and its lit
/// pixels from its source row's.
#[inline(always)]
fn zlib_rows<'a>(
    w: usize,
    h: usize,
    row_of: impl Fn(usize) -> &'a [u8],
    lit_box: PixelBox,
) -> (Vec<u8>, Lit) {
    let PixelBox { r0, r1, c0, c1 } = lit_box;
    let (c0, c1) = (c0.min(w), c1.min(w).max(c0.min(w)));
    let mut bits = Bits {
        out: Vec::with_capacity(4096),
        acc: 0,
        n: 0,
        codes: codes(),
    };
    bits.put(0x78, 8);
    bits.put(0x01, 8);
    bits.put(1, 1); // BFINAL
    bits.put(1, 2); // BTYPE = 01, fixed Huffman
    let mut runs = Runs {
        bits,
        adler: Adler::NEW,
        v: 0,
        k: 0,
    };
    // Signatures of the last COPY_ROWS rows (row r at r % COPY_ROWS), and what their
    // bytes add to the Adler-32 once a copy needed it.
    let mut last = [0u64; COPY_ROWS];
    let mut delta: [Option<AdlerDelta>; COPY_ROWS] = [None; COPY_ROWS];
    // The lit pixels of those rows, and of the image.
    let (mut row_lit, mut lit) = ([RowLit::default(); COPY_ROWS], Lit::default());
    let max_back = COPY_ROWS.min(MAX_DISTANCE / (w + 1));
    // Whether the last row was a copy: then this row is first compared with the rows
    // above as it is (the scan would find the same row: the nearest equal one).
    let mut copied = false;
    for r in 0..h {
        let slot = r % COPY_ROWS;
        if !(r0..r1).contains(&r) {
            // filter byte 0, then an empty row: both continue the zero run
            runs.push(0, 1 + w);
            (last[slot], delta[slot], copied) = (0, None, false);
            row_lit[slot] = RowLit::default();
            continue;
        }
        let row = &row_of(r)[c0..c1];
        // The row as a copy of the row `j` above (ring slots `from` and `to`).
        let copy_of = |runs: &mut Runs,
                       ring: (&mut [u64], &mut [Option<AdlerDelta>], &mut [RowLit]),
                       j: usize| {
            let (from, to) = ((r - j) % COPY_ROWS, slot);
            let d = *ring.1[from].get_or_insert_with(|| AdlerDelta::of_row(w, c0, row));
            runs.adler.add(d);
            emit_copy(&mut runs.bits, w + 1, distance_bits(j * (w + 1)));
            (ring.0[to], ring.1[to], ring.2[to]) = (ring.0[from], Some(d), ring.2[from]);
        };
        if copied {
            let back = (1..=max_back.min(r - r0))
                .find(|&j| last[(r - j) % COPY_ROWS] != 0 && row_of(r - j)[c0..c1] == *row);
            if let Some(j) = back {
                runs.end();
                runs.k = 0;
                copy_of(&mut runs, (&mut last, &mut delta, &mut row_lit), j);
                lit.add(r, row_lit[slot]);
                continue;
            }
        }
        // Where the stream was before this row.
        let (mark, acc, n, pv, pk) = (
            runs.bits.out.len(),
            runs.bits.acc,
            runs.bits.n,
            runs.v,
            runs.k,
        );
        let adler = (runs.adler.a, runs.adler.b, runs.adler.pending);
        let (sig, this) = push_row(&mut runs, row, w, c0, c1);
        (delta[slot], row_lit[slot], copied) = (None, this, false);
        lit.add(r, this);
        let Some(sig) = sig.filter(|_| max_back > 0) else {
            last[slot] = 0;
            continue;
        };
        // Most rows match none of the rows above: one test of all of them first (the
        // ring holds the rows r − 1 … r − COPY_ROWS, 0 for rows of zeros and before row 0).
        let seen = last.iter().fold(false, |a, &x| a | (x == sig));
        let back = if seen {
            (1..=max_back.min(r - r0))
                .find(|&j| last[(r - j) % COPY_ROWS] == sig && row_of(r - j)[c0..c1] == *row)
        } else {
            None
        };
        last[slot] = sig;
        if let Some(j) = back {
            // Take the row's codes back, write the run pending before it, then the copy.
            runs.bits.out.truncate(mark);
            (runs.bits.acc, runs.bits.n, runs.v, runs.k) = (acc, n, pv, pk);
            (runs.adler.a, runs.adler.b, runs.adler.pending) = adler;
            runs.end();
            runs.k = 0;
            copy_of(&mut runs, (&mut last, &mut delta, &mut row_lit), j);
            copied = true;
        }
    }
    runs.end();
    let Runs {
        mut bits, adler, ..
    } = runs;
    bits.put(0, 7); // end of block (symbol 256: seven zero bits)
    let mut out = bits.finish();
    let ad = (((adler.b % ADLER_MOD) as u32) << 16) | (adler.a % ADLER_MOD) as u32;
    out.extend_from_slice(&ad.to_be_bytes());
    (out, lit)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::xorshift_bits;

    fn decode(png: &[u8]) -> (u32, u32, Vec<u8>) {
        let img = image::load_from_memory_with_format(png, image::ImageFormat::Png).unwrap();
        let g = img.as_luma8().expect("8-bit gray").clone();
        (g.width(), g.height(), g.into_raw())
    }

    /// The same stream written the slow, obvious way: raw scanlines, runs found byte by
    /// byte, rows to copy found by comparing whole rows, codes written bit by bit,
    /// Adler-32 byte by byte.
    fn reference_png(w: usize, h: usize, data: &[u8]) -> Vec<u8> {
        let rows: Vec<Vec<u8>> = data
            .chunks(w)
            .map(|row| [0].iter().chain(row).copied().collect())
            .collect();
        let raw: Vec<u8> = rows.concat();
        let mut bits: Vec<bool> = Vec::new();
        let huff = |bits: &mut Vec<bool>, code: u32, len: u32| {
            (0..len).rev().for_each(|i| bits.push(code >> i & 1 == 1))
        };
        let plain =
            |bits: &mut Vec<bool>, v: u32, n: u32| (0..n).for_each(|i| bits.push(v >> i & 1 == 1));
        plain(&mut bits, 0x78, 8);
        plain(&mut bits, 0x01, 8);
        plain(&mut bits, 1, 1);
        plain(&mut bits, 1, 2);
        // A match of `m` bytes at distance `d`, as pieces of at most 258.
        let matches = |bits: &mut Vec<bool>, mut m: usize, d: usize| {
            const DBASE: [usize; 30] = [
                1, 2, 3, 4, 5, 7, 9, 13, 17, 25, 33, 49, 65, 97, 129, 193, 257, 385, 513, 769,
                1025, 1537, 2049, 3073, 4097, 6145, 8193, 12289, 16385, 24577,
            ];
            let dc = DBASE.iter().rposition(|&b| b <= d).unwrap();
            let dextra = if dc < 4 { 0 } else { dc as u32 / 2 - 1 };
            while m > 0 {
                let l = if m <= 258 {
                    m
                } else if m - 258 < 3 {
                    m - 3
                } else {
                    258
                };
                let (sym, extra_bits, extra) = length_code(l);
                match sym {
                    257..=279 => huff(bits, sym - 256, 7),
                    _ => huff(bits, 0xC0 + sym - 280, 8),
                }
                plain(bits, extra, extra_bits);
                huff(bits, dc as u32, 5);
                plain(bits, (d - DBASE[dc]) as u32, dextra);
                m -= l;
            }
        };
        let code_runs = |bits: &mut Vec<bool>, raw: &[u8]| {
            let mut i = 0;
            while i < raw.len() {
                let v = raw[i];
                let k = raw[i..].iter().take_while(|&&b| b == v).count();
                i += k;
                let lit = |bits: &mut Vec<bool>| match v {
                    0..=143 => huff(bits, 0x30 + v as u32, 8),
                    _ => huff(bits, 0x190 + v as u32 - 144, 9),
                };
                if k < 4 {
                    (0..k).for_each(|_| lit(bits));
                    continue;
                }
                lit(bits);
                matches(bits, k - 1, 1);
            }
        };
        let runs_in = |row: &[u8]| 1 + row.windows(2).filter(|p| p[0] != p[1]).count();
        // Rows coded as runs since the last copy.
        let mut pending = Vec::new();
        for (r, row) in rows.iter().enumerate() {
            let back = (1..=8.min(r))
                .filter(|j| j * (w + 1) <= 32768)
                .find(|&j| rows[r - j] == *row && runs_in(row) >= 4);
            if let Some(j) = back {
                code_runs(&mut bits, &pending);
                pending.clear();
                matches(&mut bits, w + 1, j * (w + 1));
            } else {
                pending.extend_from_slice(row);
            }
        }
        code_runs(&mut bits, &pending);
        huff(&mut bits, 0, 7); // end of block
        let mut idat: Vec<u8> = bits
            .chunks(8)
            .map(|b| b.iter().enumerate().map(|(j, &x)| (x as u8) << j).sum())
            .collect();
        let (a, b) = adler_bytewise(raw.iter().copied());
        idat.extend_from_slice(&((b << 16 | a) as u32).to_be_bytes());
        let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
        let mut ihdr = (w as u32).to_be_bytes().to_vec();
        ihdr.extend_from_slice(&(h as u32).to_be_bytes());
        ihdr.extend_from_slice(&[8, 0, 0, 0, 0]);
        chunk(&mut out, b"IHDR", &ihdr);
        chunk(&mut out, b"IDAT", &idat);
        chunk(&mut out, b"IEND", &[]);
        out
    }

    /// Test image `k` of `w × h`: 0 zeros, 1 full, 2 random bytes, 3 a disc with
    /// anti-aliased edges, 4 runs (up to 600 long) of four values, 5 one value, 6 runs of
    /// three values (some up to 3000 long), 7 and 8 runs of random bytes (some up to 300
    /// long), 9 and 10 rows repeating rows above ([`repeated_rows`]). Runs cross rows.
    fn image(w: usize, h: usize, k: usize, rnd: &mut dyn FnMut() -> u64) -> Vec<u8> {
        let mut d = vec![0u8; w * h];
        let (mut i, n) = (0, d.len());
        match k {
            0 => {}
            1 => d.fill(255),
            2 => d.iter_mut().for_each(|v| *v = rnd() as u8),
            3 => {
                for (i, v) in d.iter_mut().enumerate() {
                    let (x, y) = ((i % w) as f64, (i / w) as f64);
                    let r = ((x - w as f64 / 2.0).powi(2) + (y - h as f64 / 2.0).powi(2)).sqrt();
                    let c = (w.min(h) as f64 / 3.0 - r + 0.5).clamp(0.0, 1.0);
                    *v = (c * 255.0).round() as u8;
                }
            }
            4 => {
                while i < n {
                    let k = (rnd() % 600) as usize + 1;
                    let v = [0u8, 255, 7, 128][(rnd() % 4) as usize];
                    d[i..(i + k).min(n)].fill(v);
                    i += k;
                }
            }
            5..=8 => {
                while i < n {
                    let r = rnd();
                    let len = match (k, r % 4) {
                        (5, _) => n,
                        (6, 0) => (r >> 8) as usize % 3000 + 1,
                        (_, 0) => (r >> 8) as usize % 300 + 1,
                        _ => (r >> 8) as usize % 9 + 1,
                    };
                    let v = match k {
                        5 | 6 => [0u8, 255, 131][(r >> 40) as usize % 3],
                        _ => (r >> 40) as u8,
                    };
                    d[i..(i + len).min(n)].fill(v);
                    i += len;
                }
            }
            _ => return repeated_rows(w, h, k == 10, rnd),
        }
        d
    }

    #[test]
    fn bytes_match_the_obvious_encoder_and_decode() {
        // Pins the exact stream (not just what a decoder reads back): masks are hashed
        // into job.json, so a change of bytes is a change of output.
        let mut rnd = xorshift_bits(0x0bad_5eed_1234_5678);
        for (w, h) in [
            (1, 1),
            (3, 2),
            (7, 5),
            (9, 4),
            (259, 3),
            (300, 7),
            (517, 2),
            (1000, 13),
            (1024, 40),
            (700, 600),
            (1024, 768),
        ] {
            for k in 0..11 {
                let d = image(w, h, k, &mut rnd);
                let (png, counted) = encode_gray8_in(w as u32, h as u32, &d, PixelBox::ALL);
                assert!(png == reference_png(w, h, &d), "{w}x{h} image {k}");
                assert_eq!(counted, lit_of(w, &d), "{w}x{h} image {k}");
                let by_rows = encode_gray8_rows(w as u32, h as u32, |r| &d[r * w..(r + 1) * w]);
                assert!(by_rows == png, "{w}x{h} image {k}: by rows");
                assert!(decode(&png) == (w as u32, h as u32, d), "{w}x{h} image {k}");
            }
        }
    }

    /// Rows that often repeat the row above: runs of random values and lengths (`zones`
    /// false), or bands of zone-like rows (a few runs of grays between zeros, bands of
    /// zero rows between them) as zone-compensated masks have.
    fn repeated_rows(w: usize, h: usize, zones: bool, rnd: &mut dyn FnMut() -> u64) -> Vec<u8> {
        let mut d = vec![0u8; w * h];
        let mut row = vec![0u8; w];
        for r in 0..h {
            let x = rnd();
            if r == 0 || x.is_multiple_of(4) {
                row.fill(0);
                if zones && x.is_multiple_of(3) {
                    // a band of zeros
                } else {
                    let (a, b) = ((x >> 8) as usize % w, (x >> 24) as usize % w);
                    let (a, b) = (a.min(b), a.max(b) + 1);
                    let mut c = a;
                    while c < b {
                        let y = rnd();
                        let k = if zones {
                            (y as usize % 80 + 1).min(b - c)
                        } else {
                            (y as usize % 9 + 1).min(b - c)
                        };
                        let v = if zones {
                            120 + (y >> 20) as u8 % 9
                        } else {
                            (y >> 20) as u8
                        };
                        row[c..c + k].fill(v);
                        c += k;
                    }
                }
            }
            d[r * w..(r + 1) * w].copy_from_slice(&row);
            // Now and then a row from up to ten rows above (copies from as far as eight).
            let j = 1 + (x >> 40) as usize % 10;
            if x % 4 == 1 && j <= r {
                d.copy_within((r - j) * w..(r - j + 1) * w, r * w);
            }
        }
        d
    }

    #[test]
    fn rows_repeating_the_row_above_are_copied() {
        let mut rnd = xorshift_bits(0x5eed_0fc0_b1e5);
        // Distances 2, 4, 10 (extra bits), 301, 1025 and 32768, the largest; no copies
        // beyond it.
        for (w, h) in [
            (1, 9),
            (3, 9),
            (9, 30),
            (300, 50),
            (1024, 100),
            (32767, 3),
            (32768, 3),
        ] {
            for zones in [false, true] {
                let d = repeated_rows(w, h, zones, &mut rnd);
                let (png, counted) = encode_gray8_in(w as u32, h as u32, &d, PixelBox::ALL);
                assert!(png == reference_png(w, h, &d), "{w}x{h} {zones}");
                assert!(decode(&png).2 == d, "{w}x{h} {zones}");
                assert_eq!(counted, lit_of(w, &d), "{w}x{h} {zones}");
                // The lit box does not change the bytes.
                let lit: Vec<(usize, usize)> = (0..w * h)
                    .filter(|&i| d[i] != 0)
                    .map(|i| (i / w, i % w))
                    .collect();
                if let (Some(&(r0, _)), Some(&(r1, _))) = (lit.first(), lit.last()) {
                    let c0 = lit.iter().map(|p| p.1).min().unwrap();
                    let c1 = lit.iter().map(|p| p.1).max().unwrap() + 1;
                    let lit_box = PixelBox::new(r0, r1 + 1, c0, c1);
                    let boxed = encode_gray8_in(w as u32, h as u32, &d, lit_box);
                    assert!(boxed.0 == png, "{w}x{h} {zones}: boxed");
                    assert_eq!(boxed.1, counted, "{w}x{h} {zones}: boxed");
                }
            }
        }
        // A zone-compensated square: 400 rows, each a run of zeros, an edge, five zones
        // of grays, an edge, zeros; one zone alternates two grays (period 2), another
        // shows the upper one every fourth row. Copied, a row costs about 11 bytes
        // instead of more than 20.
        let (w, h) = (1024usize, 768usize);
        let mut d = vec![0u8; w * h];
        for r in 100..500 {
            let row = &mut d[r * w..(r + 1) * w];
            row[199] = 60;
            for z in 0..5 {
                row[200 + 80 * z..280 + 80 * z].fill(200 + z as u8);
            }
            row[200..280].fill(200 + (r % 2) as u8);
            row[440..520].fill(210 + (r % 4 == 0) as u8);
            row[600] = 60;
        }
        let (png, counted) = encode_gray8_in(w as u32, h as u32, &d, PixelBox::ALL);
        assert!(png == reference_png(w, h, &d));
        assert!(decode(&png).2 == d);
        assert!(png.len() < 4600 + 400 * 12, "{}", png.len());
        assert_eq!(counted, lit_of(w, &d));
    }

    /// The nonzero pixels of `d` (`w` wide), pixel by pixel.
    fn lit_of(w: usize, d: &[u8]) -> Lit {
        let lit: Vec<usize> = (0..d.len()).filter(|&i| d[i] != 0).collect();
        let (cols, rows) = (lit.iter().map(|i| i % w), lit.iter().map(|i| i / w));
        Lit {
            count: lit.len() as u64,
            sum: d.iter().map(|&v| v as u64).sum(),
            lit_box: (!lit.is_empty()).then(|| {
                [
                    cols.clone().min().unwrap() as u32,
                    rows.clone().min().unwrap() as u32,
                    cols.max().unwrap() as u32 + 1,
                    rows.max().unwrap() as u32 + 1,
                ]
            }),
        }
    }

    #[test]
    fn boxed_encoding_is_byte_identical() {
        let (w, h) = (300usize, 200usize);
        let mut d = vec![0u8; w * h];
        for r in 50..120 {
            for c in 40..260 {
                d[r * w + c] = if (r + c) % 17 == 0 { 99 } else { 255 };
            }
        }
        let full = encode_gray8(w as u32, h as u32, &d);
        for [r0, r1, c0, c1] in [
            [50, 120, 40, 260],
            [0, 200, 0, 300],
            [49, 121, 39, 261],
            [50, 120, 0, 300],
        ] {
            let b = PixelBox::new(r0, r1, c0, c1);
            let (png, counted) = encode_gray8_in(w as u32, h as u32, &d, b);
            assert_eq!(png, full, "{b:?}");
            assert_eq!(counted, lit_of(w, &d), "{b:?}");
        }
    }

    /// Adler-32's two sums over `data`, byte by byte.
    fn adler_bytewise(data: impl IntoIterator<Item = u8>) -> (u64, u64) {
        data.into_iter().fold((1, 0), |(a, b), x| {
            let a = (a + x as u64) % ADLER_MOD;
            (a, (b + a) % ADLER_MOD)
        })
    }

    #[test]
    fn adler_runs_match_bytewise() {
        let data: Vec<u8> = (0..200_000u32)
            .map(|i| {
                if (i / 70_000) % 2 == 0 {
                    255
                } else {
                    (i % 7) as u8
                }
            })
            .collect();
        let (a, b) = adler_bytewise(data.iter().copied());
        let mut ad = Adler::NEW;
        let mut i = 0;
        while i < data.len() {
            let k = run_len(&data[i..], data[i]);
            ad.run(data[i], k as u64);
            i += k;
        }
        assert_eq!((ad.a % ADLER_MOD, ad.b % ADLER_MOD), (a, b));
        // Random runs, short and long, some past the plain-integer limit, over more bytes
        // than one reduction period.
        let mut rnd = xorshift_bits(0x2545_F491_4F6C_DD1D);
        let (mut a, mut b) = (1u64, 0u64);
        let mut ad = Adler::NEW;
        let mut total = 0u64;
        while total < 12_000_000 {
            let r = rnd();
            let v = (r >> 8) as u8;
            let k = match r % 8 {
                0 => (r >> 20) % 3_000_000,
                1..=3 => (r >> 20) % 2000,
                _ => (r >> 20) % 16,
            };
            ad.run(v, k);
            total += k;
            for _ in 0..k {
                a = (a + v as u64) % ADLER_MOD;
                b = (b + a) % ADLER_MOD;
            }
        }
        assert_eq!((ad.a % ADLER_MOD, ad.b % ADLER_MOD), (a, b));
    }

    #[test]
    fn the_scanlines_adler32_is_the_encoders() {
        let mut rnd = xorshift_bits(7);
        for (w, h) in [(1, 1), (5, 3), (1024, 768), (333, 17)] {
            for zeros in [false, true] {
                let d: Vec<u8> = (0..w * h)
                    .map(|i| {
                        if zeros && (i / w) % 3 != 1 {
                            0
                        } else {
                            rnd() as u8 % 4 * 60
                        }
                    })
                    .collect();
                let png = encode_gray8(w as u32, h as u32, &d);
                let plain = d.chunks(w).flat_map(|row| [0].iter().chain(row).copied());
                let (a, b) = adler_bytewise(plain);
                let want = (b << 16 | a) as u32;
                assert_eq!(scanlines_adler32(w as u32, &d), want);
                assert_eq!(scanlines_adler32_of(&png), want);
            }
        }
        // Every byte value; a field of 255s long enough for the sums to wrap many times.
        let every: Vec<u8> = (0..=255u8).cycle().take(257 * 300).collect();
        for (w, d) in [(257, every), (3840, vec![255u8; 3840 * 2160])] {
            let plain = d.chunks(w).flat_map(|row| [0].iter().chain(row).copied());
            let (a, b) = adler_bytewise(plain);
            assert_eq!(scanlines_adler32(w as u32, &d), (b << 16 | a) as u32);
        }
    }

    #[test]
    fn empty_mask_is_tiny() {
        let png = encode_gray8(1024, 768, &vec![0u8; 1024 * 768]);
        // Deflate copies at most 258 bytes per 13-bit code: ~5 KB for 786 KB of zeros.
        assert!(png.len() < 5200, "{}", png.len());
    }
}
