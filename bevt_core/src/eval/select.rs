//! Leave-one-sequence-out (LOSO) selection: how well does "pick the variant with the best
//! mean score" do on a sequence it did not see?
//!
//! For each held-out sequence, the variant with the best mean criterion over the *other*
//! sequences is chosen and scored on the held-out one. The mean of those held-out scores
//! (the LOSO mean) estimates what the selection rule itself is worth on unseen footage;
//! the best full-set mean is that estimate's optimistic counterpart (the choice has seen the
//! sequences it is scored on). A large gap between the two says the full-set ranking fits
//! the set.
//!
//! Ties are broken towards the earlier variant, so the incumbent should be listed first:
//! a challenger must be strictly better to be chosen.

use thiserror::Error;

/// Why a score table cannot be used.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum SelectError {
    /// No variant was given.
    #[error("no variant to choose from")]
    NoVariants,
    /// Fewer than two sequences: nothing is left to choose on once one is held out.
    #[error("leave-one-sequence-out needs at least 2 sequences, got {0}")]
    TooFewSequences(usize),
    /// A variant's scores do not have one value per sequence.
    #[error("variant {variant:?} has {got} scores for {expected} sequences")]
    Shape {
        /// The variant.
        variant: String,
        /// Its number of scores.
        got: usize,
        /// The number of sequences.
        expected: usize,
    },
    /// A score is NaN or infinite.
    #[error("variant {variant:?}, sequence {sequence:?}: score {value} is not finite")]
    NonFinite {
        /// The variant.
        variant: String,
        /// The sequence.
        sequence: String,
        /// The value.
        value: f64,
    },
    /// The same name was given twice.
    #[error("{kind} {name:?} is given twice")]
    Duplicate {
        /// `variant` or `sequence`.
        kind: &'static str,
        /// The repeated name.
        name: String,
    },
}

/// Per-sequence scores of several variants on the same sequences (higher is better).
#[derive(Debug, Clone, PartialEq)]
pub struct ScoreTable {
    variants: Vec<String>,
    sequences: Vec<String>,
    /// `scores[v][s]`.
    scores: Vec<Vec<f64>>,
}

impl ScoreTable {
    /// Checks and stores `scores[v][s]` for `variants[v]` on `sequences[s]`.
    ///
    /// # Errors
    /// No variant, fewer than two sequences, a repeated name, a row of the wrong length or
    /// a non-finite score.
    pub fn new(
        variants: Vec<String>,
        sequences: Vec<String>,
        scores: Vec<Vec<f64>>,
    ) -> Result<Self, SelectError> {
        if variants.is_empty() {
            return Err(SelectError::NoVariants);
        }
        if sequences.len() < 2 {
            return Err(SelectError::TooFewSequences(sequences.len()));
        }
        for (kind, names) in [("variant", &variants), ("sequence", &sequences)] {
            for (i, n) in names.iter().enumerate() {
                if names[..i].contains(n) {
                    return Err(SelectError::Duplicate {
                        kind,
                        name: n.clone(),
                    });
                }
            }
        }
        if scores.len() != variants.len() {
            return Err(SelectError::Shape {
                variant: format!("({} rows for {} variants)", scores.len(), variants.len()),
                got: scores.len(),
                expected: variants.len(),
            });
        }
        for (v, row) in scores.iter().enumerate() {
            if row.len() != sequences.len() {
                return Err(SelectError::Shape {
                    variant: variants[v].clone(),
                    got: row.len(),
                    expected: sequences.len(),
                });
            }
            if let Some((s, &value)) = row.iter().enumerate().find(|(_, x)| !x.is_finite()) {
                return Err(SelectError::NonFinite {
                    variant: variants[v].clone(),
                    sequence: sequences[s].clone(),
                    value,
                });
            }
        }
        Ok(Self {
            variants,
            sequences,
            scores,
        })
    }

    /// Variant names, in the order given (ties go to the earlier one).
    pub fn variants(&self) -> &[String] {
        &self.variants
    }

    /// Sequence names.
    pub fn sequences(&self) -> &[String] {
        &self.sequences
    }

    /// Score of variant `v` on sequence `s`.
    pub fn score(&self, v: usize, s: usize) -> f64 {
        self.scores[v][s]
    }

    /// Mean score of variant `v` over every sequence except `skip`.
    fn mean_without(&self, v: usize, skip: Option<usize>) -> f64 {
        let row = &self.scores[v];
        let (sum, n) = row
            .iter()
            .enumerate()
            .filter(|(s, _)| Some(*s) != skip)
            .fold((0.0, 0usize), |(a, n), (_, x)| (a + x, n + 1));
        sum / n as f64
    }

    /// The variant with the best mean over every sequence except `skip` (the earliest on a
    /// tie), and that mean.
    fn best_without(&self, skip: Option<usize>) -> (usize, f64) {
        let mut best = (0, self.mean_without(0, skip));
        for v in 1..self.variants.len() {
            let m = self.mean_without(v, skip);
            if m > best.1 {
                best = (v, m);
            }
        }
        best
    }
}

/// One fold: the sequence held out and what the selection did without it.
#[derive(Debug, Clone, PartialEq)]
pub struct Fold {
    /// Index of the held-out sequence.
    pub held_out: usize,
    /// Index of the variant chosen on the other sequences.
    pub chosen: usize,
    /// The chosen variant's mean over the other sequences.
    pub train_mean: f64,
    /// The chosen variant's score on the held-out sequence.
    pub held_out_score: f64,
    /// The best score any variant reached on the held-out sequence (an oracle bound).
    pub oracle_score: f64,
}

/// The result of [`leave_one_sequence_out`].
#[derive(Debug, Clone, PartialEq)]
pub struct Loso {
    /// One fold per sequence, in the table's sequence order.
    pub folds: Vec<Fold>,
    /// Mean of the held-out scores: the selection rule's estimated worth on unseen footage.
    pub loso_mean: f64,
    /// Each variant's mean over every sequence.
    pub full_means: Vec<f64>,
    /// The variant with the best full-set mean (what the full set alone would choose).
    pub full_choice: usize,
}

impl Loso {
    /// How many folds chose each variant.
    pub fn times_chosen(&self) -> Vec<usize> {
        let n = self.full_means.len();
        let mut c = vec![0; n];
        for f in &self.folds {
            c[f.chosen] += 1;
        }
        c
    }

    /// The best full-set mean minus the LOSO mean: how much the full-set figure flatters
    /// the choice (0 when every fold chose the same variant).
    pub fn optimism(&self) -> f64 {
        self.full_means[self.full_choice] - self.loso_mean
    }
}

/// Runs leave-one-sequence-out selection on `table` (see the module documentation).
pub fn leave_one_sequence_out(table: &ScoreTable) -> Loso {
    let n = table.sequences.len();
    let folds: Vec<Fold> = (0..n)
        .map(|s| {
            let (chosen, train_mean) = table.best_without(Some(s));
            let oracle_score = (0..table.variants.len())
                .map(|v| table.score(v, s))
                .fold(f64::NEG_INFINITY, f64::max);
            Fold {
                held_out: s,
                chosen,
                train_mean,
                held_out_score: table.score(chosen, s),
                oracle_score,
            }
        })
        .collect();
    let loso_mean = folds.iter().map(|f| f.held_out_score).sum::<f64>() / n as f64;
    let full_means = (0..table.variants.len())
        .map(|v| table.mean_without(v, None))
        .collect();
    let (full_choice, _) = table.best_without(None);
    Loso {
        folds,
        loso_mean,
        full_means,
        full_choice,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(p: &str, n: usize) -> Vec<String> {
        (0..n).map(|i| format!("{p}{i}")).collect()
    }

    #[test]
    fn hand_computed_three_by_three() {
        // Variant a is steady; b wins big on s0 only; c wins a little on s1 and s2.
        //        s0   s1   s2   mean
        // a     0.5  0.5  0.5  0.5
        // b     0.9  0.3  0.3  0.5
        // c     0.2  0.6  0.6  0.4667
        let t = ScoreTable::new(
            vec!["a".into(), "b".into(), "c".into()],
            names("s", 3),
            vec![
                vec![0.5, 0.5, 0.5],
                vec![0.9, 0.3, 0.3],
                vec![0.2, 0.6, 0.6],
            ],
        )
        .unwrap();
        let r = leave_one_sequence_out(&t);
        // Hold out s0: means on s1, s2 are a 0.5, b 0.3, c 0.6 -> c, scores 0.2 on s0.
        // Hold out s1: a 0.5, b 0.6, c 0.4 -> b, scores 0.3. Hold out s2: the same, b, 0.3.
        let chosen: Vec<usize> = r.folds.iter().map(|f| f.chosen).collect();
        assert_eq!(chosen, vec![2, 1, 1]);
        let held: Vec<f64> = r.folds.iter().map(|f| f.held_out_score).collect();
        assert_eq!(held, vec![0.2, 0.3, 0.3]);
        assert!((r.folds[0].train_mean - 0.6).abs() < 1e-12);
        assert!((r.folds[1].train_mean - 0.6).abs() < 1e-12);
        assert_eq!(r.folds[0].oracle_score, 0.9);
        assert!((r.loso_mean - 0.8 / 3.0).abs() < 1e-12);
        // Full set: a and b tie at 0.5; the earlier (a) is the full-set choice.
        assert_eq!(r.full_choice, 0);
        assert!((r.full_means[2] - 1.4 / 3.0).abs() < 1e-12);
        assert!((r.optimism() - (0.5 - 0.8 / 3.0)).abs() < 1e-12);
        assert_eq!(r.times_chosen(), vec![0, 2, 1]);
    }

    #[test]
    fn a_variant_best_everywhere_is_chosen_in_every_fold() {
        let t = ScoreTable::new(
            vec!["base".into(), "better".into()],
            names("s", 4),
            vec![vec![0.4, 0.5, 0.6, 0.1], vec![0.5, 0.6, 0.7, 0.2]],
        )
        .unwrap();
        let r = leave_one_sequence_out(&t);
        assert!(r.folds.iter().all(|f| f.chosen == 1));
        assert!((r.loso_mean - r.full_means[1]).abs() < 1e-12);
        assert!(r.optimism().abs() < 1e-12);
    }

    #[test]
    fn ties_go_to_the_earlier_variant() {
        let t = ScoreTable::new(
            vec!["incumbent".into(), "challenger".into()],
            names("s", 2),
            vec![vec![0.5, 0.5], vec![0.5, 0.5]],
        )
        .unwrap();
        let r = leave_one_sequence_out(&t);
        assert!(r.folds.iter().all(|f| f.chosen == 0));
        assert_eq!(r.full_choice, 0);
    }

    #[test]
    fn bad_tables_are_refused_with_the_reason() {
        let two = || names("s", 2);
        assert_eq!(
            ScoreTable::new(vec![], two(), vec![]),
            Err(SelectError::NoVariants)
        );
        assert_eq!(
            ScoreTable::new(vec!["a".into()], names("s", 1), vec![vec![0.5]]),
            Err(SelectError::TooFewSequences(1))
        );
        let e = ScoreTable::new(vec!["a".into()], two(), vec![vec![0.5]]).unwrap_err();
        assert!(e.to_string().contains("\"a\" has 1 scores for 2"), "{e}");
        let e = ScoreTable::new(vec!["a".into()], two(), vec![vec![0.5, f64::NAN]]).unwrap_err();
        assert!(e.to_string().contains("\"s1\""), "{e}");
        let e = ScoreTable::new(
            vec!["a".into(), "a".into()],
            two(),
            vec![vec![0.5, 0.5], vec![0.5, 0.5]],
        )
        .unwrap_err();
        assert!(
            e.to_string().contains("variant \"a\" is given twice"),
            "{e}"
        );
        let e = ScoreTable::new(
            vec!["a".into()],
            vec!["x".into(), "x".into()],
            vec![vec![0.5, 0.5]],
        )
        .unwrap_err();
        assert!(e.to_string().contains("sequence \"x\""), "{e}");
        let e =
            ScoreTable::new(vec!["a".into(), "b".into()], two(), vec![vec![0.5, 0.5]]).unwrap_err();
        assert!(matches!(e, SelectError::Shape { .. }), "{e}");
    }
}
