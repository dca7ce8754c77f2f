//! The lost state of [`super::BevtTracker`]: the model frozen at the last confident frame,
//! and the bounded re-detection search of [`crate::redetect`] on every lost frame.
//!
//! This module owns everything about being lost; the tracker calls it once per frame:
//!
//! - [`start`] when a track is initialised (the re-detection template starts from the box);
//! - [`verified`] when a drift check ([`super::drift`]) agrees with the box: the model and
//!   template of that frame are the ones a drift loss freezes;
//! - [`after_decision`] on a tracked frame, right after the state machine decided: it keeps
//!   the template fresh on confident frames, freezes the model when the track stops being
//!   confident, and enters the search when the track is lost (on drift: with the model and
//!   template of the last agreeing check, from the drift point);
//! - [`search`] instead of tracking, on every frame while lost.
//!
//! It reads the tracker's geometry and position; only the freeze and the entry into the
//! search swap the tracker's filter, appearance model and ideal response.

use super::{BevtTracker, State};
use crate::confidence::{psr, Measures};
use crate::config::RedetectionConfig;
use crate::config::TrackerSpec;
use crate::error::TrackError;
use crate::geometry::Point2;
use crate::image::Frame;
use crate::redetect::nano::SEARCH_CELLS;
use crate::redetect::{
    candidate_threshold, context_side, propose, Appearance, Candidate, CandidateTracker, Proposal,
    ProposalScratch, Scored, SearchPlan, Verifier, VerifierHit,
};
use crate::track_state::TrackState;
use crate::tracker::TrackOutput;
use rustfft::num_complex::Complex32;

/// A search result within this many cells of the candidate is the candidate.
const CANDIDATE_NEAR_CELLS: f32 = 3.0;
/// Weight of each confident frame in the re-detection template's running mean.
const APPEARANCE_RATE: f32 = 0.05;
/// Consensus reported while lost (no response is compared with the ideal model).
const LOST_CONSENSUS: f32 = 0.0;
/// Spacing of the verifier's tiles, fraction of its search region (the head's grid covers
/// the whole crop).
const VERIFIER_TILE_STRIDE: f32 = 0.75;
/// A verifier hit within this fraction of the context side of the verifier's candidate is
/// the candidate.
const VERIFIER_NEAR: f32 = 0.5;

/// The frozen filter's most confident window of a lost frame: its confidence and peak
/// score (reported with the frame) and where it points (the hint for the verifier,
/// `redetection.verifier_filter_hint`).
#[derive(Debug, Clone, Copy)]
struct BestWindow {
    confidence: f32,
    peak: f32,
    pos: Point2,
    scale: f32,
}

impl BestWindow {
    /// Keeps the window (`(pos, confidence, peak)` at `scale`) when it is more confident.
    fn offer(&mut self, (pos, confidence, peak): (Point2, f32, f32), scale: f32) {
        if confidence > self.confidence {
            *self = Self {
                confidence,
                peak,
                pos,
                scale,
            };
        }
    }
}

/// A saved model: filter, appearance model and ideal response, position and scale, and the
/// learning gate's reference level of the score.
#[derive(Debug, Default)]
struct Snapshot {
    g_f: Vec<Complex32>,
    model_xf: Vec<Complex32>,
    m_ideal: Vec<f32>,
    pos: Point2,
    scale: f32,
    reference: f32,
    saved: bool,
}

impl Snapshot {
    fn take(&mut self, st: &State) {
        self.g_f.clone_from(&st.g_f);
        self.model_xf.clone_from(&st.model_xf);
        self.m_ideal.clone_from(&st.m_ideal);
        self.pos = st.pos;
        self.scale = st.scale;
        self.reference = st.confidence.reference();
        self.saved = true;
    }
}

/// What the tracker keeps for, and while, being lost.
#[derive(Debug, Default)]
pub(super) struct LostState {
    /// The model of the last confident frame.
    last: Snapshot,
    /// The model and re-detection template of the last frame a drift check agreed with.
    verified: Snapshot,
    verified_appearance: Appearance,
    /// The learning gate's reference level of the frozen model.
    reference: f32,
    /// The search.
    plan: SearchPlan,
    candidates: CandidateTracker,
    scale_at_loss: f32,
    /// Confidence a window needs to be a candidate ([`candidate_threshold`]).
    threshold: f32,
    /// The re-detection template, kept from confident frames, and the proposal buffers.
    appearance: Appearance,
    scratch: ProposalScratch,
    /// The learned verifier's whole-frame tiles and its own candidate.
    vplan: SearchPlan,
    vcand: CandidateTracker,
}

/// Side of the square the re-detection template covers at `scale`, pixels.
fn template_side(st: &State, scale: f32) -> f32 {
    (st.geo.base_target.w * st.geo.base_target.h).sqrt() * scale
}

/// A new track on `frame`: the re-detection template is the initial box.
pub(super) fn start(st: &mut State, frame: &Frame<'_>) {
    observe(st, frame, true);
    st.lost.verified.saved = false;
}

/// The lost search's candidates (the filter's and the verifier's) moved by `f`: the scene
/// moved under the camera since the previous frame (`motion.camera`).
pub(super) fn move_with_scene(st: &mut State, f: impl Fn(Point2) -> Point2) {
    st.lost.candidates.move_by(&f);
    st.lost.vcand.move_by(&f);
}

/// A drift check agreed with the box on this (confident, not yet learned) frame: the
/// model and the re-detection template are the target's, and are what a loss on drift
/// goes back to.
pub(super) fn verified(st: &mut State) {
    let mut v = std::mem::take(&mut st.lost.verified);
    v.take(st);
    st.lost.verified = v;
    st.lost.verified_appearance.clone_from(&st.lost.appearance);
}

/// A tracked frame whose state the state machine has just decided (`before` → `state`).
/// Returns `true` when the track is now lost: the tracker then reports the frame and
/// stops (no learning); [`search`] takes the next frames.
///
/// The template is blended before the frame is learned, which leaves it as it was when it
/// was blended after: learning changes the filter, not the position, scale or frame.
pub(super) fn after_decision(
    st: &mut State,
    frame: &Frame<'_>,
    spec: &TrackerSpec,
    before: TrackState,
    state: TrackState,
) -> bool {
    let was_confident = matches!(before, TrackState::Tracking | TrackState::Reacquired);
    let drifted = st.states.drifted();
    if state != TrackState::Tracking && was_confident && !drifted {
        let mut last = std::mem::take(&mut st.lost.last);
        last.take(st);
        st.lost.last = last;
    }
    match state {
        TrackState::Lost if drifted => {
            enter_on_drift(st, spec);
            true
        }
        TrackState::Lost => {
            enter(st, spec);
            true
        }
        TrackState::Tracking => {
            observe(st, frame, false);
            false
        }
        _ => false,
    }
}

/// A confident frame (or the initial one, `first`): blends the target into the
/// re-detection template.
fn observe(st: &mut State, frame: &Frame<'_>, first: bool) {
    let side = template_side(st, st.scale);
    let rate = if first { 1.0 } else { APPEARANCE_RATE };
    st.lost.appearance.observe(frame, st.pos, side, rate);
}

/// Swaps the model saved in `snap` in (its position and scale too when `to_saved_pos`).
fn restore(st: &mut State, snap: &mut Snapshot, to_saved_pos: bool) {
    std::mem::swap(&mut st.g_f, &mut snap.g_f);
    std::mem::swap(&mut st.model_xf, &mut snap.model_xf);
    std::mem::swap(&mut st.m_ideal, &mut snap.m_ideal);
    if to_saved_pos {
        st.pos = snap.pos;
        st.scale = snap.scale;
    }
    snap.saved = false;
}

/// Enters the lost state: restores the last confident model and position, plans the search.
fn enter(st: &mut State, spec: &TrackerSpec) {
    let mut last = std::mem::take(&mut st.lost.last);
    st.lost.reference = last.reference;
    if last.saved {
        restore(st, &mut last, true);
    }
    st.lost.last = last;
    plan(st, spec);
}

/// Enters the lost state on drift: the box is on something else, so the model (and the
/// re-detection template) it has learned since the last agreeing check is not the
/// target's. Restores those of the last agreeing check (the current ones when no check
/// agreed yet) and plans the search from the drift point (the current position and
/// scale), where the target was last seen going.
fn enter_on_drift(st: &mut State, spec: &TrackerSpec) {
    let mut v = std::mem::take(&mut st.lost.verified);
    if v.saved {
        st.lost.reference = v.reference;
        restore(st, &mut v, false);
        std::mem::swap(&mut st.lost.appearance, &mut st.lost.verified_appearance);
    } else {
        st.lost.reference = st.confidence.reference();
    }
    st.lost.verified = v;
    plan(st, spec);
}

/// Plans the search from the current position and scale.
fn plan(st: &mut State, spec: &TrackerSpec) {
    let l = &mut st.lost;
    l.scale_at_loss = st.scale;
    let confidence = &st.confidence;
    l.threshold = candidate_threshold(&spec.config.redetection, l.reference, |s| {
        confidence.confidence(s)
    });
    l.candidates.clear();
    l.plan = SearchPlan::new(
        st.pos,
        st.frame_w,
        st.frame_h,
        st.geo.patch_side as f32 * st.scale,
        &spec.config.redetection,
    );
    let r = &spec.config.redetection;
    let vparams = RedetectionConfig {
        scales: r.verifier_scales.clone(),
        tile_stride: VERIFIER_TILE_STRIDE,
        ..spec.config.redetection.clone()
    };
    let vside = tile_side(st, r.verifier_tile_cells, st.scale);
    st.lost.vcand.clear();
    st.lost.vplan = SearchPlan::new(st.pos, st.frame_w, st.frame_h, vside, &vparams);
}

/// Side of a verifier crop of `cells` grid points at absolute `scale`, pixels: NanoTrack's
/// search region (twice the context side for its 255-pixel crop, 16 cells, exactly) grown
/// with the crop at the same resolution (`redetection.verifier_tile_cells` for the tiles).
fn tile_side(st: &State, cells: usize, scale: f32) -> f32 {
    let search = 2.0 * verifier_side(st, scale);
    match cells {
        SEARCH_CELLS => search,
        cells => search * (16 * cells - 1) as f32 / (16 * SEARCH_CELLS - 1) as f32,
    }
}

/// The verifier's template context side at absolute `scale`, pixels.
fn verifier_side(st: &State, scale: f32) -> f32 {
    context_side(st.geo.base_target.w * scale, st.geo.base_target.h * scale)
}

/// The absolute tracker scale of a verifier hit's box.
fn hit_scale(st: &State, hit: &VerifierHit) -> f32 {
    let base = (st.geo.base_target.w * st.geo.base_target.h).sqrt();
    let s = (hit.w * hit.h).sqrt() / base.max(f32::EPSILON);
    if s.is_finite() {
        s.clamp(st.min_scale, st.max_scale)
    } else {
        st.lost.scale_at_loss
    }
}

/// One lost frame of the learned verifier: follow its candidate (one pass while it holds),
/// or spend `verifier_windows` on the whole-frame tiles, the first of them (with
/// `verifier_filter_hint`) on `hint`, the frozen filter's most confident window of the
/// frame (position and absolute scale): the cheap witness points, the learned one looks
/// there before it walks on; then (with `verifier_proposals`) on the frame's best
/// template-match proposals at the scale of the loss (`proposals`, the filter's of this
/// frame, matched again only when they are fewer). The candidate once it has been above
/// `verifier_threshold` for `reacquire_frames` frames in a row and (with
/// `verifier_filter_check`) the frozen filter makes it a candidate too. A candidate the
/// filter refuses is dropped (it must be confirmed anew).
fn verify(
    st: &mut State,
    frame: &Frame<'_>,
    spec: &TrackerSpec,
    v: &mut dyn Verifier,
    hint: (Point2, f32),
    proposals: &[Proposal],
) -> Result<Option<Candidate>, TrackError> {
    let r = &spec.config.redetection;
    let thr = r.verifier_threshold;
    let near = VERIFIER_NEAR * verifier_side(st, st.lost.scale_at_loss);
    st.lost.vcand.begin_frame(near);
    let mut passes = r.verifier_windows;
    // Only hits at or above `thr` can be followed or offered: below it the box is not
    // needed (`followed` drops the candidate, `offer` ignores the hit; the head's outputs
    // are checked finite, so a score is never NaN).
    if let Some(c) = st.lost.vcand.current() {
        st.verifier_passes += 1;
        let hit = v.search_above(frame, c.pos, 2.0 * verifier_side(st, c.scale), thr)?;
        match hit {
            Some(Scored::Hit(h)) => {
                let scale = hit_scale(st, &h);
                st.lost.vcand.followed(h.pos, scale, h.score, thr);
            }
            Some(Scored::Below(s)) => st.lost.vcand.followed(c.pos, c.scale, s, thr),
            None => st
                .lost
                .vcand
                .followed(c.pos, c.scale, f32::NEG_INFINITY, thr),
        }
        // A candidate that holds is being confirmed: the frame costs this one pass. The
        // tiles could only replace it with a higher-scoring hit elsewhere during its
        // `reacquire_frames` frames; a candidate that fails (its score below the bar, or
        // the filter check) sends the search back to the tiles, this frame or the next.
        passes = if st.lost.vcand.current().is_some() {
            0
        } else {
            passes.saturating_sub(1)
        };
    }
    let at_loss = st.lost.scale_at_loss;
    // The match only when tile passes are left (a candidate being followed takes none) and
    // the filter's sweep did not already find as many.
    let wanted = r.verifier_proposals.min(passes);
    let own;
    let proposals = if proposals.len() >= wanted {
        proposals
    } else {
        let side = template_side(st, at_loss);
        let l = &mut st.lost;
        own = propose(frame, &l.appearance, side, wanted, &mut l.scratch);
        &own[..]
    };
    let mut firsts = r
        .verifier_filter_hint
        .then_some(hint)
        .into_iter()
        .chain(proposals.iter().take(wanted).map(|p| (p.center, at_loss)));
    for _ in 0..passes {
        // The hint and the proposals point at one place: NanoTrack's own crop there. The
        // walk's tiles cover the frame: `verifier_tile_cells` grid points each.
        let (center, scale, cells) = match firsts.next() {
            Some((c, s)) => (c, s, SEARCH_CELLS),
            None => {
                let Some(w) = st.lost.vplan.next_window() else {
                    break;
                };
                let scale = st.lost.scale_at_loss * w.scale;
                (w.center, scale, r.verifier_tile_cells)
            }
        };
        let side = tile_side(st, cells, scale);
        st.verifier_passes += 1;
        if let Some(Scored::Hit(h)) = v.search_above_cells(frame, center, side, thr, cells)? {
            let scale = hit_scale(st, &h);
            st.lost.vcand.offer(h.pos, scale, h.score, thr);
        }
    }
    let Some(c) = st.lost.vcand.end_frame(r.reacquire_frames) else {
        return Ok(None);
    };
    if r.verifier_filter_check {
        // The second witness: the frozen filter must find a candidate there too.
        let (_, conf, _) = evaluate(st, frame, c.pos, c.scale, spec)?;
        if conf.is_nan() || conf < st.lost.threshold {
            st.lost.vcand.clear();
            return Ok(None);
        }
    }
    Ok(Some(c))
}

/// One search window at `center` and absolute `scale`: the position the frozen filter
/// points to and its confidence.
fn evaluate(
    st: &mut State,
    frame: &Frame<'_>,
    center: Point2,
    scale: f32,
    spec: &TrackerSpec,
) -> Result<(Point2, f32, f32), TrackError> {
    let side = st.geo.patch_side;
    let region = side as f32 * scale;
    st.sampler.prepare(frame, center, region, region, side);
    let State {
        workers,
        sampler,
        window,
        g_f,
        layers,
        geo,
        ..
    } = st;
    let w = &mut workers[0];
    w.detect(
        sampler,
        center,
        region,
        geo.cell,
        window,
        g_f,
        layers,
        spec.config.detection.newton_iterations,
    )?;
    let step = geo.cell as f32 * scale;
    let pos = Point2 {
        x: (center.x + w.peak.dx * step).clamp(0.0, st.frame_w as f32),
        y: (center.y + w.peak.dy * step).clamp(0.0, st.frame_h as f32),
    };
    let m = Measures {
        peak: w.peak.score,
        psr: psr(
            &w.resp,
            geo.grid,
            spec.config.confidence.psr_exclusion_cells,
        ),
    };
    let pos = if pos.x.is_finite() && pos.y.is_finite() {
        pos
    } else {
        center
    };
    let c = st.confidence.confidence(st.confidence.score(m));
    Ok((pos, c, w.peak.score))
}

/// One lost frame: follow the candidate, spend the rest of the budget on the plan, take the
/// track back once a candidate has been confident for long enough.
pub(super) fn search(
    st: &mut State,
    frame: &Frame<'_>,
    spec: &TrackerSpec,
    verifier: Option<&mut (dyn Verifier + 'static)>,
) -> Result<TrackOutput, TrackError> {
    let p = &spec.config.redetection;
    let threshold = st.lost.threshold;
    let near = st.geo.cell as f32 * st.scale * CANDIDATE_NEAR_CELLS;
    st.lost.candidates.begin_frame(near);
    let mut budget = p.windows_per_frame;
    // The window at the current position, followed with the frozen filter.
    let (scale, cand) = (st.scale, st.lost.candidates.current());
    let (pos, conf, peak) = evaluate(st, frame, st.pos, scale, spec)?;
    st.pos = pos;
    let mut best = BestWindow {
        confidence: conf,
        peak,
        pos,
        scale,
    };
    budget = budget.saturating_sub(1);
    match cand {
        Some(_) if st.lost.candidates.is_candidate(pos) => {
            st.lost.candidates.followed(pos, scale, conf, threshold);
        }
        Some(c) => {
            let (cpos, cconf, cpeak) = evaluate(st, frame, c.pos, c.scale, spec)?;
            best.offer((cpos, cconf, cpeak), c.scale);
            st.lost.candidates.followed(cpos, c.scale, cconf, threshold);
            st.lost.candidates.offer(pos, scale, conf, threshold);
            budget = budget.saturating_sub(1);
        }
        None => st.lost.candidates.offer(pos, scale, conf, threshold),
    }
    // The rest of the budget sweeps the frame, unless the verifier does that
    // (`filter_search`): the window above follows the last position either way.
    if !p
        .filter_search
        .sweeps(verifier.is_some() && p.enabled, p.verifier_filter_hint)
    {
        budget = 0;
    }
    // Whole-frame template-match proposals, at the scale of the loss.
    let side = template_side(st, st.lost.scale_at_loss);
    let wanted = if p.enabled {
        p.proposals.min(budget)
    } else {
        0
    };
    let proposals = propose(
        frame,
        &st.lost.appearance,
        side,
        wanted,
        &mut st.lost.scratch,
    );
    for pr in proposals.iter().copied() {
        let scale = st.lost.scale_at_loss;
        let (pos, conf, peak) = evaluate(st, frame, pr.center, scale, spec)?;
        best.offer((pos, conf, peak), scale);
        st.lost.candidates.offer(pos, scale, conf, threshold);
        budget = budget.saturating_sub(1);
    }
    for _ in 0..budget {
        let Some(w) = st.lost.plan.next_window() else {
            break;
        };
        let scale = (st.lost.scale_at_loss * w.scale).clamp(st.min_scale, st.max_scale);
        let (pos, conf, peak) = evaluate(st, frame, w.center, scale, spec)?;
        best.offer((pos, conf, peak), scale);
        st.lost.candidates.offer(pos, scale, conf, threshold);
    }
    let accepted = match st.lost.candidates.end_frame(p.reacquire_frames) {
        Some(c) => Some(c),
        None => match verifier {
            Some(v) if p.enabled => verify(st, frame, spec, v, (best.pos, best.scale), &proposals)?
                .map(|c| Candidate {
                    confidence: best.confidence.max(st.lost.threshold),
                    ..c
                }),
            _ => None,
        },
    };
    if let Some(c) = accepted {
        st.pos = c.pos;
        st.scale = c.scale;
        st.lost.candidates.clear();
        st.lost.vcand.clear();
        let (state, reason) = st.states.reacquired();
        return Ok(BevtTracker::output_at(
            st,
            c.pos,
            c.scale,
            (LOST_CONSENSUS, false, best.peak),
            (c.confidence, state, reason),
        ));
    }
    let (state, reason) = st.states.searching(best.confidence);
    let (pos, scale, conf) = match st.lost.candidates.current() {
        Some(c) => (c.pos, c.scale, c.confidence),
        None => (st.pos, st.scale, best.confidence),
    };
    Ok(BevtTracker::output_at(
        st,
        pos,
        scale,
        (LOST_CONSENSUS, false, best.peak),
        (conf, state, reason),
    ))
}
