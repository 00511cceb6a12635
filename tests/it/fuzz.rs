//! Mutation fuzzing of every parser and file reader, in process, on the stable toolchain.
//!
//! Each target starts from a few valid inputs (seeds) and feeds the parser inputs made from
//! them by random mutations (bit flips, interesting bytes, inserted, deleted, repeated and
//! spliced ranges, numbers replaced by extreme ones, truncation), with a fixed seed per
//! target, so a run is reproducible. A parser may return an error, never panic, abort or
//! hang: a panic fails the test with the input written to
//! `target/fuzz-crash-TARGET-N.bin`; a watchdog aborts the process, after writing the input
//! the same way, when one execution takes longer than 10 s.
//!
//! The archive targets open a whole job as `dmdsl run` does (`formats::open` on a scratch
//! file, then `exec::run`: verification and simulation): `archive` mutates the bytes of
//! the zips (most die at a CRC), `sl1`, `control` and `zipped` change a seed archive's
//! entries by what they hold (settings values set to extreme numbers, huge counts or deep
//! `${...}` expressions, keys removed, PNG headers and chunks changed with their CRCs
//! made right, entries dropped, duplicated, renamed, moved or taken from another seed)
//! and zip it again validly. The SL1 seeds are the fixtures with their displays shrunk 8
//! times in pixels (same settings, same code paths, a fraction of the time).
//!
//! The `nanodlp` target does the same with a plate (the first SL1 seed exported), and
//! `hardware` reads the SLA control-file standard's hardware description (JSON values
//! replaced, bytes mutated) and checks a job against it; every `control` input is
//! validated against the standard's schema first.
//!
//! CI runs 10⁴ inputs per target and fewer for the archive targets (1500, 150, 800, 150,
//! 150) and `hardware` (2000): about 6 s in all in the test build on 2 cores. A long run
//! (docs/BENCHMARKS.md, "Fuzzing"):
//!
//! ```sh
//! DMDSL_FUZZ_RUNS=1000000 cargo test --release --test it fuzz -- --nocapture
//! ```
//!
//! `DMDSL_FUZZ_RUNS` sets every target's count, `DMDSL_FUZZ_SEED` changes the seed;
//! `DMDSL_FUZZ_TARGET` runs one target. Every crash found becomes a regression input under
//! `fixtures/fuzz/` (replayed by `regression_inputs_are_refused_cleanly`; an archive is
//! opened and replayed as the archive targets do).

use crate::common::*;
use dmdsl::bundle::Manifest;
use dmdsl::geometry::distortion::Table;
use dmdsl::profile::{Calibration, Profile};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// A parser under test: returns whether it accepted the input (only counted).
type Parser = fn(&[u8]) -> bool;

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn stl(b: &[u8]) -> bool {
    dmdsl::mesh::load_bytes(Path::new("fuzz.stl"), b).is_ok()
}

fn obj(b: &[u8]) -> bool {
    dmdsl::mesh::load_bytes(Path::new("fuzz.obj"), b).is_ok()
}

fn profile(b: &[u8]) -> bool {
    Profile::from_toml(&text(b), "fuzz.toml").is_ok_and(|p| {
        // What a job does first with a profile: its field and a second validation.
        let f = p.field();
        f.width_mm() >= 0.0 && p.validate().is_ok()
    })
}

fn calibration(b: &[u8]) -> bool {
    Calibration::from_toml(&text(b), Path::new("fuzz.toml")).is_ok()
}

fn readings(b: &[u8]) -> bool {
    dmdsl::optics::calib::parse_csv(&text(b), Path::new("fuzz.csv")).is_ok()
}

fn distortion(b: &[u8]) -> bool {
    Table::parse(Path::new("fuzz.csv"), &text(b)).is_ok()
}

fn manifest(b: &[u8]) -> bool {
    Manifest::from_json(b, Path::new("job.json")).is_ok_and(|m| {
        // The executor's first use of a manifest: its machine and a replay of its steps.
        m.machine.validate().is_ok() && {
            let _ = dmdsl::exec::replay(&m);
            true
        }
    })
}

/// A job archive (zipped bundle, SL1/SL1S, SLA control file) opened as a user's file is
/// (`formats::open` takes a path: the bytes go to a scratch file of this thread) and, when
/// it opens, replayed (`exec::run`: verification and simulation), so everything after the
/// reader sees the content too.
fn archive(b: &[u8]) -> bool {
    let path = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!(
        "fuzz-archive-{:?}.zip",
        std::thread::current().id()
    ));
    std::fs::write(&path, b).unwrap();
    dmdsl::exec::run(&path, &dmdsl::exec::RunOptions::default()).is_ok()
}

/// The SLA control-file standard's hardware description: read, its machine made for the
/// default profile's record and the standard's example's requests checked against it.
fn hardware(b: &[u8]) -> bool {
    use dmdsl::formats::control::hardware::Hardware;
    let Ok(v) = serde_json::from_slice::<serde_json::Value>(b) else {
        return false;
    };
    static MACHINE: std::sync::OnceLock<dmdsl::bundle::Machine> = std::sync::OnceLock::new();
    let m = MACHINE.get_or_init(|| {
        let mut m = dmdsl::bundle::Machine::of(&Profile::default_profile());
        m.projector[0].calibration = None;
        m
    });
    Hardware::from_json(Path::new("fuzz.json"), &v).is_ok_and(|h| {
        let _ = h.machine(m);
        let r = dmdsl::formats::Request {
            layer: 0,
            at: String::new(),
            file: "a.png".into(),
            engine: "visitech".into(),
            wavelength_nm: Some(405),
            offset_um: [2500.0, -1.0],
            gray_correction: true,
            size_px: Some((2560, 1600)),
        };
        let _ = h.check(&[r], true);
        let _ = h.check_projectors(m);
        true
    })
}

/// A JSON input: one of its values replaced (`json_mutated`), or bytes mutated.
fn json_or_bytes(rng: &mut Rng, seed: &[u8], other: &[u8]) -> Vec<u8> {
    match rng.below(4) {
        0 => bytes_mutated(rng, seed, other),
        _ => json_mutated(rng, seed).unwrap_or_else(|| bytes_mutated(rng, seed, other)),
    }
}

/// SL1 archive `bytes` with its display `f` times smaller in pixels: every PNG shrunk,
/// `display_pixels_x`/`_y` divided (rounded up), the rest as PrusaSlicer wrote it. A
/// replay of the fixtures' full displays takes about a second in a debug build; the
/// shrunk ones take milliseconds and reach the same code.
fn shrunk_sl1(bytes: &[u8], f: u32) -> Vec<u8> {
    let entries: Vec<(String, Vec<u8>)> = unzip(bytes)
        .into_iter()
        .map(|(name, b)| {
            if name.ends_with(".png") {
                // Every f-th pixel of every f-th row.
                use image::ImageDecoder;
                let dec = image::codecs::png::PngDecoder::new(std::io::Cursor::new(&b)).unwrap();
                let (w, h) = dec.dimensions();
                let mut px = vec![0; dec.total_bytes() as usize];
                dec.read_image(&mut px).unwrap();
                let (sw, sh) = (w.div_ceil(f), h.div_ceil(f));
                let small: Vec<u8> = (0..sh)
                    .flat_map(|y| (0..sw).map(move |x| (x * f, y * f)))
                    .map(|(x, y)| px[(y * w + x) as usize])
                    .collect();
                let mut out = Vec::new();
                image::ImageEncoder::write_image(
                    image::codecs::png::PngEncoder::new(&mut out),
                    &small,
                    sw,
                    sh,
                    image::ExtendedColorType::L8,
                )
                .unwrap();
                (name, out)
            } else if name == "prusaslicer.ini" {
                let text: String = text(&b)
                    .lines()
                    .map(|l| match l.split_once(" = ") {
                        Some((k, v)) if k.starts_with("display_pixels_") => {
                            format!("{k} = {}\n", v.parse::<u32>().unwrap().div_ceil(f))
                        }
                        _ => format!("{l}\n"),
                    })
                    .collect();
                (name, text.into_bytes())
            } else {
                (name, b)
            }
        })
        .collect();
    rezip(&mut Rng(1), &entries)
}

/// The job archive `bytes` exported as a zipped bundle (`dmdsl export`).
fn as_zipped_bundle(bytes: &[u8]) -> Vec<u8> {
    exported(bytes, dmdsl::formats::Format::DmdjobZip)
}

/// The job archive `bytes` exported as a NanoDLP plate.
fn as_plate(bytes: &[u8]) -> Vec<u8> {
    exported(bytes, dmdsl::formats::Format::Nanodlp)
}

/// The job archive `bytes` exported in `format`.
fn exported(bytes: &[u8], format: dmdsl::formats::Format) -> Vec<u8> {
    // Tests run in parallel threads: a folder of this thread's, the same file names (the
    // manifest records the name).
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("fuzz-seed-{:?}", std::thread::current().id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (from, to) = (
        dir.join("seed.sl1"),
        dir.join(format!("seed{}", format.extension())),
    );
    std::fs::write(&from, bytes).unwrap();
    let job = dmdsl::formats::open(&from).unwrap();
    dmdsl::formats::write(format, &job.manifest, &*job.source, &to, None).unwrap();
    std::fs::read(&to).unwrap()
}

/// How a target makes an input from a seed and another seed.
type Mutator = fn(&mut Rng, &[u8], &[u8]) -> Vec<u8>;

/// A target: name, parser, seeds, how inputs are made, inputs a run by default.
struct Target {
    name: &'static str,
    parse: Parser,
    seeds: Vec<Vec<u8>>,
    make: Mutator,
    runs: u64,
}

/// Inputs per target by default (`DMDSL_FUZZ_RUNS` replaces every target's count).
const RUNS: u64 = 10_000;

/// 1 to 4 byte mutations of the seed.
fn bytes_mutated(rng: &mut Rng, seed: &[u8], other: &[u8]) -> Vec<u8> {
    let mut input = seed.to_vec();
    for _ in 0..1 + rng.below(4) {
        mutate(rng, &mut input, other);
    }
    input
}

/// The targets.
fn targets() -> Vec<Target> {
    let read = |name: &str| std::fs::read(fixture(name)).unwrap();
    let ascii = b"solid t\nfacet normal 0 0 1\n outer loop\n  vertex 0 0 0\n  vertex 10 0 0\n  vertex 0 10 5\n endloop\nendfacet\nfacet normal 0 0 1\n outer loop\n  vertex 10 0 0\n  vertex 10 10 5\n  vertex 0 10 5\n endloop\nendfacet\nendsolid t\n".to_vec();
    let obj_src = b"# box corner\nv 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\nvn 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\ng part\nf 1//1 2//1 3//1\n".to_vec();
    let profiles: Vec<Vec<u8>> = dmdsl::profile::builtin_names()
        .into_iter()
        .map(|n| {
            dmdsl::profile::builtin_source(n)
                .unwrap()
                .as_bytes()
                .to_vec()
        })
        .collect();
    let cal = Profile::default_profile().projector[0]
        .calibration
        .clone()
        .unwrap()
        .to_toml()
        .into_bytes();
    let mut readings_csv = String::from("# zone readings\nx_mm,y_mm,gray,irradiance_mw_cm2\n");
    for (i, g) in [255, 200, 150].into_iter().enumerate() {
        for x in 0..4 {
            for y in 0..3 {
                let e = (1.0 + 0.1 * x as f64 + 0.05 * y as f64) * (1.0 - 0.002 * i as f64);
                readings_csv += &format!(
                    "{},{},{g},{e:.4}\n",
                    2.5 + 5.0 * x as f64,
                    2.5 + 5.0 * y as f64
                );
            }
        }
    }
    let lens = read("lens_table.csv");
    let lens_head: Vec<u8> = text(&lens)
        .lines()
        .take(24)
        .flat_map(|l| format!("{l}\n").into_bytes())
        .collect();
    let job = serde_json::to_vec_pretty(&dmdsl::exec::testutil::two_layer_topdown()).unwrap();
    let plain = |name, parse, seeds| Target {
        name,
        parse,
        seeds,
        make: bytes_mutated,
        runs: RUNS,
    };
    let sl1: Vec<Vec<u8>> = [
        "sl1/cube1.sl1",
        "sl1/cube3mm.sl1",
        "sl1/cylinder_hole.sl1s",
        "sl1/cylinder_slow.sl1",
    ]
    .into_iter()
    .map(|f| shrunk_sl1(&read(f), 8))
    .collect();
    let control = vec![read("control/channel.zip")];
    // The zipped bundle of the fixtures, and two with small masks: shrunk SL1 files
    // exported as zipped bundles.
    let zipped = vec![
        read("zip/cube5.dmdjob.zip"),
        as_zipped_bundle(&sl1[0]),
        as_zipped_bundle(&sl1[2]),
    ];
    // A NanoDLP plate of small masks: the first shrunk SL1 exported as a plate.
    let nanodlp = vec![as_plate(&sl1[0])];
    let all: Vec<Vec<u8>> = [&sl1[..], &control, &zipped, &nanodlp].concat();
    // Each input of an archive target opens and replays a whole job: their counts keep
    // them to a few seconds in all in the test build on 2 cores.
    let zips = |name, seeds, runs| Target {
        name,
        parse: archive,
        seeds,
        make: zip_mutated,
        runs,
    };
    vec![
        plain(
            "stl",
            stl,
            vec![read("cube10.stl"), read("vertex_on_plane.stl"), ascii],
        ),
        plain("obj", obj, vec![obj_src]),
        plain("profile", profile, profiles),
        plain("calibration", calibration, vec![cal]),
        plain("readings", readings, vec![readings_csv.into_bytes()]),
        plain("distortion", distortion, vec![lens_head]),
        plain("manifest", manifest, vec![job]),
        Target {
            runs: 1500,
            ..plain("archive", archive, all)
        },
        zips("sl1", sl1, 150),
        zips("control", control, 800),
        zips("zipped", zipped, 150),
        zips("nanodlp", nanodlp, 150),
        Target {
            make: json_or_bytes,
            runs: 2000,
            ..plain(
                "hardware",
                hardware,
                vec![read("sla_control/hardware_config_example.json")],
            )
        },
    ]
}

/// xorshift64*: small, seeded, no dependency.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545F4914F6CDD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Bytes parsers give meaning to.
const BYTES: &[u8] = b"\x00\xff\x7f\x80-+.eE0123456789,;\n\r\t \"'[]{}=#/\\:x";
/// Numbers at the edges of what parsers and the arithmetic after them meet.
const NUMBERS: &[&str] = &[
    "0",
    "-0",
    "1",
    "-1",
    "1e308",
    "-1e308",
    "1e-308",
    "5e-324",
    "nan",
    "inf",
    "-inf",
    "NaN",
    "4294967295",
    "4294967296",
    "18446744073709551615",
    "-9223372036854775808",
    "1e20",
    "0.0005",
    "63.4765625",
    "99999999999999999999999999999",
    "1e",
    "--1",
    "0x10",
];

/// One mutation of `input` (with `other`, a seed, for splicing).
fn mutate(rng: &mut Rng, input: &mut Vec<u8>, other: &[u8]) {
    let n = input.len();
    match rng.below(10) {
        0 if n > 0 => {
            let i = rng.below(n);
            input[i] ^= 1 << rng.below(8);
        }
        1 if n > 0 => {
            let i = rng.below(n);
            input[i] = BYTES[rng.below(BYTES.len())];
        }
        2 => {
            let i = rng.below(n + 1);
            let k = 1 + rng.below(8);
            for _ in 0..k {
                input.insert(i, BYTES[rng.below(BYTES.len())]);
            }
        }
        3 if n > 0 => {
            let i = rng.below(n);
            let k = 1 + rng.below((n - i).min(64));
            input.drain(i..i + k);
        }
        4 if n > 0 => {
            // Repeat a range (long lines, deep nesting, many records).
            let i = rng.below(n);
            let k = 1 + rng.below((n - i).min(256));
            let piece = input[i..i + k].to_vec();
            for _ in 0..1 + rng.below(16) {
                input.splice(i..i, piece.iter().copied());
            }
        }
        5 if !other.is_empty() => {
            // Splice part of another seed in.
            let i = rng.below(n + 1);
            let j = rng.below(other.len());
            let k = 1 + rng.below((other.len() - j).min(512));
            input.splice(i..i, other[j..j + k].iter().copied());
        }
        6 | 7 => {
            // Replace a number (a run of digits, signs, dots and exponents).
            let starts: Vec<usize> = (0..n)
                .filter(|&i| {
                    input[i].is_ascii_digit() && (i == 0 || !input[i - 1].is_ascii_alphanumeric())
                })
                .collect();
            if !starts.is_empty() {
                let i = starts[rng.below(starts.len())];
                let mut j = i;
                while j < n && (input[j].is_ascii_digit() || b".eE-+".contains(&input[j])) {
                    j += 1;
                }
                input.splice(i..j, NUMBERS[rng.below(NUMBERS.len())].bytes());
            }
        }
        8 if n > 4 && input.len() >= 84 && rng.below(2) == 0 => {
            // Binary STL: a 32-bit field (triangle count or a float) set to an edge value.
            let i = 80 + 4 * rng.below((n - 80) / 4);
            let v: u32 = [
                0,
                1,
                u32::MAX,
                0x7f80_0000,
                0xff80_0000,
                0x7fc0_0000,
                0x0000_0001,
            ][rng.below(7)];
            input[i..i + 4].copy_from_slice(&v.to_le_bytes());
        }
        _ if n > 0 => input.truncate(rng.below(n)),
        _ => input.extend_from_slice(other),
    }
}

/// The entries of a zip (a seed: always readable).
fn unzip(bytes: &[u8]) -> Vec<(String, Vec<u8>)> {
    zip_entries_of(bytes).unwrap()
}

/// A valid zip of `entries` (a name given twice keeps its first entry).
fn rezip(rng: &mut Rng, entries: &[(String, Vec<u8>)]) -> Vec<u8> {
    use std::io::Write;
    let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    for (name, bytes) in entries {
        let method = if rng.below(2) == 0 {
            zip::CompressionMethod::Stored
        } else {
            zip::CompressionMethod::Deflated
        };
        let opts = zip::write::SimpleFileOptions::default().compression_method(method);
        if w.start_file(name.as_str(), opts).is_ok() {
            w.write_all(bytes).unwrap();
        }
    }
    w.finish().unwrap().into_inner()
}

/// Values aimed at the settings' numbers and counts.
const JSON_NUMBERS: &[&str] = &[
    "0",
    "-1",
    "1e308",
    "-1e308",
    "5e-324",
    "18446744073709551615",
    "4294967296",
    "1000000000",
    "0.5",
    "true",
    "null",
    "\"x\"",
    "[]",
    "{}",
];

/// An expression that is deep, long or heavy for the control file's `${...}`.
fn expression(rng: &mut Rng) -> String {
    let k = [10, 1000, 100_000][rng.below(3)];
    match rng.below(6) {
        0 => format!("${{{}1{}}}", "(".repeat(k), ")".repeat(k)),
        1 => format!("${{{}1}}", "-".repeat(k)),
        2 => format!("${{2{}}}", "**2".repeat(k)),
        3 => format!("${{1{}}}", "+1".repeat(k)),
        4 => format!("${{base_ms{}}}", " * base_ms".repeat(k)),
        _ => format!("x{}", "${base_ms}".repeat(k)),
    }
}

/// Every path (object keys and array indices) to a value of `v`.
fn json_paths(
    v: &serde_json::Value,
    at: &mut Vec<serde_json::Value>,
    out: &mut Vec<Vec<serde_json::Value>>,
) {
    out.push(at.clone());
    match v {
        serde_json::Value::Object(m) => {
            for (k, x) in m {
                at.push(k.clone().into());
                json_paths(x, at, out);
                at.pop();
            }
        }
        serde_json::Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                at.push(i.into());
                json_paths(x, at, out);
                at.pop();
            }
        }
        _ => {}
    }
}

/// A JSON entry with one value replaced (an extreme number, an expression, a count),
/// removed or set as a huge `Number of duplications`; other text as bytes.
fn json_mutated(rng: &mut Rng, bytes: &[u8]) -> Option<Vec<u8>> {
    let mut root: serde_json::Value = serde_json::from_slice(bytes).ok()?;
    let mut paths = Vec::new();
    json_paths(&root, &mut Vec::new(), &mut paths);
    let path = &paths[rng.below(paths.len())];
    let (last, parent) = path.split_last()?;
    let mut node = &mut root;
    for p in parent {
        node = match p {
            serde_json::Value::String(k) => node.get_mut(k.as_str())?,
            p => node.get_mut(p.as_u64()? as usize)?,
        };
    }
    let value: serde_json::Value = match rng.below(4) {
        0 => serde_json::from_str(JSON_NUMBERS[rng.below(JSON_NUMBERS.len())]).ok()?,
        1 => expression(rng).into(),
        2 => {
            // A huge count where the file repeats things.
            if let Some(m) = node.as_object_mut() {
                m.insert(
                    "Number of duplications".into(),
                    serde_json::json!([1_000_000_000u64, u64::MAX, 100_000][rng.below(3)]),
                );
            }
            return serde_json::to_vec(&root).ok();
        }
        _ => {
            match (node, last) {
                (serde_json::Value::Object(m), serde_json::Value::String(k)) => {
                    m.remove(k.as_str());
                }
                (serde_json::Value::Array(a), i) => {
                    let i = i.as_u64()? as usize;
                    if i < a.len() {
                        a.remove(i);
                    }
                }
                _ => {}
            }
            return serde_json::to_vec(&root).ok();
        }
    };
    match (node, last) {
        (serde_json::Value::Object(m), serde_json::Value::String(k)) => {
            m.insert(k.clone(), value);
        }
        (serde_json::Value::Array(a), i) => a[i.as_u64()? as usize] = value,
        _ => {}
    }
    serde_json::to_vec_pretty(&root).ok()
}

/// An ini entry (`key = value` lines) with one value replaced by an extreme number or
/// count, or one line removed.
fn ini_mutated(rng: &mut Rng, bytes: &[u8]) -> Vec<u8> {
    let text = String::from_utf8_lossy(bytes);
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    if lines.is_empty() {
        return bytes.to_vec();
    }
    let i = rng.below(lines.len());
    if rng.below(4) == 0 {
        lines.remove(i);
    } else if let Some((k, _)) = lines[i].split_once('=') {
        let v = match rng.below(3) {
            0 => "99999".to_string(),
            1 => ["portrait", "landscape", "slow", "high_viscosity", ""][rng.below(5)].into(),
            _ => NUMBERS[rng.below(NUMBERS.len())].to_string(),
        };
        lines[i] = format!("{k}= {v}");
    }
    (lines.join("\n") + "\n").into_bytes()
}

/// A PNG with its header's size or colour type changed, or its bytes mutated, every
/// chunk's CRC then made right (so the decoder reads what was changed).
fn png_mutated(rng: &mut Rng, bytes: &[u8], other: &[u8]) -> Vec<u8> {
    let mut b = bytes.to_vec();
    if b.len() >= 33 && &b[12..16] == b"IHDR" && rng.below(2) == 0 {
        match rng.below(4) {
            0 | 1 => {
                let at = 16 + 4 * rng.below(2);
                let v: u32 = [0, 1, 65_535, 1 << 20, i32::MAX as u32, u32::MAX][rng.below(6)];
                b[at..at + 4].copy_from_slice(&v.to_be_bytes());
            }
            2 => b[24] = [1, 2, 4, 8, 16][rng.below(5)],
            _ => b[25] = [0, 2, 3, 4, 6, 7][rng.below(6)],
        }
    } else {
        b = bytes_mutated(rng, &b, other);
    }
    // Right every chunk's CRC.
    let mut i = 8;
    while i + 12 <= b.len() {
        let n = u32::from_be_bytes(b[i..i + 4].try_into().unwrap()) as usize;
        if i + 12 + n > b.len() {
            break;
        }
        let crc = crc32fast::hash(&b[i + 4..i + 8 + n]);
        b[i + 8 + n..i + 12 + n].copy_from_slice(&crc.to_be_bytes());
        i += 12 + n;
    }
    b
}

/// One or a few changes to a seed archive, re-zipped validly: an entry's content mutated
/// by its kind (settings text, JSON, PNG, or bytes), an entry dropped, duplicated under
/// another name, renamed, moved, or taken from the other seed.
fn zip_mutated(rng: &mut Rng, seed: &[u8], other: &[u8]) -> Vec<u8> {
    let mut entries = unzip(seed);
    for _ in 0..1 + rng.below(3) {
        if entries.is_empty() {
            break;
        }
        let i = rng.below(entries.len());
        match rng.below(10) {
            0..=5 => {
                let (name, bytes) = &entries[i];
                let lower = name.to_ascii_lowercase();
                let new = if lower.ends_with(".ini") && rng.below(4) != 0 {
                    ini_mutated(rng, bytes)
                } else if lower.ends_with(".json") && rng.below(4) != 0 {
                    json_mutated(rng, bytes).unwrap_or_else(|| bytes_mutated(rng, bytes, bytes))
                } else if lower.ends_with(".png") {
                    png_mutated(rng, bytes, bytes)
                } else {
                    bytes_mutated(rng, bytes, bytes)
                };
                entries[i].1 = new;
            }
            6 => {
                entries.remove(i);
            }
            7 => {
                // Duplicate or rename: a digit changed, a folder added or taken away.
                let (name, bytes) = entries[i].clone();
                let mut n = name.into_bytes();
                match rng.below(3) {
                    0 => {
                        if let Some(d) = n.iter().rposition(u8::is_ascii_digit) {
                            n[d] = b'0' + rng.below(10) as u8;
                        }
                    }
                    1 => n.splice(0..0, b"sub/".iter().copied()).for_each(drop),
                    _ => {
                        if let Some(s) = n.iter().position(|&c| c == b'/') {
                            n.drain(..=s);
                        }
                    }
                }
                let name = String::from_utf8_lossy(&n).into_owned();
                if rng.below(2) == 0 {
                    entries[i].0 = name;
                } else {
                    entries.push((name, bytes));
                }
            }
            8 => {
                let j = rng.below(entries.len());
                entries.swap(i, j);
            }
            _ => {
                let others = unzip(other);
                entries.insert(i, others[rng.below(others.len())].clone());
            }
        }
    }
    rezip(rng, &entries)
}

/// The input running now, for the watchdog and for a panic report.
struct Current {
    target: &'static str,
    index: u64,
    input: Vec<u8>,
}

/// Writes a failing input under `target/` and returns the path.
fn save(c: &Current) -> std::path::PathBuf {
    let p = root().join(format!("target/fuzz-crash-{}-{}.bin", c.target, c.index));
    let _ = std::fs::create_dir_all(p.parent().unwrap());
    let _ = std::fs::write(&p, &c.input);
    p
}

fn env_u64(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

#[test]
fn parsers_never_panic_or_hang_on_mutated_inputs() {
    let runs = std::env::var("DMDSL_FUZZ_RUNS")
        .ok()
        .and_then(|v| v.parse::<u64>().ok());
    let seed = env_u64("DMDSL_FUZZ_SEED", 0x5eed);
    let only = std::env::var("DMDSL_FUZZ_TARGET").ok();
    let current = Arc::new(Mutex::new(None::<Current>));
    let started = Arc::new(AtomicU64::new(0));
    let done = Arc::new(AtomicU64::new(0));
    {
        // Watchdog: one execution running for more than 10 s is a hang.
        let (current, started, done) = (current.clone(), started.clone(), done.clone());
        std::thread::spawn(move || {
            let (mut last, mut since) = (u64::MAX, Instant::now());
            loop {
                std::thread::sleep(Duration::from_millis(500));
                let s = started.load(Ordering::Relaxed);
                if s != last || done.load(Ordering::Relaxed) == s {
                    (last, since) = (s, Instant::now());
                } else if since.elapsed() > Duration::from_secs(10) {
                    if let Ok(c) = current.lock() {
                        if let Some(c) = c.as_ref() {
                            eprintln!(
                                "fuzz: {} input {} hangs; input in {}",
                                c.target,
                                c.index,
                                save(c).display()
                            );
                        }
                    }
                    std::process::abort();
                }
            }
        });
    }
    // The seeds first: a failure to make them is reported as any test failure.
    let targets = targets();
    // A parser's panic is caught and reported below; its message would only flood the
    // output. Panics of the other tests, which run in parallel threads of this binary,
    // still print.
    let fuzzing = std::thread::current().id();
    let previous = Arc::new(std::panic::take_hook());
    {
        let previous = previous.clone();
        std::panic::set_hook(Box::new(move |info| {
            if std::thread::current().id() != fuzzing {
                previous(info);
            }
        }));
    }
    let mut failures = Vec::new();
    for (k, t) in targets.into_iter().enumerate() {
        let Target {
            name,
            parse,
            seeds,
            make,
            ..
        } = t;
        if only.as_deref().is_some_and(|o| o != name) {
            continue;
        }
        let runs = runs.unwrap_or(t.runs);
        let mut rng = Rng(seed ^ (0x9e37_79b9_7f4a_7c15u64.wrapping_mul(k as u64 + 1)));
        let (t0, mut accepted) = (Instant::now(), 0u64);
        for i in 0..runs {
            let seed = &seeds[rng.below(seeds.len())];
            let other = &seeds[rng.below(seeds.len())];
            let mut input = make(&mut rng, seed, other);
            // Some inputs are the seeds themselves or no mutation at all.
            if i < seeds.len() as u64 {
                input = seeds[i as usize].clone();
            }
            *current.lock().unwrap() = Some(Current {
                target: name,
                index: i,
                input: input.clone(),
            });
            started.fetch_add(1, Ordering::Relaxed);
            let r = catch_unwind(AssertUnwindSafe(|| parse(&input)));
            done.fetch_add(1, Ordering::Relaxed);
            match r {
                Ok(ok) => accepted += ok as u64,
                Err(e) => {
                    let msg = e
                        .downcast_ref::<String>()
                        .cloned()
                        .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
                        .unwrap_or_default();
                    let c = current.lock().unwrap();
                    let path = save(c.as_ref().unwrap());
                    failures.push(format!(
                        "{name} input {i} panicked: {msg} (input in {})",
                        path.display()
                    ));
                    if failures.len() >= 10 {
                        break;
                    }
                }
            }
        }
        eprintln!(
            "fuzz: {name}: {runs} inputs in {:.1} s, {accepted} accepted",
            t0.elapsed().as_secs_f64()
        );
    }
    std::panic::set_hook(Box::new(move |info| previous(info)));
    *current.lock().unwrap() = None;
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn regression_inputs_are_refused_cleanly() {
    // Inputs that once crashed a parser, named TARGET-what.EXT: each must now give an
    // error (or parse), never panic. An archive (any of the archive targets) is opened
    // and replayed as the `archive` target does.
    let dir = root().join("fixtures/fuzz");
    let by_name: Vec<(&str, Parser)> = targets().into_iter().map(|t| (t.name, t.parse)).collect();
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_string_lossy().into_owned();
        let target = name.split('-').next().unwrap();
        let Some((_, parse)) = by_name.iter().find(|(t, _)| *t == target) else {
            continue;
        };
        let input = std::fs::read(&p).unwrap();
        assert!(
            catch_unwind(AssertUnwindSafe(|| parse(&input))).is_ok(),
            "{name} panics"
        );
        n += 1;
    }
    assert!(n > 0, "no regression inputs in {}", dir.display());
}
