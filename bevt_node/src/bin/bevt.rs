//! `bevt`: evaluate, run and demonstrate the BEVT tracker from the command line.
//!
//! - `bevt demo`: track a synthetic sequence generated in memory (no files needed).
//! - `bevt eval`: one-pass evaluation on a UAV123-style dataset, with plots and comparisons.
//! - `bevt select`: leave-one-sequence-out selection over finished `bevt eval` folders.
//! - `bevt track`: track through a folder of frames from an initial box.
//! - `bevt replay`: replay a recorded camera topic (rosbag2) through the node logic, MCAP out.

use anyhow::{bail, Context, Result};
use bevt_core::eval::metrics::score_sequence;
use bevt_core::eval::perturb::Perturbation;
use bevt_core::eval::synth::SynthParams;
use bevt_core::{BBox, BevtTracker, Frame, PixelFormat, Tracker};
use bevt_node::node::node_params::launch_from_args;
use bevt_node::params::load_config;
use bevt_node::tool::dataset::{format_annotation_row, image_files, parse_annotation};
use bevt_node::tool::eval::{parse_compare, EvalOptions};
use bevt_node::tool::replay::{
    decode_only, parse_box as parse_replay_box, parse_reinit_file, parse_time_ns, InitAt,
    ReplayOptions, ReplaySummary,
};
use bevt_node::tool::runner::{decode_ahead, track_feed, Decode};
use bevt_node::tool::select::{render, select, Criterion, SelectOptions};
use clap::{Args, Parser, Subcommand};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

#[derive(Parser)]
#[command(
    name = "bevt",
    version,
    about = "BEVT visual object tracker: offline evaluation, tracking and replay tools",
    after_help = "Run `bevt <COMMAND> --help` for a command's options. Boxes are `x,y,w,h` in \
                  pixels: top-left corner, width, height. Exit codes: 0 success; 1 error (bad \
                  value, unreadable input); 2 malformed command line or, for eval and track, \
                  a sequence or frame that failed (the partial result is kept)."
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Args, Clone)]
struct ConfigArgs {
    /// Tracker configuration (YAML); default: the embedded config/bevt.yaml.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Override a configuration key, e.g. `--set admm.penalty=none` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Worker threads for one frame's scales (sets the configuration's `threads`; default 1).
    #[arg(long, value_name = "N")]
    threads: Option<usize>,
}

#[derive(Subcommand)]
enum Cmd {
    /// Track a synthetic sequence generated in memory and score it against its exact truth.
    ///
    /// No files, camera or ROS needed: a textured target moves and grows over a moving
    /// background. Every N-th frame prints the tracked box, the true box (x y w h, pixels,
    /// 0-based), the centre error and the tracker's consensus; the end prints precision at
    /// 20 px, success AUC and the tracking speed.
    Demo {
        #[command(flatten)]
        cfg: ConfigArgs,
        /// Number of frames to generate (2 to 100000).
        #[arg(long, value_name = "N", default_value_t = 150)]
        frames: usize,
        /// Frame width, pixels (64 to 4096).
        #[arg(long, value_name = "PX", default_value_t = 640)]
        width: usize,
        /// Frame height, pixels (64 to 4096).
        #[arg(long, value_name = "PX", default_value_t = 360)]
        height: usize,
        /// Print a line every N frames (frames are numbered from 1; the last is always printed).
        #[arg(long, value_name = "N", default_value_t = 15)]
        every: usize,
    },
    /// One-pass evaluation on a dataset: precision, success AUC and speed per sequence,
    /// optionally compared with other trackers' results and plotted.
    ///
    /// Each sequence is tracked once from its first annotated box, without re-initialisation
    /// (OPE, as in UAV123/OTB). Written to --out: `<sequence>.txt` (one `x,y,w,h` box per
    /// frame, 1-based like the annotations), `summary.json` (updated after every sequence),
    /// and with --plots `precision.png` and `success.png`. Exit code 2 when a sequence failed
    /// (unreadable frame or annotation): the others are still scored.
    Eval {
        #[command(flatten)]
        cfg: ConfigArgs,
        /// Dataset root: a folder with `sequences.json` (manifest), a UAV123 download
        /// (`anno/` and `data_seq/`), or OTB-style `<sequence>/img/` +
        /// `<sequence>/groundtruth_rect.txt`.
        #[arg(long, value_name = "DIR")]
        dataset: PathBuf,
        /// Output folder (created if missing) for result files, summary.json and plots.
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// Comma-separated sequence names (default: all).
        #[arg(long, value_name = "NAMES", value_delimiter = ',')]
        sequences: Vec<String>,
        /// Write precision.png and success.png (curves of every tracker, legend by score).
        #[arg(long)]
        plots: bool,
        /// Compare with another tracker: NAME=DIR, DIR holding its `<sequence>.txt` boxes
        /// (one `x,y,w,h` row per frame, 1-based like the annotations). Repeatable.
        #[arg(long, value_name = "NAME=DIR")]
        compare: Vec<String>,
        /// Name of this run in tables and plots.
        #[arg(long, default_value = "BEVT-rs")]
        name: String,
        /// Transform every frame and its ground truth alike, deterministically:
        /// `key=value,...` with tiny=F (downscale, 0.1..=1), zoom=Z, aspect=A (1..=3),
        /// shake=PX (0..=64), blur=SIGMA (0..=8), light=G (1..=4), gamma=G (1..=3),
        /// lookalike=K (a copy of the initial target K widths beside it, 1.5..=8),
        /// period=FRAMES (default 40), seed=N. E.g. `--perturb shake=8,seed=1`.
        #[arg(long, value_name = "SPEC")]
        perturb: Option<String>,
        /// Where frames are decoded: `ahead` on a thread beside the tracker (the shortest
        /// run), or `inline` on the tracking thread between its timed calls, so that nothing
        /// else runs while it is timed, as the peers' harnesses decode (speed comparisons:
        /// `scripts/speed-rounds.sh`). Only init and update are timed either way.
        #[arg(long, value_name = "WHERE", default_value = "ahead")]
        decode: Decode,
    },
    /// Leave-one-sequence-out selection over finished `bevt eval --out` folders.
    ///
    /// For each sequence held out, the variant with the best mean criterion over the other
    /// sequences is chosen and scored on it. Prints every fold, the pooled LOSO mean beside
    /// each variant's full-set mean, and the per-sequence scores (Markdown). List the
    /// incumbent first: ties go to the earlier variant.
    Select {
        /// Candidates: NAME=DIR, DIR a `bevt eval --out` folder (its summary.json is read).
        #[arg(value_name = "NAME=DIR", required = true)]
        variants: Vec<String>,
        /// What to maximise: auc, p20 or sr50.
        #[arg(long, default_value = "auc")]
        criterion: String,
        /// Comma-separated sequences to use (default: all of the first variant's, which
        /// every variant must have).
        #[arg(long, value_name = "NAMES", value_delimiter = ',')]
        sequences: Vec<String>,
    },
    /// Track a target through a folder of frames from an initial box, one box per frame.
    ///
    /// Boxes in and out are in the UAV123/OTB annotation convention: `x,y,w,h` in pixels,
    /// top-left corner 1-based (the image's top-left pixel is 1,1). Exit code 2 when a frame
    /// cannot be read or tracked: the boxes before it are still written.
    Track {
        #[command(flatten)]
        cfg: ConfigArgs,
        /// Folder of frames (jpg, jpeg, png or bmp), tracked in file-name order.
        #[arg(long, value_name = "DIR")]
        images: PathBuf,
        /// Initial box on the first frame: `x,y,w,h`, pixels, 1-based (e.g. `120,80,40,30`).
        #[arg(long, value_name = "X,Y,W,H")]
        init: String,
        /// Result file: one `x,y,w,h` row per frame, 1-based like --init (the first row is
        /// the initial box); default: standard output.
        #[arg(long, value_name = "FILE")]
        out: Option<PathBuf>,
    },
    /// Replay a recorded camera topic (rosbag2 directory, .mcap or .db3) through the node
    /// logic and write the track as MCAP (Foxglove) and CSV.
    Replay(ReplayArgs),
}

#[derive(Args)]
struct ReplayArgs {
    #[command(flatten)]
    cfg: ConfigArgs,
    /// Bag directory (metadata.yaml + .mcap or .db3), or a bare .mcap / .db3 file.
    #[arg(long)]
    bag: PathBuf,
    /// Image topic (sensor_msgs/msg/Image or sensor_msgs/msg/CompressedImage).
    #[arg(long)]
    topic: String,
    /// Initial box `x,y,w,h`, image pixels from 0 (as the node's reinit service; the CSV
    /// is 0-based too). Annotation files (groundtruth_rect.txt) and `bevt eval`'s results
    /// count from 1: subtract 1 from their x and y, or the replay starts 1 px off.
    #[arg(long)]
    init: String,
    /// Apply the initial box on the N-th message of the topic (from 1, as `bevt track`'s
    /// frames; default 1).
    #[arg(long, value_name = "N", conflicts_with = "init_time")]
    init_frame: Option<u64>,
    /// Apply the initial box on the first frame stamped at or after T (seconds).
    #[arg(long, value_name = "T")]
    init_time: Option<String>,
    /// Output MCAP: /detections, /track_status, /track_annotations.
    #[arg(long)]
    out: PathBuf,
    /// Also write `stamp,x,y,w,h,score,state` per frame.
    #[arg(long)]
    csv: Option<PathBuf>,
    /// Re-initialisations to serve: `stamp,x,y,w,h[,at]` per line (seconds; stamp = the
    /// frame the box was drawn on, 0 = newest; at = when it reached the node, default stamp).
    #[arg(long, value_name = "FILE")]
    reinit_file: Option<PathBuf>,
    /// Copy the image topic into the output, so one file opens in Foxglove over the video.
    #[arg(long)]
    copy_images: bool,
    /// Node parameters file (`--params-file` format) for image limits and the ring buffer.
    #[arg(long, value_name = "FILE")]
    params_file: Option<PathBuf>,
    /// Only read and decode the frames (no tracking, no output): prints the throughput.
    #[arg(long)]
    decode_only: bool,
}

/// Smallest and largest side of a demo frame, pixels (a frame is generated in memory).
const DEMO_MIN_SIDE: usize = 64;
/// See [`DEMO_MIN_SIDE`].
const DEMO_MAX_SIDE: usize = 4096;
/// Most demo frames (boxes are kept per frame).
const DEMO_MAX_FRAMES: usize = 100_000;

fn spec_of(c: &ConfigArgs) -> Result<bevt_core::TrackerSpec> {
    let mut set = c.set.clone();
    if let Some(t) = c.threads {
        set.push(format!("threads={t}"));
    }
    Ok(load_config(c.config.as_deref(), &set)?)
}

fn pool(threads: usize) -> Result<rayon::ThreadPool> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("bevt-worker-{i}"))
        .build()
        .context("cannot start the worker threads")
}

fn demo(
    cfg: &ConfigArgs,
    frames: usize,
    width: usize,
    height: usize,
    every: usize,
) -> Result<ExitCode> {
    let spec = spec_of(cfg)?;
    let sides = DEMO_MIN_SIDE..=DEMO_MAX_SIDE;
    if !sides.contains(&width) || !sides.contains(&height) {
        bail!("the demo needs frames of {DEMO_MIN_SIDE}..={DEMO_MAX_SIDE} pixels a side, got {width}x{height}");
    }
    if !(2..=DEMO_MAX_FRAMES).contains(&frames) {
        bail!("--frames {frames}: expected 2..={DEMO_MAX_FRAMES}");
    }
    let seq = SynthParams {
        width,
        height,
        frames,
        target: (width as f32 / 8.0, height as f32 / 7.0),
        path_amplitude: (width as f32 / 5.0, height as f32 / 6.0),
        ..SynthParams::default()
    };
    println!(
        "bevt demo: synthetic {}x{} sequence, {} frames, textured target moving and growing over a moving background",
        width, height, seq.frames
    );
    let threads = spec.config.threads;
    let mut tracker = BevtTracker::new(spec);
    let mut preds = Vec::with_capacity(seq.frames);
    let mut truth = Vec::with_capacity(seq.frames);
    let mut secs = 0.0;
    let pool = pool(threads)?;
    for t in 0..seq.frames {
        let f = seq.frame(t);
        let frame = Frame::packed(&f.rgb, width, height, PixelFormat::Rgb8)?;
        let t0 = Instant::now();
        let out = if t == 0 {
            pool.install(|| tracker.init(&frame, f.truth))?;
            None
        } else {
            Some(pool.install(|| tracker.update(&frame))?)
        };
        secs += t0.elapsed().as_secs_f64();
        let b = out.map_or(f.truth, |o| o.bbox);
        preds.push(b);
        truth.push(Some(f.truth));
        if let Some(o) = out {
            if (t + 1) % every.max(1) == 0 || t + 1 == seq.frames {
                println!(
                    "frame {:4}  box {:7.1} {:7.1} {:6.1} {:6.1}  truth {:7.1} {:7.1} {:6.1} {:6.1}  error {:5.2} px  consensus {:.3}  {}",
                    t + 1, b.x, b.y, b.w, b.h, f.truth.x, f.truth.y, f.truth.w, f.truth.h,
                    b.center().distance(&f.truth.center()),
                    o.consensus,
                    if o.learned { "learned" } else { "skipped" }
                );
            }
        }
    }
    let s = score_sequence(&preds, &truth);
    println!(
        "demo: precision@20px {:.3}, success AUC {:.3}, mean centre error {:.2} px, {:.1} fps (tracking only)",
        s.precision_20,
        s.auc,
        s.mean_center_error,
        seq.frames as f64 / secs.max(1e-9)
    );
    Ok(ExitCode::SUCCESS)
}

#[allow(clippy::too_many_arguments)]
fn eval(
    cfg: &ConfigArgs,
    dataset: &Path,
    out: &Path,
    sequences: &[String],
    plots: bool,
    compare: &[String],
    name: &str,
    perturb: Option<&str>,
    decode: Decode,
) -> Result<ExitCode> {
    let perturb = perturb
        .map(|p| Perturbation::parse(p).map_err(|e| anyhow::anyhow!("--perturb {p:?}: {e}")))
        .transpose()?;
    let opts = EvalOptions {
        tracker: spec_of(cfg)?,
        dataset: dataset.to_path_buf(),
        out: out.to_path_buf(),
        sequences: sequences.to_vec(),
        plots,
        compare: compare
            .iter()
            .map(|c| parse_compare(c).map_err(|e| anyhow::anyhow!("--compare {e}")))
            .collect::<Result<_>>()?,
        name: name.to_string(),
        progress: true,
        perturb,
        decode,
    };
    Ok(ExitCode::from(
        bevt_node::tool::eval::eval(&opts)?.exit_code(),
    ))
}

/// `--init x,y,w,h`: one finite box with positive size. Every bad box (unparsable, NaN,
/// empty, negative, or refused by the tracker on the first frame) is a usage error:
/// exit code 1 with the reason.
fn parse_box(s: &str) -> Result<BBox> {
    let rows = parse_annotation(s, Path::new("--init")).with_context(|| format!("--init {s:?}"))?;
    match rows.as_slice() {
        [Some(b)] if b.is_finite() && b.w > 0.0 && b.h > 0.0 => Ok(*b),
        _ => bail!("--init {s:?}: expected one finite box x,y,w,h with positive width and height"),
    }
}

fn track(cfg: &ConfigArgs, images: &Path, init: &str, out: Option<&Path>) -> Result<ExitCode> {
    let spec = spec_of(cfg)?;
    let init_arg = init;
    let init = parse_box(init)?;
    let files = image_files(images)?;
    if files.is_empty() {
        bail!("{} has no jpg/png frames", images.display());
    }
    let pool = pool(spec.config.threads)?;
    let mut tracker = BevtTracker::new(spec);
    let run = pool.install(|| track_feed(&mut tracker, decode_ahead(files), 0, init, |_, _| {}));
    if run.init_failed {
        bail!(
            "--init {init_arg:?}: {}",
            run.error.as_deref().unwrap_or("refused by the tracker")
        );
    }
    let mut text = String::new();
    for b in &run.boxes {
        text.push_str(&format_annotation_row(b.as_ref()));
        text.push('\n');
    }
    match out {
        Some(p) => {
            std::fs::write(p, &text).with_context(|| format!("cannot write {}", p.display()))?
        }
        None => print!("{text}"),
    }
    eprintln!(
        "tracked {} frames at {:.1} fps ({} learned, {} skipped)",
        run.frames_tracked,
        run.fps(),
        run.learned,
        run.skipped
    );
    if let Some(e) = run.error {
        eprintln!(
            "error: stopped early: {e} (the {} boxes before it were written)",
            run.boxes.len()
        );
        return Ok(ExitCode::from(2));
    }
    Ok(ExitCode::SUCCESS)
}

fn run(cli: Cli) -> Result<ExitCode> {
    match &cli.cmd {
        Cmd::Demo {
            cfg,
            frames,
            width,
            height,
            every,
        } => demo(cfg, *frames, *width, *height, *every),
        Cmd::Eval {
            cfg,
            dataset,
            out,
            sequences,
            plots,
            compare,
            name,
            perturb,
            decode,
        } => eval(
            cfg,
            dataset,
            out,
            sequences,
            *plots,
            compare,
            name,
            perturb.as_deref(),
            *decode,
        ),
        Cmd::Select {
            variants,
            criterion,
            sequences,
        } => {
            let opts = SelectOptions {
                variants: variants
                    .iter()
                    .map(|v| parse_compare(v).map_err(anyhow::Error::msg))
                    .collect::<Result<_>>()?,
                criterion: Criterion::parse(criterion).map_err(anyhow::Error::msg)?,
                sequences: sequences.clone(),
            };
            print!("{}", render(&select(&opts)?));
            Ok(ExitCode::SUCCESS)
        }
        Cmd::Track {
            cfg,
            images,
            init,
            out,
        } => track(cfg, images, init, out.as_deref()),
        Cmd::Replay(a) => replay(a),
    }
}

fn print_replay_summary(s: &ReplaySummary) {
    let states: Vec<String> = s.states.iter().map(|(k, v)| format!("{k} {v}")).collect();
    println!(
        "replay: {} messages, {} frames in {:.2} s ({:.1} frames/s); states: {}",
        s.messages,
        s.frames,
        s.seconds,
        s.frames as f64 / s.seconds.max(1e-9),
        if states.is_empty() {
            "none".into()
        } else {
            states.join(", ")
        }
    );
    for (reason, n) in &s.skipped {
        println!("  skipped or unusable: {n} x {reason}");
    }
    if s.reinit_applied > 0 || !s.reinit_refused.is_empty() {
        println!(
            "  re-initialisations: {} applied, {} refused",
            s.reinit_applied,
            s.reinit_refused.len()
        );
    }
    for r in &s.reinit_refused {
        println!("    refused: {r}");
    }
}

/// A flag set by SIGINT or SIGTERM (the `ctrlc` handler), for a run to finish its outputs
/// and stop.
fn stop_on_signal() -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    ctrlc::set_handler(move || s.store(true, Ordering::Relaxed))
        .context("cannot install the SIGINT/SIGTERM handler")?;
    Ok(stop)
}

fn replay(a: &ReplayArgs) -> Result<ExitCode> {
    let launch = match &a.params_file {
        Some(p) => launch_from_args(
            &[
                "--ros-args".to_string(),
                "--params-file".to_string(),
                p.display().to_string(),
            ],
            |_| None,
        )?,
        None => launch_from_args(&[], |_| None)?,
    };
    if a.decode_only {
        let (n, s) = decode_only(&a.bag, &a.topic, &launch.node)?;
        println!(
            "replay --decode-only: {n} of {} messages read and decoded in {:.3} s ({:.1} frames/s)",
            s.messages,
            s.seconds,
            n as f64 / s.seconds.max(1e-9)
        );
        for (reason, k) in &s.skipped {
            println!("  unusable: {k} x {reason}");
        }
        return Ok(ExitCode::SUCCESS);
    }
    // Before anything is read or written: no output may be an input or the other output.
    let mut outputs = vec![("--out", a.out.as_path())];
    if let Some(c) = &a.csv {
        outputs.push(("--csv", c.as_path()));
    }
    let mut inputs = vec![a.bag.as_path()];
    inputs.extend(a.reinit_file.as_deref());
    inputs.extend(a.params_file.as_deref());
    inputs.extend(a.cfg.config.as_deref());
    bevt_node::tool::outputs::refuse_overwriting_inputs(&outputs, &inputs)
        .map_err(anyhow::Error::msg)?;
    let init_at = match (&a.init_time, a.init_frame) {
        (Some(t), _) => InitAt::Time(parse_time_ns(t).map_err(anyhow::Error::msg)?),
        (None, Some(0)) => bail!("--init-frame counts from 1 (the first message is 1)"),
        (None, n) => InitAt::Frame(n.map_or(0, |n| n - 1)),
    };
    let reinit = match &a.reinit_file {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("cannot read {}", p.display()))?;
            parse_reinit_file(&text).map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?
        }
        None => Vec::new(),
    };
    let opts = ReplayOptions {
        bag: a.bag.clone(),
        topic: a.topic.clone(),
        init: parse_replay_box(&a.init).map_err(|e| anyhow::anyhow!("--init {e}"))?,
        init_at,
        tracker: spec_of(&a.cfg)?,
        node: launch.node,
        out: a.out.clone(),
        csv: a.csv.clone(),
        reinit,
        copy_images: a.copy_images,
        stop: Some(stop_on_signal()?),
    };
    let pool = pool(opts.tracker.config.threads)?;
    match pool.install(|| bevt_node::tool::replay::replay(&opts, true)) {
        Ok(s) => {
            print_replay_summary(&s);
            let csv = opts.csv.as_ref().map(|c| format!(" and {}", c.display()));
            println!("wrote {}{}", opts.out.display(), csv.unwrap_or_default());
            if s.interrupted {
                eprintln!(
                    "replay: interrupted by a signal after {} frames; the outputs are finished and hold them",
                    s.frames
                );
                // The shell's code for a process ended by SIGINT.
                return Ok(ExitCode::from(130));
            }
            Ok(ExitCode::SUCCESS)
        }
        Err(e) => {
            print_replay_summary(&e.summary);
            let kept = if e.partial.is_empty() {
                "no output was written".to_string()
            } else {
                let files: Vec<String> =
                    e.partial.iter().map(|p| p.display().to_string()).collect();
                format!("the frames processed are kept in {}", files.join(" and "))
            };
            eprintln!(
                "error: {}\n({kept}; {} is untouched)",
                e.reason,
                opts.out.display()
            );
            Ok(ExitCode::FAILURE)
        }
    }
}

fn main() -> ExitCode {
    bevt_node::tool::pipe::exit_quietly_on_broken_pipe();
    match run(Cli::parse()) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run_track(init: &str) -> Result<ExitCode> {
        let dir = std::env::temp_dir().join(format!("bevt_track_{}", std::process::id()));
        std::fs::create_dir_all(&dir)?;
        let seq = SynthParams::default();
        for t in 0..3 {
            let f = seq.frame(t);
            image::RgbImage::from_raw(seq.width as u32, seq.height as u32, f.rgb)
                .context("frame")?
                .save(dir.join(format!("{t:04}.png")))?;
        }
        let cfg = ConfigArgs {
            config: None,
            set: Vec::new(),
            threads: None,
        };
        let out = dir.join(format!("out_{}.txt", init.len()));
        track(&cfg, &dir, init, Some(&out))
    }

    #[test]
    fn demo_sizes_are_bounded_before_anything_is_allocated() {
        let cfg = ConfigArgs {
            config: None,
            set: Vec::new(),
            threads: None,
        };
        for (frames, w, h) in [
            (10, 100_000, 100_000),
            (10, 32, 64),
            (usize::MAX, 640, 360),
            (1, 640, 360),
        ] {
            assert!(demo(&cfg, frames, w, h, 1).is_err(), "{frames} {w}x{h}");
        }
    }

    #[test]
    fn every_bad_init_box_is_the_same_usage_error() {
        // Unparsable, NaN, empty, negative, tiny and off-frame boxes alike.
        for bad in [
            "1,2,3",
            "NaN,1,10,10",
            "1,1,0,10",
            "1,1,-10,10",
            "1,1,10,-10",
            "1,1,inf,10",
            "10,10,2,2",
            "-900,-900,20,20",
            "5000,5000,20,20",
        ] {
            let e = run_track(bad).map(|_| ()).unwrap_err().to_string();
            assert!(e.contains("--init"), "{bad}: {e}");
        }
        let seq = SynthParams::default();
        let t = seq.truth(0);
        let good = format!("{},{},{},{}", t.x + 1.0, t.y + 1.0, t.w, t.h);
        assert_eq!(run_track(&good).unwrap(), ExitCode::SUCCESS);
    }
}
