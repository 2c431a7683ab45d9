//! `sextant-fuzz TARGET [--seconds S] [--iterations N] [--seed X]`: a stable-Rust mutation fuzzer
//! for the targets of the library (no coverage feedback; libFuzzer needs nightly). It starts
//! from a seed corpus (the shipped configuration and scenarios, a recording written by the
//! daemon's recorder, well-formed sample streams), applies random mutations (bit flips,
//! interesting bytes and floats, inserted/deleted/duplicated ranges, truncation, splicing of two
//! inputs, TOML value replacement) and runs the target on each. A panic is caught, the input
//! saved to `fuzz/artifacts/TARGET-N.bin`, and the run ends with exit code 1. The input being
//! run is also kept in `fuzz/artifacts/TARGET-current.bin`, so that an abort (e.g. an
//! allocation failure, which cannot be caught) leaves its reproducer behind.
//! Reproduce one input: `sextant-fuzz TARGET --input FILE`.

use sextant_fuzz::{TARGETS, repo_root, run_target};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// xorshift64*: deterministic, dependency-free.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next() % n as u64) as usize
        }
    }
}

const INTERESTING_F64: [f64; 10] = [
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    0.0,
    -0.0,
    f64::MAX,
    f64::MIN_POSITIVE,
    1e300,
    -1.0,
    6_378_137.0,
];
const TOML_VALUES: [&str; 14] = [
    "nan",
    "inf",
    "-inf",
    "-1",
    "0",
    "1e308",
    "\"\"",
    "[]",
    "{}",
    "true",
    "1979-01-01T00:00:00",
    "-9223372036854775808",
    "[[]]",
    "\"x\"",
];

fn mutate(rng: &mut Rng, input: &[u8], corpus: &[Vec<u8>]) -> Vec<u8> {
    let mut v = input.to_vec();
    let rounds = 1 + rng.below(4);
    for _ in 0..rounds {
        let n = v.len();
        match rng.below(9) {
            0 if n > 0 => {
                let i = rng.below(n);
                v[i] ^= 1 << rng.below(8);
            }
            1 if n > 0 => {
                let i = rng.below(n);
                v[i] = [0u8, 0xff, 0x7f, 0x80, b'=', b'[', b'"', b'\n'][rng.below(8)];
            }
            2 if n >= 8 => {
                let i = rng.below(n - 7);
                let x = INTERESTING_F64[rng.below(INTERESTING_F64.len())];
                v[i..i + 8].copy_from_slice(&x.to_le_bytes());
            }
            3 if n > 0 => {
                let a = rng.below(n);
                let b = (a + 1 + rng.below(64)).min(n);
                v.drain(a..b);
            }
            4 if n > 0 => {
                let a = rng.below(n);
                let b = (a + 1 + rng.below(64)).min(n);
                let piece = v[a..b].to_vec();
                let at = rng.below(n);
                v.splice(at..at, piece);
            }
            5 => v.truncate(rng.below(n + 1)),
            6 if !corpus.is_empty() => {
                let other = &corpus[rng.below(corpus.len())];
                let cut = rng.below(n + 1);
                let from = rng.below(other.len() + 1);
                v.truncate(cut);
                v.extend_from_slice(&other[from..]);
            }
            7 => {
                // Replace a TOML value (text after a '=' up to the end of its line).
                let eqs: Vec<usize> = v
                    .iter()
                    .enumerate()
                    .filter(|(_, c)| **c == b'=')
                    .map(|(i, _)| i)
                    .collect();
                if !eqs.is_empty() {
                    let at = eqs[rng.below(eqs.len())] + 1;
                    let end = v[at..]
                        .iter()
                        .position(|c| *c == b'\n')
                        .map_or(v.len(), |p| at + p);
                    let val = format!(" {}", TOML_VALUES[rng.below(TOML_VALUES.len())]);
                    v.splice(at..end, val.into_bytes());
                }
            }
            _ => {
                let extra: Vec<u8> = (0..1 + rng.below(32)).map(|_| rng.next() as u8).collect();
                let at = rng.below(n + 1);
                v.splice(at..at, extra);
            }
        }
    }
    v
}

fn seed_corpus(target: &str) -> Vec<Vec<u8>> {
    let root = repo_root();
    let read = |p: &str| std::fs::read(root.join(p)).unwrap_or_default();
    match target {
        "system_config" => vec![read("config/sextant.toml"), read("config/filter.toml")],
        "scenario" => std::fs::read_dir(root.join("config/scenarios"))
            .map(|rd| {
                rd.flatten()
                    .filter(|e| e.path().extension().is_some_and(|x| x == "toml"))
                    .filter_map(|e| std::fs::read(e.path()).ok())
                    .collect()
            })
            .unwrap_or_default(),
        "recording" => vec![small_recording()],
        _ => {
            // Well-formed continuation messages of each type: kind byte (odd = plausible
            // header), 24 header bytes, then plausible values.
            let mut out = Vec::new();
            for kind in 0..5u8 {
                let mut m = vec![(kind << 1) | 1];
                m.extend_from_slice(&[0u8; 24]);
                let vals: &[f64] = match kind {
                    0 => &[0.005, 2e-7, 0.0, -3e-7, 0.0, 0.0, -0.049, 0.0, 0.0],
                    1 => &[1.0, 0.0, 0.0, 0.0, 2.4e-5, 2e-4, 0.0, 1.0],
                    2 => &[1.0, 8.0, 2.846e6, 2.193e6, 5.24e6, 0.0, 0.0, 0.0, 4.0],
                    3 => &[0.05, 0.5, 10.0],
                    _ => &[99_000.0, 15.0],
                };
                for x in vals {
                    m.extend_from_slice(&x.to_le_bytes());
                }
                out.push(m);
            }
            let all: Vec<u8> = out.concat();
            out.push(all);
            out
        }
    }
}

/// A small recording written by the daemon's recorder.
fn small_recording() -> Vec<u8> {
    use sextant_daemons::recorder::{Record, Recorder, RecorderOptions};
    let path = std::env::temp_dir().join(format!("sextant-fuzz-seed-{}.mcap", std::process::id()));
    let Ok(rec) = Recorder::start(
        &path,
        &RecorderOptions {
            chunk_size_bytes: 4096,
            ..Default::default()
        },
    ) else {
        return Vec::new();
    };
    for k in 0..200u64 {
        let mut s = msgs::ImuSample::default();
        s.header.seq = k + 1;
        s.header.time_ns = 1_398_556_800_000_000_000 + k as i64 * 5_000_000;
        s.dt_s = 0.005;
        rec.record(Record::Imu(s), k);
        if k % 10 == 0 {
            let mut n = msgs::NavSolution::default();
            n.header = s.header;
            n.q_ned_body = [1.0, 0.0, 0.0, 0.0];
            rec.record(Record::Nav(n), k);
        }
    }
    let _ = rec.finish();
    let bytes = std::fs::read(&path).unwrap_or_default();
    let _ = std::fs::remove_file(&path);
    bytes
}

struct Args {
    target: String,
    seconds: f64,
    iterations: u64,
    seed: u64,
    input: Option<PathBuf>,
}

fn parse_args() -> Result<Args, String> {
    let mut it = std::env::args().skip(1);
    let target = it.next().ok_or(format!(
        "usage: sextant-fuzz TARGET [--seconds S] [--iterations N] [--seed X] [--input FILE]; \
         targets: {}",
        TARGETS.join(", ")
    ))?;
    let mut a = Args {
        target,
        seconds: 60.0,
        iterations: u64::MAX,
        seed: 0x5e47_a17,
        input: None,
    };
    while let Some(k) = it.next() {
        let v = it.next().ok_or(format!("{k} needs a value"))?;
        match k.as_str() {
            "--seconds" => a.seconds = v.parse().map_err(|_| format!("bad --seconds {v}"))?,
            "--iterations" => {
                a.iterations = v.parse().map_err(|_| format!("bad --iterations {v}"))?
            }
            "--seed" => a.seed = v.parse().map_err(|_| format!("bad --seed {v}"))?,
            "--input" => a.input = Some(PathBuf::from(v)),
            other => return Err(format!("unknown option {other}")),
        }
    }
    if !TARGETS.contains(&a.target.as_str()) {
        return Err(format!(
            "unknown target {}; targets: {}",
            a.target,
            TARGETS.join(", ")
        ));
    }
    Ok(a)
}

fn main() {
    let a = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    if let Some(p) = &a.input {
        let data = std::fs::read(p).unwrap_or_else(|e| {
            eprintln!("{}: {e}", p.display());
            std::process::exit(2)
        });
        run_target(&a.target, &data);
        println!("{}: no failure on {}", a.target, p.display());
        return;
    }
    let artifacts = repo_root().join("fuzz/artifacts");
    let _ = std::fs::create_dir_all(&artifacts);
    let current = artifacts.join(format!("{}-current.bin", a.target));
    // Quiet panics: they are reported once per failing input below.
    std::panic::set_hook(Box::new(|_| {}));
    let mut corpus = seed_corpus(&a.target);
    if corpus.is_empty() {
        corpus.push(Vec::new());
    }
    let mut rng = Rng(a.seed | 1);
    let t0 = Instant::now();
    let limit = Duration::from_secs_f64(a.seconds);
    let (mut runs, mut failures) = (0u64, 0u64);
    while runs < a.iterations && t0.elapsed() < limit {
        let base = &corpus[rng.below(corpus.len())];
        let input = if runs < corpus.len() as u64 {
            corpus[runs as usize].clone()
        } else {
            mutate(&mut rng, base, &corpus)
        };
        let _ = std::fs::write(&current, &input);
        let target = a.target.clone();
        let data = input.clone();
        let r = std::panic::catch_unwind(move || run_target(&target, &data));
        runs += 1;
        if let Err(p) = r {
            failures += 1;
            let msg = p
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            let file = artifacts.join(format!("{}-{failures}.bin", a.target));
            let _ = std::fs::write(&file, &input);
            eprintln!(
                "{}: panic `{msg}`; input saved to {}",
                a.target,
                file.display()
            );
        } else if corpus.len() < 256 && rng.below(50) == 0 {
            // Keep some mutants as further bases (no coverage feedback: a random sample).
            corpus.push(input);
        }
    }
    let _ = std::fs::remove_file(&current);
    println!(
        "{}: {runs} inputs in {:.1} s ({:.0}/s), {failures} failures",
        a.target,
        t0.elapsed().as_secs_f64(),
        runs as f64 / t0.elapsed().as_secs_f64()
    );
    if failures > 0 {
        std::process::exit(1);
    }
}
