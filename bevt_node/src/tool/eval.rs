//! `bevt eval`: one-pass evaluation of a dataset with result files, `summary.json`, a console
//! table, optional comparisons with peers' result folders and optional plots.
//!
//! The command line only parses its arguments into [`EvalOptions`], calls [`eval`] and exits
//! with [`EvalOutcome::exit_code`]; tests drive the same function.

use crate::tool::dataset::open_dataset;
use crate::tool::plots::{plot_curves, Curve};
use crate::tool::report::{
    build_summary, console_table, summarize_run, write_result_file, write_summary, Summary,
};
use crate::tool::runner::{run_perturbed, Decode};
use anyhow::{bail, Context, Result};
use bevt_core::eval::perturb::Perturbation;
use bevt_core::{BevtTracker, TrackerSpec};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Exit code when the evaluation ran but at least one sequence failed (its partial result
/// is kept); usage and I/O errors exit with 1.
pub const EXIT_SEQUENCE_FAILED: u8 = 2;

/// What `bevt eval` needs, validated by the caller (the tracker configuration is loaded).
#[derive(Debug, Clone)]
pub struct EvalOptions {
    /// Tracker specification (configuration file plus `--set` overrides).
    pub tracker: TrackerSpec,
    /// Dataset root.
    pub dataset: PathBuf,
    /// Output folder (created when missing).
    pub out: PathBuf,
    /// Sequences to run (empty: all).
    pub sequences: Vec<String>,
    /// Write `precision.png` and `success.png`.
    pub plots: bool,
    /// Peers' result folders, `(name, folder)`.
    pub compare: Vec<(String, PathBuf)>,
    /// Our tracker's name in tables and plots.
    pub name: String,
    /// Draw the progress bars on standard error (hidden when false).
    pub progress: bool,
    /// Transform every frame and its ground truth (`--perturb`; `None`: the footage as is).
    pub perturb: Option<Perturbation>,
    /// Where frames are decoded (`--decode`): beside the tracker, or between its timed
    /// calls on its own thread.
    pub decode: Decode,
}

/// Parses one `--compare NAME=DIR`.
///
/// # Errors
/// A message when there is no `=`, the name is empty, or the folder is not one.
pub fn parse_compare(s: &str) -> Result<(String, PathBuf), String> {
    let (name, dir) = s
        .split_once('=')
        .ok_or_else(|| format!("{s:?}: expected NAME=DIR"))?;
    if name.trim().is_empty() {
        return Err(format!("{s:?}: the NAME before '=' is empty"));
    }
    let dir = PathBuf::from(dir);
    if !dir.is_dir() {
        return Err(format!("{name}: {} is not a folder", dir.display()));
    }
    Ok((name.to_string(), dir))
}

/// Where one sequence's progress bar stood when the sequence ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SequenceProgress {
    /// Sequence name (the bar's prefix).
    pub name: String,
    /// Frames processed.
    pub position: u64,
    /// The bar's length: the sequence's frames (0 when it could not be loaded).
    pub length: u64,
}

/// The result of [`eval`].
#[derive(Debug, Clone)]
pub struct EvalOutcome {
    /// The summary written to `summary.json`.
    pub summary: Summary,
    /// The plots written (empty without `plots`).
    pub plots: Vec<PathBuf>,
    /// Each sequence's progress bar at its end.
    pub progress: Vec<SequenceProgress>,
}

impl EvalOutcome {
    /// 0 when every sequence ran to its end, [`EXIT_SEQUENCE_FAILED`] otherwise.
    pub fn exit_code(&self) -> u8 {
        if self.summary.overall.failed > 0 {
            EXIT_SEQUENCE_FAILED
        } else {
            0
        }
    }
}

fn sequence_bar(name: &str, frames: u64, visible: bool) -> ProgressBar {
    let target = if visible {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    };
    let bar = ProgressBar::with_draw_target(Some(frames), target);
    bar.set_style(
        ProgressStyle::with_template("{prefix:>14} [{bar:40}] {pos}/{len} frames {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_prefix(name.to_string());
    bar
}

/// Runs the evaluation: every selected sequence once (one-pass, no re-initialisation),
/// writing `<sequence>.txt` and `summary.json` after each sequence (nothing computed is lost
/// when a later one fails or the run is interrupted), then the console table and the plots.
///
/// # Errors
/// Unreadable dataset, unknown sequence name, a model that cannot be loaded (checked before
/// any sequence runs), output folder or plots that cannot be written, or worker threads that
/// cannot start. A sequence that fails (unreadable frame, bad
/// annotation) is not an error: it is reported in the summary and in
/// [`EvalOutcome::exit_code`].
pub fn eval(opts: &EvalOptions) -> Result<EvalOutcome> {
    let mut ds = open_dataset(&opts.dataset)?;
    if !opts.sequences.is_empty() {
        ds.select(&opts.sequences)?;
    }
    for (n, d) in &opts.compare {
        if !d.is_dir() {
            bail!("--compare {n}: {} is not a folder", d.display());
        }
    }
    // The models load, plan and pass their check here, once, as the node does at start-up:
    // not inside the first sequence's timed `init` (the peers' harnesses load theirs before
    // timing too), and a bad model path stops the run before any sequence, naming its key.
    BevtTracker::check_models(&opts.tracker).context("cannot load the tracker's models")?;
    let out = opts.out.as_path();
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let threads = opts.tracker.config.threads;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("bevt-worker-{i}"))
        .build()
        .context("cannot start the worker threads")?;
    let config_json = serde_json::to_value(&opts.tracker.config)?;
    let mut summaries = Vec::new();
    let mut truths = BTreeMap::new();
    let mut progress = Vec::new();
    println!(
        "bevt eval: {} sequences from {} ({} layout), {} thread(s)",
        ds.sequences.len(),
        ds.root.display(),
        ds.layout,
        threads
    );
    let perturb = opts.perturb.map(|p| p.to_string());
    if let Some(p) = &perturb {
        println!("perturbation: {p} (frames and ground truth transformed alike)");
    }
    for entry in &ds.sequences {
        let loaded = entry.load();
        let frames = loaded.as_ref().map_or(0, |s| s.frames.len() as u64);
        let bar = sequence_bar(&entry.name, frames, opts.progress);
        let mut tracker = BevtTracker::new(opts.tracker.clone());
        let run = pool.install(|| {
            run_perturbed(
                &entry.name,
                loaded,
                opts.perturb.as_ref(),
                opts.decode,
                &mut tracker,
                |_, o| {
                    bar.inc(1);
                    if let Some(o) = o {
                        bar.set_message(format!("consensus {:.2}", o.consensus));
                    }
                },
            )
        });
        progress.push(SequenceProgress {
            name: entry.name.clone(),
            position: bar.position(),
            length: bar.length().unwrap_or(0),
        });
        bar.finish_and_clear();
        if let Err(e) = write_result_file(out, &run) {
            eprintln!("warning: cannot write the result of {}: {e}", run.name);
        }
        let s = summarize_run(&run);
        println!(
            "{:>14}: {} frames, P@20 {:.3}, AUC {:.3}, {:.1} fps{}",
            s.name,
            s.frames_tracked,
            s.precision_20,
            s.auc,
            s.fps,
            s.error
                .as_deref()
                .map_or(String::new(), |e| format!("  FAILED: {e}"))
        );
        truths.insert(run.name.clone(), run.truth.clone());
        summaries.push(s);
        // Keep a summary on disk after every sequence: nothing computed is lost.
        let mut partial = build_summary(
            &opts.name,
            &ds,
            &summaries,
            &truths,
            &opts.compare,
            config_json.clone(),
        );
        partial.perturb.clone_from(&perturb);
        partial.decode = opts.decode.name();
        write_summary(out, &partial)
            .with_context(|| format!("cannot write {}/summary.json", out.display()))?;
    }
    let mut summary = build_summary(
        &opts.name,
        &ds,
        &summaries,
        &truths,
        &opts.compare,
        config_json,
    );
    summary.perturb = perturb;
    summary.decode = opts.decode.name();
    write_summary(out, &summary)
        .with_context(|| format!("cannot write {}/summary.json", out.display()))?;
    println!("\n{}", console_table(&summary));
    let plots = if opts.plots {
        write_plots(out, &opts.name, &summary)?
    } else {
        Vec::new()
    };
    println!("results: {}", out.display());
    Ok(EvalOutcome {
        summary,
        plots,
        progress,
    })
}

/// The curves of one plot: ours first, then the peers in `summary.compare` order.
pub fn plot_series(name: &str, summary: &Summary, success: bool) -> Vec<Curve> {
    let pick = |o: &crate::tool::report::Overall| {
        if success {
            (o.auc, o.success_curve.clone())
        } else {
            (o.precision_20, o.precision_curve.clone())
        }
    };
    let (score, values) = pick(&summary.overall);
    let mut curves = vec![Curve {
        name: name.to_string(),
        score,
        values,
        own: true,
    }];
    for p in &summary.compare {
        let (score, values) = pick(&p.overall);
        curves.push(Curve {
            name: p.name.clone(),
            score,
            values,
            own: false,
        });
    }
    curves
}

/// Writes `precision.png` and `success.png` into `out`; returns their paths.
///
/// # Errors
/// A plot that cannot be drawn or written.
pub fn write_plots(out: &Path, name: &str, summary: &Summary) -> Result<Vec<PathBuf>> {
    let n = summary.overall.sequences;
    let precision = out.join("precision.png");
    let success = out.join("success.png");
    plot_curves(
        &precision,
        &format!("Precision plots of OPE ({n} sequences)"),
        "Location error threshold (px)",
        "Precision",
        50.0,
        &plot_series(name, summary, false),
    )
    .map_err(anyhow::Error::msg)?;
    plot_curves(
        &success,
        &format!("Success plots of OPE ({n} sequences)"),
        "Overlap threshold (IoU)",
        "Success rate",
        1.0,
        &plot_series(name, summary, true),
    )
    .map_err(anyhow::Error::msg)?;
    println!("plots: {}, {}", precision.display(), success.display());
    Ok(vec![precision, success])
}
