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
//! CI runs 10⁴ inputs per target (seconds). A long run (docs/BENCHMARKS.md, "Fuzzing"):
//!
//! ```sh
//! DMDSL_FUZZ_RUNS=1000000 cargo test --release --test it fuzz -- --nocapture
//! ```
//!
//! `DMDSL_FUZZ_SEED` changes the seed; `DMDSL_FUZZ_TARGET` runs one target. Every crash
//! found becomes a regression input under `fixtures/fuzz/` (replayed by
//! `regression_inputs_are_refused_cleanly`).

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

/// The targets: name, parser, seeds.
fn targets() -> Vec<(&'static str, Parser, Vec<Vec<u8>>)> {
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
    vec![
        (
            "stl",
            stl as Parser,
            vec![read("cube10.stl"), read("vertex_on_plane.stl"), ascii],
        ),
        ("obj", obj, vec![obj_src]),
        ("profile", profile, profiles),
        ("calibration", calibration, vec![cal]),
        ("readings", readings, vec![readings_csv.into_bytes()]),
        ("distortion", distortion, vec![lens_head]),
        ("manifest", manifest, vec![job]),
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
    let runs = env_u64("DMDSL_FUZZ_RUNS", 10_000);
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
    for (k, (name, parse, seeds)) in targets().into_iter().enumerate() {
        if only.as_deref().is_some_and(|o| o != name) {
            continue;
        }
        let mut rng = Rng(seed ^ (0x9e37_79b9_7f4a_7c15u64.wrapping_mul(k as u64 + 1)));
        let (t0, mut accepted) = (Instant::now(), 0u64);
        for i in 0..runs {
            let mut input = seeds[rng.below(seeds.len())].clone();
            let other = &seeds[rng.below(seeds.len())];
            for _ in 0..1 + rng.below(4) {
                mutate(&mut rng, &mut input, other);
            }
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
    // error (or parse), never panic.
    let dir = root().join("fixtures/fuzz");
    let by_name: Vec<(&str, Parser)> = targets().into_iter().map(|(n, p, _)| (n, p)).collect();
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
