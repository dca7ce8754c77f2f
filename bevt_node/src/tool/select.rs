//! `bevt select`: leave-one-sequence-out selection over finished `bevt eval --out` folders.
//!
//! Each `NAME=DIR` is one candidate variant (a preset, a `--set` change); its
//! `DIR/summary.json` gives the per-sequence scores. For each held-out sequence the variant
//! with the best mean criterion over the other sequences is chosen and scored on the held-out
//! one ([`bevt_core::eval::select`]); the report gives every fold, the pooled LOSO mean beside
//! each variant's full-set mean, and the per-sequence scores. List the incumbent first: ties
//! go to the earlier variant.

use anyhow::{bail, Context, Result};
use bevt_core::eval::select::{leave_one_sequence_out, Loso, ScoreTable};
use serde::Deserialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// What the selection maximises.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Criterion {
    /// Success AUC.
    Auc,
    /// Precision at 20 px.
    P20,
    /// Success at IoU 0.5.
    Sr50,
}

impl Criterion {
    /// Every criterion, in report column order.
    pub const ALL: [Criterion; 3] = [Criterion::Auc, Criterion::P20, Criterion::Sr50];

    /// Parses `auc`, `p20` or `sr50`.
    ///
    /// # Errors
    /// Any other word, with the accepted ones.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "auc" => Ok(Self::Auc),
            "p20" | "p@20" | "precision" => Ok(Self::P20),
            "sr50" | "sr@0.5" => Ok(Self::Sr50),
            _ => Err(format!("criterion {s:?}: expected auc, p20 or sr50")),
        }
    }

    /// The column label.
    pub fn label(self) -> &'static str {
        match self {
            Self::Auc => "AUC",
            Self::P20 => "P@20",
            Self::Sr50 => "SR@0.5",
        }
    }

    fn of(self, r: &SequenceRow) -> Option<f64> {
        match self {
            Self::Auc => r.auc,
            Self::P20 => r.precision_20,
            Self::Sr50 => r.success_50,
        }
    }
}

/// What `bevt select` needs.
#[derive(Debug, Clone)]
pub struct SelectOptions {
    /// Candidates, `(name, eval output folder)`, the incumbent first.
    pub variants: Vec<(String, PathBuf)>,
    /// What the selection maximises.
    pub criterion: Criterion,
    /// Sequences to use (empty: every sequence of the first variant, which all must have).
    pub sequences: Vec<String>,
}

/// The parts of `summary.json` the selection reads.
#[derive(Debug, Deserialize)]
struct SummaryFile {
    sequences: Vec<SequenceRow>,
    #[serde(default)]
    perturb: Option<String>,
}

/// One sequence of `summary.json` (a failed sequence's scores are `null`).
#[derive(Debug, Deserialize)]
struct SequenceRow {
    name: String,
    status: String,
    #[serde(default)]
    error: Option<String>,
    precision_20: Option<f64>,
    auc: Option<f64>,
    success_50: Option<f64>,
}

fn read_summary(name: &str, dir: &Path) -> Result<SummaryFile> {
    let path = dir.join("summary.json");
    let text = std::fs::read_to_string(&path).with_context(|| {
        format!(
            "{name}: cannot read {} (a `bevt eval --out` folder?)",
            path.display()
        )
    })?;
    serde_json::from_str(&text)
        .with_context(|| format!("{name}: {} is not a `bevt eval` summary", path.display()))
}

/// The selection: one [`ScoreTable`] per criterion on the same variants and sequences, and
/// the LOSO run on the chosen criterion.
#[derive(Debug, Clone)]
pub struct SelectReport {
    /// The criterion the folds chose by.
    pub criterion: Criterion,
    /// The perturbation every variant was run under (`None`: the footage as is).
    pub perturb: Option<String>,
    /// Per-sequence scores, one table per criterion of [`Criterion::ALL`].
    pub tables: Vec<(Criterion, ScoreTable)>,
    /// The leave-one-sequence-out result on [`Self::criterion`].
    pub loso: Loso,
}

impl SelectReport {
    /// The table of one criterion.
    pub fn table(&self, c: Criterion) -> &ScoreTable {
        self.tables
            .iter()
            .find(|(k, _)| *k == c)
            .map(|(_, t)| t)
            .unwrap_or(&self.tables[0].1)
    }

    /// The mean of `c` over the folds' held-out sequences, each scored by its fold's choice.
    pub fn loso_mean_of(&self, c: Criterion) -> f64 {
        let t = self.table(c);
        let n = self.loso.folds.len().max(1) as f64;
        self.loso
            .folds
            .iter()
            .map(|f| t.score(f.chosen, f.held_out))
            .sum::<f64>()
            / n
    }
}

/// Reads every variant's summary, checks they are comparable and runs the selection.
///
/// # Errors
/// A missing or malformed `summary.json`, a sequence that failed or is missing in some
/// variant, variants run under different perturbations, fewer than two sequences, or a
/// repeated variant name.
pub fn select(opts: &SelectOptions) -> Result<SelectReport> {
    if opts.variants.is_empty() {
        bail!("no variant given: expected NAME=DIR... (bevt eval --out folders)");
    }
    let mut summaries = Vec::new();
    for (name, dir) in &opts.variants {
        summaries.push((name.as_str(), read_summary(name, dir)?));
    }
    let (first_name, first) = &summaries[0];
    let sequences: Vec<String> = if opts.sequences.is_empty() {
        first.sequences.iter().map(|r| r.name.clone()).collect()
    } else {
        opts.sequences.clone()
    };
    for (name, s) in &summaries {
        if s.perturb != first.perturb {
            bail!(
                "{name} was run with perturbation {} but {first_name} with {}: compare runs on the same footage",
                s.perturb.as_deref().unwrap_or("none"),
                first.perturb.as_deref().unwrap_or("none")
            );
        }
        if opts.sequences.is_empty() {
            let extra: Vec<&str> = s
                .sequences
                .iter()
                .map(|r| r.name.as_str())
                .filter(|n| !sequences.iter().any(|q| q == n))
                .collect();
            if !extra.is_empty() {
                bail!(
                    "{name} has sequences {first_name} has not ({}): give the common ones with --sequences",
                    extra.join(", ")
                );
            }
        }
    }
    let mut tables = Vec::new();
    for c in Criterion::ALL {
        let mut rows = Vec::new();
        for (name, s) in &summaries {
            let mut row = Vec::new();
            for q in &sequences {
                let r = s
                    .sequences
                    .iter()
                    .find(|r| &r.name == q)
                    .with_context(|| format!("{name} has no sequence {q:?}"))?;
                if r.status != "ok" {
                    bail!(
                        "{name}: sequence {q} failed in that run ({}); rerun it or leave it out with --sequences",
                        r.error.as_deref().unwrap_or("no reason given")
                    );
                }
                row.push(
                    c.of(r)
                        .with_context(|| format!("{name}: sequence {q} has no {}", c.label()))?,
                );
            }
            rows.push(row);
        }
        let names = summaries.iter().map(|(n, _)| n.to_string()).collect();
        tables.push((c, ScoreTable::new(names, sequences.clone(), rows)?));
    }
    let table = &tables
        .iter()
        .find(|(k, _)| *k == opts.criterion)
        .context("criterion table")?
        .1;
    let loso = leave_one_sequence_out(table);
    Ok(SelectReport {
        criterion: opts.criterion,
        perturb: first.perturb.clone(),
        tables,
        loso,
    })
}

/// The report as Markdown tables: the folds, the variants, the per-sequence scores.
pub fn render(r: &SelectReport) -> String {
    let c = r.criterion;
    let t = r.table(c);
    let seqs = t.sequences();
    let vars = t.variants();
    let n = seqs.len();
    let mut o = String::new();
    let _ = writeln!(
        o,
        "Leave-one-sequence-out over {n} sequences, {} variants, choosing by mean {} (ties: the earlier variant){}.\n",
        vars.len(),
        c.label(),
        r.perturb
            .as_ref()
            .map_or(String::new(), |p| format!("; perturbation {p}"))
    );
    let _ = writeln!(
        o,
        "| held out | chosen on the other {} | its mean {} there | held-out AUC | held-out P@20 | held-out SR@0.5 | best held-out {} (oracle) |",
        n - 1,
        c.label(),
        c.label()
    );
    let _ = writeln!(o, "|---|---|---|---|---|---|---|");
    for f in &r.loso.folds {
        let _ = writeln!(
            o,
            "| {} | {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} |",
            seqs[f.held_out],
            vars[f.chosen],
            f.train_mean,
            r.table(Criterion::Auc).score(f.chosen, f.held_out),
            r.table(Criterion::P20).score(f.chosen, f.held_out),
            r.table(Criterion::Sr50).score(f.chosen, f.held_out),
            f.oracle_score
        );
    }
    let oracle = r.loso.folds.iter().map(|f| f.oracle_score).sum::<f64>() / n as f64;
    let _ = writeln!(
        o,
        "| **LOSO mean** | | | **{:.3}** | **{:.3}** | **{:.3}** | {:.3} |\n",
        r.loso_mean_of(Criterion::Auc),
        r.loso_mean_of(Criterion::P20),
        r.loso_mean_of(Criterion::Sr50),
        oracle
    );
    let chosen = r.loso.times_chosen();
    let _ = writeln!(
        o,
        "| variant | full-set AUC | P@20 | SR@0.5 | chosen in folds |"
    );
    let _ = writeln!(o, "|---|---|---|---|---|");
    for (v, name) in vars.iter().enumerate() {
        let mean = |k: Criterion| {
            let tk = r.table(k);
            (0..n).map(|s| tk.score(v, s)).sum::<f64>() / n as f64
        };
        let mark = if v == r.loso.full_choice {
            " (full-set choice)"
        } else {
            ""
        };
        let _ = writeln!(
            o,
            "| {name}{mark} | {:.3} | {:.3} | {:.3} | {} of {n} |",
            mean(Criterion::Auc),
            mean(Criterion::P20),
            mean(Criterion::Sr50),
            chosen[v]
        );
    }
    let _ = writeln!(
        o,
        "\nFull-set choice {} at {} {:.3}; the selection's LOSO mean {:.3} (optimism {:+.3}).\n",
        vars[r.loso.full_choice],
        c.label(),
        r.loso.full_means[r.loso.full_choice],
        r.loso.loso_mean,
        r.loso.optimism()
    );
    let _ = write!(o, "Per sequence, {}:\n\n| variant |", c.label());
    for s in seqs {
        let _ = write!(o, " {s} |");
    }
    let _ = write!(o, "\n|---|");
    for _ in seqs {
        let _ = write!(o, "---|");
    }
    let _ = writeln!(o);
    for (v, name) in vars.iter().enumerate() {
        let _ = write!(o, "| {name} |");
        for s in 0..n {
            let _ = write!(o, " {:.3} |", t.score(v, s));
        }
        let _ = writeln!(o);
    }
    o
}
