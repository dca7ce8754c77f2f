//! Issue 11: the fuzz targets of `bevt_tests::fuzz` on stable, bounded. For each target:
//! every saved crash input in `fuzz/regressions/<target>/` is replayed (each became a
//! regression when it was fixed), then the seeds and a fixed number of deterministic
//! mutations of them run through the body. libFuzzer (`fuzz/`, nightly) explores the same
//! bodies for real; this keeps them running in CI and on every `cargo test`.
//!
//! `BEVT_FUZZ_ITERS` sets the mutations per target (default 3000); `BEVT_FUZZ_SEED_DIR`
//! writes the seeds out as libFuzzer corpora (`<dir>/<target>/seed-N`).

use bevt_tests::fuzz::{Target, TARGETS};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Mutations per target by default.
const DEFAULT_ITERS: usize = 3000;
/// Wall-clock cap per target (the machine may be loaded): a budget, not a measurement.
const TIME_CAP: Duration = Duration::from_secs(15);
/// Largest mutated input.
const MAX_LEN: usize = 4096;

/// xorshift64*: deterministic, no dependency.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Bytes fuzzers like: boundaries of integers, syntax of the text formats.
const INTERESTING: &[&[u8]] = &[
    &[0xff, 0xff, 0xff, 0xff],
    &[0xff, 0xff, 0xff, 0x7f],
    &[0, 0, 0, 0x80],
    &[0],
    b"NaN",
    b"-1",
    b"1e309",
    b"18446744073709551616",
    b"\n",
    b":=",
    b"[",
    b"{",
    b"\"",
    b": ",
    b"&a *a",
    b"!!binary",
    b",",
];

/// One random edit of `s`: flip, set, insert, delete, duplicate, truncate, splice in an
/// interesting token or part of another seed.
fn mutate(rng: &mut Rng, s: &mut Vec<u8>, other: &[u8]) {
    let n = s.len();
    match rng.below(8) {
        0 if n > 0 => {
            let i = rng.below(n);
            s[i] ^= 1 << rng.below(8);
        }
        1 if n > 0 => {
            let i = rng.below(n);
            s[i] = rng.next() as u8;
        }
        2 => {
            let i = rng.below(n + 1);
            s.insert(i, rng.next() as u8);
        }
        3 if n > 0 => {
            let i = rng.below(n);
            let k = 1 + rng.below((n - i).min(16));
            s.drain(i..i + k);
        }
        4 if n > 0 => {
            let i = rng.below(n);
            let k = 1 + rng.below((n - i).min(64));
            let chunk = s[i..i + k].to_vec();
            let j = rng.below(n + 1);
            s.splice(j..j, chunk);
        }
        5 if n > 0 => s.truncate(rng.below(n)),
        6 => {
            let t = INTERESTING[rng.below(INTERESTING.len())];
            let i = rng.below(n + 1);
            if rng.below(2) == 0 || i + t.len() > n {
                s.splice(i..i, t.iter().copied());
            } else {
                s[i..i + t.len()].copy_from_slice(t);
            }
        }
        _ if !other.is_empty() => {
            let i = rng.below(other.len());
            let k = 1 + rng.below((other.len() - i).min(64));
            let j = rng.below(n + 1);
            s.splice(j..j, other[i..i + k].iter().copied());
        }
        _ => s.push(rng.next() as u8),
    }
    s.truncate(MAX_LEN);
}

fn regressions_dir(t: &Target) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz/regressions")
        .join(t.name)
}

/// Runs `t`: regressions, seeds, then mutations; returns the inputs executed.
#[allow(clippy::panic)] // a test helper: a panicking input fails the calling test
fn run_target(t: &Target) -> usize {
    let mut executed = 0;
    if let Ok(dir) = std::fs::read_dir(regressions_dir(t)) {
        let mut files: Vec<PathBuf> = dir.flatten().map(|e| e.path()).collect();
        files.sort();
        for f in files {
            let data = std::fs::read(&f).expect("read a regression input");
            eprintln!("{}: replaying {}", t.name, f.display());
            (t.run)(&data);
            executed += 1;
        }
    }
    let seeds = (t.seeds)();
    assert!(!seeds.is_empty(), "{} has no seed", t.name);
    if let Ok(dir) = std::env::var("BEVT_FUZZ_SEED_DIR") {
        let d = PathBuf::from(dir).join(t.name);
        std::fs::create_dir_all(&d).expect("seed folder");
        for (i, s) in seeds.iter().enumerate() {
            std::fs::write(d.join(format!("seed-{i}")), s).expect("write a seed");
        }
    }
    for s in &seeds {
        (t.run)(s);
        executed += 1;
    }
    let iters = std::env::var("BEVT_FUZZ_ITERS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(DEFAULT_ITERS);
    // A fixed seed per target: a failure reproduces with the same command.
    let mut rng =
        Rng(0x9e37_79b9_7f4a_7c15 ^ t.name.len() as u64 ^ (t.name.as_bytes()[0] as u64) << 32);
    let start = Instant::now();
    for i in 0..iters {
        if start.elapsed() > TIME_CAP {
            break;
        }
        let mut input = seeds[i % seeds.len()].clone();
        let other = &seeds[rng.below(seeds.len())];
        for _ in 0..1 + rng.below(6) {
            mutate(&mut rng, &mut input, other);
        }
        let r = std::panic::catch_unwind(|| (t.run)(&input));
        if r.is_err() {
            let keep = std::env::temp_dir().join(format!("bevt_fuzz_crash_{}_{i}", t.name));
            let _ = std::fs::write(&keep, &input);
            panic!(
                "{}: input {i} panicked; saved to {} (copy it to fuzz/regressions/{}/ with the fix)",
                t.name,
                keep.display(),
                t.name
            );
        }
        executed += 1;
    }
    executed
}

macro_rules! fuzz_tests {
    ($($name:ident),* $(,)?) => {
        $(
            #[test]
            fn $name() {
                let t = TARGETS
                    .iter()
                    .find(|t| t.name == stringify!($name))
                    .expect("a target of this name");
                let n = run_target(t);
                eprintln!("{}: {n} inputs", t.name);
                assert!(n > 0);
            }
        )*
    };
}

fuzz_tests!(
    image_raw,
    image_compressed,
    cdr_messages,
    node_requests,
    param_requests,
    ros_args,
    params_file,
    tracker_config,
    dataset_manifest,
    annotation,
    bag_reader,
);

/// Every target has a test above (a new target without one fails here).
#[test]
fn every_target_is_run() {
    let names = [
        "image_raw",
        "image_compressed",
        "cdr_messages",
        "node_requests",
        "param_requests",
        "ros_args",
        "params_file",
        "tracker_config",
        "dataset_manifest",
        "annotation",
        "bag_reader",
    ];
    for t in TARGETS {
        assert!(names.contains(&t.name), "{} has no test", t.name);
    }
}

/// The `bag_reader` seeds reach the messages: every seed (none, zstd, lz4 chunks, and no
/// chunks) yields its two 8×8 frames, decoded as `bevt replay` does.
#[test]
fn bag_reader_seeds_are_read_and_decoded() {
    use bevt_node::tool::bag::{read_mcap_bytes, BagLimits};
    let t = TARGETS
        .iter()
        .find(|t| t.name == "bag_reader")
        .expect("the bag_reader target");
    let seeds = (t.seeds)();
    assert_eq!(seeds.len(), 4);
    for (i, s) in seeds.iter().enumerate() {
        let mut buf = bevt_node::convert::PixelBuffer::default();
        let limits = bevt_node::convert::ImageLimits::default();
        let mut frames = Vec::new();
        let n = read_mcap_bytes(s, "/camera/image_raw", BagLimits::default(), |m| {
            frames.push(bevt_node::tool::replay::decode_message(
                &m, &mut buf, &limits,
            ));
            std::ops::ControlFlow::Continue(())
        })
        .unwrap_or_else(|e| panic!("seed {i}: {e}"));
        assert_eq!(n, 2, "seed {i}");
        assert_eq!(frames, vec![Ok((8, 8)), Ok((8, 8))], "seed {i}");
    }
}
