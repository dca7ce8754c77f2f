//! Runs NanoTrack verifier passes in a loop, for instruction counts under callgrind: the
//! difference between two runs with different pass counts is the cost of the extra passes
//! (plan building and the verifier's start-up check cancel out).
//!
//! `verifier_passes <stage> <passes> [target side px]`, stage one of
//! - `search`: score-only search passes (`search_above` with an unreachable bar: crop,
//!   backbone 255×255, the head's classification branch), as the drift check runs them;
//! - `template`: template passes (`set_template`: crop, backbone 127×127);
//! - `nodes`: as `search`, then the search passes' time node by node (backbone at 255 px and
//!   the head's classification branch, each node's mean over the passes, largest first; the
//!   per-node table of `docs/benchmarks.md`). Wall-clock times: on a shared VM compare
//!   shares within one run, not runs.
//!
//! The frame is a synthetic textured 1280×720 RGB image; the target (default 20 px, so a
//! search region of about 80 px, upsampled) sits at its centre.
//!
//! ```sh
//! cargo build --release -p bevt_core --features bench --example verifier_passes
//! valgrind --tool=callgrind --callgrind-out-file=cg.12 target/release/examples/verifier_passes search 12
//! valgrind --tool=callgrind --callgrind-out-file=cg.2 target/release/examples/verifier_passes search 2
//! ```
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use bevt_core::image::{Frame, PixelFormat};
use bevt_core::redetect::nano::{NanoVerifier, NetTimes};
use bevt_core::redetect::{context_side, Verifier};
use bevt_core::Point2;
use std::hint::black_box;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: verifier_passes search|template|nodes <passes> [target side px]";
    let stage = args.get(1).expect(usage).clone();
    let passes: usize = args.get(2).expect(usage).parse().expect(usage);
    let target: f32 = args.get(3).map_or(20.0, |s| s.parse().expect(usage));
    let (w, h) = (1280usize, 720usize);
    let data: Vec<u8> = (0..w * h * 3)
        .map(|i| {
            let (p, c) = (i / 3, i % 3);
            let (x, y) = (p % w, p / w);
            ((x * 7 + y * 13 + c * 50) ^ (x * y / 17)) as u8
        })
        .collect();
    let frame = Frame::packed(&data, w, h, PixelFormat::Rgb8).unwrap();
    let center = Point2 { x: 640.3, y: 360.7 };
    let mut v = NanoVerifier::new("", "").unwrap();
    v.set_template(&frame, center, target, target).unwrap();
    let side = 2.0 * context_side(target, target);
    // The networks' nodes timed from here: the passes only.
    v.time_nodes(stage == "nodes");
    for i in 0..passes {
        match stage.as_str() {
            "search" | "nodes" => {
                let c = Point2 {
                    x: center.x + i as f32,
                    y: center.y,
                };
                black_box(v.search_above(&frame, c, side, f32::INFINITY).unwrap());
            }
            "template" => {
                v.set_template(&frame, center, target + i as f32 * 0.01, target)
                    .unwrap();
            }
            _ => panic!("{usage}"),
        }
    }
    if stage == "nodes" {
        print_nodes(&v.node_times(), passes);
    }
}

/// The search passes' nodes (backbone at 255 px, the head's classification branch): each
/// node's mean time a pass, largest first, with its share of the pass and the total.
fn print_nodes(nets: &[NetTimes], passes: usize) {
    let mut rows: Vec<(f64, String)> = Vec::new();
    for net in nets
        .iter()
        .filter(|n| n.name == "search" || n.name == "cls")
    {
        for (label, ns) in &net.nodes {
            let us = *ns as f64 / 1e3 / passes.max(1) as f64;
            rows.push((us, format!("{}: {label}", net.name)));
        }
    }
    let total: f64 = rows.iter().map(|r| r.0).sum();
    rows.sort_by(|a, b| b.0.total_cmp(&a.0));
    // Written, not printed: a closed pipe (`… | head`) ends the table instead of panicking.
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    let _ = writeln!(
        out,
        "{passes} search passes, {total:.1} µs a pass in the networks' nodes"
    );
    for (us, what) in &rows {
        let share = 100.0 * us / total.max(1e-9);
        if writeln!(out, "{us:8.1} µs {share:5.1} %  {what}").is_err() {
            break;
        }
    }
}
