//! Scores, result files, `summary.json`, console tables and comparisons.
//!
//! Averaging follows the UAV123/OTB toolkit: scores are computed per sequence over its
//! annotated frames (NaN ground truth excluded), then averaged over sequences. Sequences
//! that failed are listed with their reason and left out of the averages.

use crate::tool::dataset::{format_annotation_row, parse_annotation, Dataset};
use crate::tool::runner::SequenceRun;
use bevt_core::eval::lost::{label_frames, reacquire_frames, score_lost, FrameLabel, LostScores};
use bevt_core::eval::metrics::{mean_curve, score_sequence, SequenceScores};
use bevt_core::{BBox, TrackState};
use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

/// How overall numbers are averaged (written into every summary).
pub const AVERAGING: &str = "per-sequence scores over annotated frames (NaN ground truth excluded), then the mean over sequences that ran to the end; fps_mean is the mean of per-sequence fps, fps_pooled total frames / total tracking time (decode excluded)";

/// One sequence in the summary.
#[derive(Debug, Clone, Serialize)]
pub struct SequenceSummary {
    /// Name.
    pub name: String,
    /// `ok` or `failed`.
    pub status: &'static str,
    /// Failure reason.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// Annotation rows.
    pub frames: usize,
    /// Frames given to the tracker.
    pub frames_tracked: usize,
    /// Precision at 20 px.
    pub precision_20: f64,
    /// Success AUC.
    pub auc: f64,
    /// Success at IoU 0.5.
    pub success_50: f64,
    /// Mean centre error, px.
    pub mean_center_error: f64,
    /// Tracking frames per second.
    pub fps: f64,
    /// Frames learned.
    pub learned: usize,
    /// Frames skipped by verification.
    pub skipped: usize,
    /// Learned-verifier search passes (absent without a verifier).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub verifier_passes: Option<u64>,
    /// Mean consensus score over updates.
    pub mean_consensus: f64,
    /// Confidence ROC-AUC and lost-state precision/recall (README "Confidence and lost
    /// state"); absent without ground truth.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lost: Option<LostScores>,
    /// Frames to re-acquire after each reappearance of the target (`null`: never).
    pub reacquire_frames: Vec<Option<usize>>,
    #[serde(skip)]
    labels: Vec<FrameLabel>,
    /// Consensus distribution over updates: minimum, 5th, 50th and 95th percentiles
    /// (nearest rank; NaN when there were no updates).
    pub consensus_quantiles: [f64; 4],
    #[serde(skip)]
    scores: Option<SequenceScores>,
    #[serde(skip)]
    seconds: f64,
}

/// Overall scores of one tracker.
#[derive(Debug, Clone, Serialize, Default)]
pub struct Overall {
    /// Sequences averaged.
    pub sequences: usize,
    /// Sequences that failed (not averaged).
    pub failed: usize,
    /// Mean precision at 20 px.
    pub precision_20: f64,
    /// Mean success AUC.
    pub auc: f64,
    /// Mean success at IoU 0.5.
    pub success_50: f64,
    /// Confidence ROC-AUC and lost-state precision/recall over the frames of all averaged
    /// sequences pooled (our tracker only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lost: Option<LostScores>,
    /// Reappearances of the target after an absence (our tracker only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reappearances: Option<usize>,
    /// Reappearances after which the target was tracked again (our tracker only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reacquired: Option<usize>,
    /// Mean frames to re-acquire over those reappearances (our tracker only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reacquire_frames_mean: Option<f64>,
    /// Mean of per-sequence fps (our tracker only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fps_mean: Option<f64>,
    /// Frames / tracking time over all sequences (our tracker only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fps_pooled: Option<f64>,
    /// Learned-verifier search passes over all sequences (our tracker, with a verifier).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub verifier_passes: Option<u64>,
    /// Mean precision curve at 0..=50 px.
    pub precision_curve: Vec<f64>,
    /// Mean success curve at IoU 0, 0.05, …, 1.
    pub success_curve: Vec<f64>,
}

/// Another tracker's scores from its result folder.
#[derive(Debug, Clone, Serialize)]
pub struct PeerScores {
    /// Display name.
    pub name: String,
    /// Overall scores over the sequences both trackers completed.
    pub overall: Overall,
    /// Per sequence (missing result files are absent).
    pub sequences: BTreeMap<String, (f64, f64)>,
    /// Sequences without a result file.
    pub missing: Vec<String>,
}

/// Mean scores of each tracker on the sequences that have one attribute.
#[derive(Debug, Clone, Serialize)]
pub struct AttributeRow {
    /// Attribute name (e.g. `SV`).
    pub attribute: String,
    /// Sequences with the attribute.
    pub sequences: Vec<String>,
    /// (tracker, precision@20, AUC).
    pub scores: Vec<(String, f64, f64)>,
}

/// The whole evaluation summary (`summary.json`).
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Our tracker's display name.
    pub tracker: String,
    /// Dataset root.
    pub dataset: String,
    /// How averages are formed.
    pub averaging: &'static str,
    /// Our overall scores.
    pub overall: Overall,
    /// Per sequence.
    pub sequences: Vec<SequenceSummary>,
    /// Compared trackers.
    pub compare: Vec<PeerScores>,
    /// Per-attribute table (empty when the dataset has no attributes).
    pub attributes: Vec<AttributeRow>,
    /// The configuration used.
    pub config: serde_json::Value,
    /// The `--perturb` applied to every frame and its truth (absent: none).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub perturb: Option<String>,
    /// Where the frames were decoded (`ahead`: on a thread beside the tracker; `inline`:
    /// between its timed calls), which the fps depend on.
    pub decode: &'static str,
}

/// Minimum, 5th, 50th and 95th percentile (nearest rank) of `v`; NaN when empty.
fn consensus_quantiles(mut v: Vec<f64>) -> [f64; 4] {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return [f64::NAN; 4];
    }
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((q * (v.len() - 1) as f64).round() as usize).min(v.len() - 1)];
    [v[0], at(0.05), at(0.5), at(0.95)]
}

/// Scores one run.
pub fn summarize_run(r: &SequenceRun) -> SequenceSummary {
    let ok = r.run.error.is_none();
    let preds: Vec<BBox> = r
        .run
        .boxes
        .iter()
        .map(|b| b.unwrap_or(BBox::new(f32::NAN, f32::NAN, f32::NAN, f32::NAN)))
        .collect();
    let scores = (!r.truth.is_empty()).then(|| score_sequence(&preds, &r.truth));
    let cons: Vec<f64> = r
        .run
        .outputs
        .iter()
        .flatten()
        .map(|o| o.consensus as f64)
        .collect();
    let s = scores.clone().unwrap_or_else(|| score_sequence(&[], &[]));
    let states = state_rows(r);
    let labels = label_frames(&states, &r.truth);
    SequenceSummary {
        name: r.name.clone(),
        status: if ok { "ok" } else { "failed" },
        error: r.run.error.clone(),
        frames: r.truth.len(),
        frames_tracked: r.run.frames_tracked,
        precision_20: s.precision_20,
        auc: s.auc,
        success_50: s.success_50,
        mean_center_error: s.mean_center_error,
        fps: r.run.fps(),
        learned: r.run.learned,
        skipped: r.run.skipped,
        verifier_passes: r.run.verifier_passes,
        mean_consensus: if cons.is_empty() {
            f64::NAN
        } else {
            cons.iter().sum::<f64>() / cons.len() as f64
        },
        lost: (!r.truth.is_empty()).then(|| score_lost(&[&labels])),
        reacquire_frames: reacquire_frames(&states, &r.truth),
        labels,
        consensus_quantiles: consensus_quantiles(cons),
        scores: ok.then_some(scores).flatten(),
        seconds: r.run.track_seconds,
    }
}

/// `(box, confidence, state)` per processed frame (`None` for the init frame and before).
fn state_rows(r: &SequenceRun) -> Vec<Option<(BBox, f32, TrackState)>> {
    r.run
        .outputs
        .iter()
        .map(|o| o.map(|o| (o.bbox, o.confidence, o.state)))
        .collect()
}

fn overall_of(scores: &[&SequenceScores]) -> Overall {
    let n = scores.len().max(1) as f64;
    let pc: Vec<&[f64]> = scores
        .iter()
        .map(|s| s.precision_curve.as_slice())
        .collect();
    let sc: Vec<&[f64]> = scores.iter().map(|s| s.success_curve.as_slice()).collect();
    Overall {
        sequences: scores.len(),
        failed: 0,
        precision_20: scores.iter().map(|s| s.precision_20).sum::<f64>() / n,
        auc: scores.iter().map(|s| s.auc).sum::<f64>() / n,
        success_50: scores.iter().map(|s| s.success_50).sum::<f64>() / n,
        lost: None,
        reappearances: None,
        reacquired: None,
        reacquire_frames_mean: None,
        fps_mean: None,
        fps_pooled: None,
        verifier_passes: None,
        precision_curve: mean_curve(&pc),
        success_curve: mean_curve(&sc),
    }
}

/// Builds the summary: our scores, peers' scores on the same sequences, attribute table.
pub fn build_summary(
    tracker: &str,
    dataset: &Dataset,
    runs: &[SequenceSummary],
    truths: &BTreeMap<String, Vec<Option<BBox>>>,
    peers: &[(String, std::path::PathBuf)],
    config: serde_json::Value,
) -> Summary {
    let done: Vec<&SequenceSummary> = runs.iter().filter(|r| r.scores.is_some()).collect();
    let scored: Vec<&SequenceScores> = done.iter().filter_map(|r| r.scores.as_ref()).collect();
    let mut overall = overall_of(&scored);
    overall.failed = runs.len() - done.len();
    let pooled: Vec<&[FrameLabel]> = done.iter().map(|r| r.labels.as_slice()).collect();
    overall.lost = Some(score_lost(&pooled));
    let re: Vec<Option<usize>> = done
        .iter()
        .flat_map(|r| r.reacquire_frames.clone())
        .collect();
    let found: Vec<usize> = re.iter().flatten().copied().collect();
    overall.reappearances = Some(re.len());
    overall.reacquired = Some(found.len());
    overall.reacquire_frames_mean =
        (!found.is_empty()).then(|| found.iter().sum::<usize>() as f64 / found.len() as f64);
    if !done.is_empty() {
        overall.fps_mean = Some(done.iter().map(|r| r.fps).sum::<f64>() / done.len() as f64);
        let secs: f64 = done.iter().map(|r| r.seconds).sum();
        let frames: usize = done.iter().map(|r| r.frames_tracked).sum();
        overall.fps_pooled = Some(if secs > 0.0 {
            frames as f64 / secs
        } else {
            0.0
        });
    }
    overall.verifier_passes = done
        .iter()
        .filter_map(|r| r.verifier_passes)
        .reduce(|a, b| a + b);
    let compare: Vec<PeerScores> = peers
        .iter()
        .map(|(name, dir)| score_peer(name, dir, &done, truths))
        .collect();
    let mut attributes = Vec::new();
    for attr in &dataset.attribute_order {
        let seqs: Vec<String> = dataset
            .sequences
            .iter()
            .filter(|s| s.attributes.get(attr).copied().flatten() == Some(true))
            .filter(|s| done.iter().any(|d| d.name == s.name))
            .map(|s| s.name.clone())
            .collect();
        if seqs.is_empty() {
            continue;
        }
        let mean_of = |get: &dyn Fn(&str) -> Option<(f64, f64)>| {
            let v: Vec<(f64, f64)> = seqs.iter().filter_map(|s| get(s)).collect();
            let n = v.len().max(1) as f64;
            (
                v.iter().map(|x| x.0).sum::<f64>() / n,
                v.iter().map(|x| x.1).sum::<f64>() / n,
            )
        };
        let mut scores = Vec::new();
        let ours = mean_of(&|s| {
            done.iter()
                .find(|d| d.name == s)
                .map(|d| (d.precision_20, d.auc))
        });
        scores.push((tracker.to_string(), ours.0, ours.1));
        for p in &compare {
            let m = mean_of(&|s| p.sequences.get(s).copied());
            scores.push((p.name.clone(), m.0, m.1));
        }
        attributes.push(AttributeRow {
            attribute: attr.clone(),
            sequences: seqs,
            scores,
        });
    }
    Summary {
        tracker: tracker.to_string(),
        dataset: dataset.root.display().to_string(),
        averaging: AVERAGING,
        overall,
        sequences: runs.to_vec(),
        compare,
        attributes,
        config,
        perturb: None,
        decode: "ahead",
    }
}

fn score_peer(
    name: &str,
    dir: &Path,
    done: &[&SequenceSummary],
    truths: &BTreeMap<String, Vec<Option<BBox>>>,
) -> PeerScores {
    let mut scores = BTreeMap::new();
    let mut missing = Vec::new();
    for r in done {
        let Some(truth) = truths.get(&r.name) else {
            continue;
        };
        let path = dir.join(format!("{}.txt", r.name));
        let parsed = std::fs::read_to_string(&path)
            .ok()
            .and_then(|t| parse_annotation(&t, &path).ok());
        match parsed {
            Some(rows) => {
                let preds: Vec<BBox> = rows
                    .iter()
                    .map(|b| b.unwrap_or(BBox::new(f32::NAN, f32::NAN, f32::NAN, f32::NAN)))
                    .collect();
                scores.insert(r.name.clone(), score_sequence(&preds, truth));
            }
            None => missing.push(r.name.clone()),
        }
    }
    let list: Vec<&SequenceScores> = scores.values().collect();
    PeerScores {
        name: name.to_string(),
        overall: overall_of(&list),
        sequences: scores
            .iter()
            .map(|(k, v)| (k.clone(), (v.precision_20, v.auc)))
            .collect(),
        missing,
    }
}

/// Writes `<out>/<name>.txt`: one row per processed frame in the annotation convention.
///
/// # Errors
/// I/O errors.
pub fn write_result_file(out: &Path, run: &SequenceRun) -> std::io::Result<()> {
    let mut s = String::new();
    for b in &run.run.boxes {
        s.push_str(&format_annotation_row(b.as_ref()));
        s.push('\n');
    }
    std::fs::write(out.join(format!("{}.txt", run.name)), s)?;
    write_state_file(out, run)
}

/// Writes `<out>/<name>.state.csv`: `frame,confidence,state,reason` per frame (1-based
/// frame numbers as in the annotation; empty confidence and state `init`/`none` for the
/// init frame and the frames before it; the reason as the node publishes it, quoted,
/// empty when tracking confidently).
///
/// # Errors
/// I/O errors.
pub fn write_state_file(out: &Path, run: &SequenceRun) -> std::io::Result<()> {
    let mut s = String::from("frame,confidence,state,reason\n");
    let first = run.run.boxes.iter().position(Option::is_some);
    for (i, o) in run.run.outputs.iter().enumerate() {
        let _ = match o {
            Some(o) => writeln!(
                s,
                "{},{:.4},{},\"{}\"",
                i + 1,
                o.confidence,
                o.state.name(),
                o.reason.to_string().replace('"', "'")
            ),
            None if Some(i) == first => writeln!(s, "{},,init,", i + 1),
            None => writeln!(s, "{},,none,", i + 1),
        };
    }
    std::fs::write(out.join(format!("{}.state.csv", run.name)), s)
}

fn fmt_opt(v: f64, width: usize) -> String {
    if v.is_finite() {
        format!("{v:>width$.3}")
    } else {
        format!("{:>width$}", "-")
    }
}

/// The console cell of the time to flag: median frames / episodes never flagged.
fn time_to_flag(l: &LostScores) -> String {
    let m = l.time_to_flag_median;
    let m = if m.is_finite() {
        format!("{m:.1}")
    } else {
        "-".to_string()
    };
    format!("{m}/{}", l.episodes_never_flagged)
}

/// Writes `summary.json`.
///
/// # Errors
/// I/O or serialisation errors.
pub fn write_summary(out: &Path, s: &Summary) -> std::io::Result<()> {
    let text = serde_json::to_string_pretty(s).map_err(std::io::Error::other)?;
    std::fs::write(out.join("summary.json"), text)
}

/// The console report: per-sequence table, overall line, comparison and attributes.
pub fn console_table(s: &Summary) -> String {
    let mut t = String::new();
    let _ = writeln!(
        t,
        "{:<14} {:>6} {:>7} {:>6} {:>7} {:>8} {:>8} {:>7} {:>7} {:>7} {:>7} {:>7} {:>7} {:>9} {:>9}  status",
        "sequence",
        "frames",
        "P@20",
        "AUC",
        "fps",
        "learned",
        "skipped",
        "vpasses",
        "confAUC",
        "flagP",
        "flagR",
        "lostP",
        "lostR",
        "ttf/never",
        "reacq"
    );
    let lost_cells = |l: Option<&LostScores>| {
        l.map_or(
            format!(
                "{:>7} {:>7} {:>7} {:>7} {:>7} {:>9}",
                "-", "-", "-", "-", "-", "-"
            ),
            |l| {
                format!(
                    "{} {} {} {} {} {:>9}",
                    fmt_opt(l.confidence_auc, 7),
                    fmt_opt(l.flag_precision, 7),
                    fmt_opt(l.flag_recall, 7),
                    fmt_opt(l.lost_precision, 7),
                    fmt_opt(l.lost_recall, 7),
                    time_to_flag(l)
                )
            },
        )
    };
    for r in &s.sequences {
        let reacq: Vec<String> = r
            .reacquire_frames
            .iter()
            .map(|f| f.map_or("never".to_string(), |f| f.to_string()))
            .collect();
        let _ = writeln!(
            t,
            "{:<14} {:>6} {:>7.3} {:>6.3} {:>7.1} {:>8} {:>8} {:>7} {} {:>9}  {}",
            r.name,
            r.frames,
            r.precision_20,
            r.auc,
            r.fps,
            r.learned,
            r.skipped,
            r.verifier_passes.map_or("-".to_string(), |p| p.to_string()),
            lost_cells(r.lost.as_ref()),
            if reacq.is_empty() {
                "-".to_string()
            } else {
                reacq.join(",")
            },
            r.error
                .as_deref()
                .map_or("ok".to_string(), |e| format!("FAILED: {e}"))
        );
    }
    let o = &s.overall;
    let _ = writeln!(
        t,
        "{:<14} {:>6} {:>7.3} {:>6.3} {:>7.1}   (mean over {} sequences; {} failed; pooled fps {:.1}{})",
        "OVERALL",
        "",
        o.precision_20,
        o.auc,
        o.fps_mean.unwrap_or(0.0),
        o.sequences,
        o.failed,
        o.fps_pooled.unwrap_or(0.0),
        o.verifier_passes
            .map_or(String::new(), |p| format!("; {p} verifier passes"))
    );
    if let Some(l) = &o.lost {
        let _ = writeln!(
            t,
            "confidence ROC-AUC {} (good {} / bad {} frames, pooled); flags (uncertain|lost) precision {} recall {} ({} flagged frames); time to flag median {} frames over {} failure episodes, {} never flagged; lost state precision {} recall {} ({} lost frames); re-acquired {}/{} reappearances, mean {} frames",
            fmt_opt(l.confidence_auc, 0),
            l.good_frames,
            l.bad_frames,
            fmt_opt(l.flag_precision, 0),
            fmt_opt(l.flag_recall, 0),
            l.flagged_frames,
            fmt_opt(l.time_to_flag_median, 0),
            l.episodes,
            l.episodes_never_flagged,
            fmt_opt(l.lost_precision, 0),
            fmt_opt(l.lost_recall, 0),
            l.lost_frames,
            o.reacquired.unwrap_or(0),
            o.reappearances.unwrap_or(0),
            o.reacquire_frames_mean
                .map_or("-".to_string(), |m| format!("{m:.1}"))
        );
    }
    if !s.compare.is_empty() {
        let _ = writeln!(
            t,
            "\n{:<22} {:>7} {:>6} {:>7}",
            "tracker", "P@20", "AUC", "SR@0.5"
        );
        let mut rows: Vec<(&str, &Overall)> = vec![(s.tracker.as_str(), &s.overall)];
        rows.extend(s.compare.iter().map(|p| (p.name.as_str(), &p.overall)));
        rows.sort_by(|a, b| b.1.auc.total_cmp(&a.1.auc));
        for (n, o) in rows {
            let _ = writeln!(
                t,
                "{:<22} {:>7.3} {:>6.3} {:>7.3}",
                n, o.precision_20, o.auc, o.success_50
            );
        }
        for p in &s.compare {
            if !p.missing.is_empty() {
                let _ = writeln!(
                    t,
                    "note: {} has no result for {}",
                    p.name,
                    p.missing.join(", ")
                );
            }
        }
    }
    if !s.attributes.is_empty() {
        let _ = writeln!(
            t,
            "\nper attribute (P@20 / AUC, mean over the sequences that have it):"
        );
        for a in &s.attributes {
            let cells: Vec<String> = a
                .scores
                .iter()
                .map(|(n, p, u)| format!("{n} {p:.3}/{u:.3}"))
                .collect();
            let _ = writeln!(
                t,
                "{:<4} (n={}) {}",
                a.attribute,
                a.sequences.len(),
                cells.join(" | ")
            );
        }
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tool::runner::TrackRun;

    #[test]
    fn consensus_quantiles_are_nearest_rank() {
        let v: Vec<f64> = (0..=100).rev().map(|i| i as f64 / 100.0).collect();
        assert_eq!(consensus_quantiles(v), [0.0, 0.05, 0.5, 0.95]);
        assert!(consensus_quantiles(vec![f64::NAN])
            .iter()
            .all(|q| q.is_nan()));
    }

    #[test]
    fn failed_runs_are_listed_but_not_averaged() {
        let b = BBox::new(0.0, 0.0, 10.0, 10.0);
        let good = SequenceRun {
            name: "a".into(),
            truth: vec![Some(b), Some(b)],
            run: TrackRun {
                boxes: vec![Some(b), Some(b)],
                frames_tracked: 2,
                track_seconds: 0.1,
                ..TrackRun::default()
            },
        };
        let bad = SequenceRun {
            name: "b".into(),
            truth: vec![Some(b), Some(b)],
            run: TrackRun {
                boxes: vec![Some(b)],
                frames_tracked: 1,
                error: Some("frame 2: corrupt".into()),
                ..TrackRun::default()
            },
        };
        let runs = vec![summarize_run(&good), summarize_run(&bad)];
        let ds = Dataset {
            root: "x".into(),
            layout: "manifest",
            sequences: Vec::new(),
            attribute_order: Vec::new(),
        };
        let s = build_summary(
            "BEVT-rs",
            &ds,
            &runs,
            &BTreeMap::new(),
            &[],
            serde_json::Value::Null,
        );
        assert_eq!(s.overall.sequences, 1);
        assert_eq!(s.overall.failed, 1);
        assert_eq!(s.overall.precision_20, 1.0);
        assert!((s.overall.fps_mean.unwrap() - 20.0).abs() < 1e-9);
        let table = console_table(&s);
        assert!(table.contains("FAILED: frame 2: corrupt"), "{table}");
        // The failed sequence's partial result is still scored on what it computed.
        assert_eq!(s.sequences[1].frames_tracked, 1);
        assert_eq!(s.sequences[1].precision_20, 0.5);
    }
}
