//! Runs a tracker over a sequence of image files: frames are decoded on a named prefetch
//! thread while the tracker works ([`Decode::Ahead`]) or on the tracking thread between
//! frames ([`Decode::Inline`]), and only `init`/`update` are timed.
//!
//! Failures (an unreadable frame, a tracker error) end the run early with the reason;
//! every box computed before that is kept.

use crate::tool::dataset::{DatasetError, Sequence, SequenceEntry};
use bevt_core::eval::perturb::{Perturbation, SequencePerturbation};
use bevt_core::{BBox, Frame, PixelFormat, TrackOutput, Tracker};
use std::path::PathBuf;
use std::sync::mpsc;
use std::time::Instant;

/// Frames decoded ahead of the tracker.
const PREFETCH_FRAMES: usize = 4;

/// A decoded RGB frame.
pub type RgbFrame = image::RgbImage;

/// The result of tracking one sequence.
#[derive(Debug, Clone, Default)]
pub struct TrackRun {
    /// Box per frame processed (`None` before the initial frame).
    pub boxes: Vec<Option<BBox>>,
    /// Tracker output per frame processed (`None` for the init frame and before it).
    pub outputs: Vec<Option<TrackOutput>>,
    /// Frames given to the tracker (init included).
    pub frames_tracked: usize,
    /// Seconds spent in `init` and `update`.
    pub track_seconds: f64,
    /// Frames the filter learned from (init excluded).
    pub learned: usize,
    /// Frames verification rejected.
    pub skipped: usize,
    /// Why the run stopped early, if it did.
    pub error: Option<String>,
    /// The run stopped because the tracker refused the initial box.
    pub init_failed: bool,
    /// The tracker's learned-verifier search passes over the run
    /// ([`bevt_core::tracker::Tracker::verifier_passes`]; `None` without a verifier).
    pub verifier_passes: Option<u64>,
}

impl TrackRun {
    /// Frames per second of tracking time (init and updates; decode excluded).
    pub fn fps(&self) -> f64 {
        if self.track_seconds > 0.0 {
            self.frames_tracked as f64 / self.track_seconds
        } else {
            0.0
        }
    }
}

/// Where a run's frames are decoded (`bevt eval --decode`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Decode {
    /// On a prefetch thread while the tracker works: the shortest run.
    #[default]
    Ahead,
    /// On the tracking thread, between frames and outside the timed calls: nothing runs
    /// beside the tracker while it is timed (the peers' harnesses decode so, e.g.
    /// `scripts/nanotrack_peer.py`); for speed comparisons.
    Inline,
}

impl Decode {
    /// The name `--decode` takes and `summary.json` records.
    pub fn name(self) -> &'static str {
        match self {
            Self::Ahead => "ahead",
            Self::Inline => "inline",
        }
    }
}

impl std::str::FromStr for Decode {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "ahead" => Ok(Self::Ahead),
            "inline" => Ok(Self::Inline),
            _ => Err(format!("{s:?}: expected 'ahead' or 'inline'")),
        }
    }
}

/// A run's decoded frames, in order.
pub type Frames = Box<dyn Iterator<Item = Result<RgbFrame, String>> + Send>;

/// Decodes `paths` on a background thread, in order.
///
/// # Errors
/// Each item is `Err(reason)` for a frame that cannot be read or decoded.
pub fn decode_ahead(paths: Vec<PathBuf>) -> impl Iterator<Item = Result<RgbFrame, String>> {
    decode_ahead_with(paths, |_, img| Ok(img))
}

/// Frame `i` of `p` decoded to RGB and passed through `map(i, frame)`.
fn decode_one(
    i: usize,
    p: &std::path::Path,
    map: &impl Fn(usize, RgbFrame) -> Result<RgbFrame, String>,
) -> Result<RgbFrame, String> {
    image::open(p)
        .map(|i| i.to_rgb8())
        .map_err(|e| format!("{}: {e}", p.display()))
        .and_then(|img| map(i, img).map_err(|e| format!("{}: {e}", p.display())))
}

/// `paths` decoded as `decode` says, each frame `i` passed through `map(i, frame)`.
///
/// # Errors
/// Each item is `Err(reason)` for a frame that cannot be read, decoded or mapped.
pub fn decode_frames(
    paths: Vec<PathBuf>,
    decode: Decode,
    map: impl Fn(usize, RgbFrame) -> Result<RgbFrame, String> + Send + 'static,
) -> Frames {
    match decode {
        Decode::Ahead => Box::new(decode_ahead_with(paths, map)),
        Decode::Inline => Box::new(
            paths
                .into_iter()
                .enumerate()
                .map(move |(i, p)| decode_one(i, &p, &map)),
        ),
    }
}

/// [`decode_ahead`], passing frame `i` through `map(i, frame)` on the decoding thread.
///
/// # Errors
/// Each item is `Err(reason)` for a frame that cannot be read, decoded or mapped.
pub fn decode_ahead_with(
    paths: Vec<PathBuf>,
    map: impl Fn(usize, RgbFrame) -> Result<RgbFrame, String> + Send + 'static,
) -> impl Iterator<Item = Result<RgbFrame, String>> {
    let (tx, rx) = mpsc::sync_channel(PREFETCH_FRAMES);
    let spawned = std::thread::Builder::new()
        .name("bevt-decode".into())
        .spawn(move || {
            for (i, p) in paths.into_iter().enumerate() {
                if tx.send(decode_one(i, &p, &map)).is_err() {
                    break;
                }
            }
        });
    let failed = spawned
        .err()
        .map(|e| format!("cannot start the decoder thread: {e}"));
    failed.into_iter().map(Err).chain(rx)
}

/// Tracks over `feed`, initialising with `init` on frame `init_index` (frames before it are
/// decoded and skipped). `on_frame(i, output)` is called after every processed frame.
pub fn track_feed<I>(
    tracker: &mut dyn Tracker,
    feed: I,
    init_index: usize,
    init: BBox,
    mut on_frame: impl FnMut(usize, Option<&TrackOutput>),
) -> TrackRun
where
    I: Iterator<Item = Result<RgbFrame, String>>,
{
    let mut run = TrackRun::default();
    for (i, item) in feed.enumerate() {
        let img = match item {
            Ok(img) => img,
            Err(e) => {
                run.error = Some(format!("frame {}: {e}", i + 1));
                break;
            }
        };
        if i < init_index {
            run.boxes.push(None);
            run.outputs.push(None);
            on_frame(i, None);
            continue;
        }
        let frame = match Frame::packed(
            img.as_raw(),
            img.width() as usize,
            img.height() as usize,
            PixelFormat::Rgb8,
        ) {
            Ok(f) => f,
            Err(e) => {
                run.error = Some(format!("frame {}: {e}", i + 1));
                break;
            }
        };
        let t0 = Instant::now();
        if i == init_index {
            let r = tracker.init(&frame, init);
            run.track_seconds += t0.elapsed().as_secs_f64();
            if let Err(e) = r {
                run.error = Some(format!("init on frame {}: {e}", i + 1));
                run.init_failed = true;
                break;
            }
            run.frames_tracked += 1;
            run.boxes.push(Some(init));
            run.outputs.push(None);
            on_frame(i, None);
            continue;
        }
        let r = tracker.update(&frame);
        run.track_seconds += t0.elapsed().as_secs_f64();
        match r {
            Ok(out) => {
                run.frames_tracked += 1;
                if out.learned {
                    run.learned += 1;
                } else {
                    run.skipped += 1;
                }
                run.boxes.push(Some(out.bbox));
                run.outputs.push(Some(out));
                on_frame(i, Some(&out));
            }
            Err(e) => {
                run.error = Some(format!("frame {}: {e}", i + 1));
                break;
            }
        }
    }
    if !run.init_failed {
        run.verifier_passes = tracker.verifier_passes();
    }
    run
}

/// A sequence's evaluation: its ground truth and the tracking run.
#[derive(Debug, Clone)]
pub struct SequenceRun {
    /// Sequence name.
    pub name: String,
    /// Ground truth (empty when the annotation could not be read).
    pub truth: Vec<Option<BBox>>,
    /// The run (with `error` set when loading failed).
    pub run: TrackRun,
}

/// One-pass evaluation of a dataset sequence: init on the first annotated frame, no
/// re-initialisation.
pub fn run_sequence(
    entry: &SequenceEntry,
    tracker: &mut dyn Tracker,
    on_frame: impl FnMut(usize, Option<&TrackOutput>),
) -> SequenceRun {
    run_loaded(&entry.name, entry.load(), tracker, on_frame)
}

/// [`run_sequence`] on a sequence already loaded with [`SequenceEntry::load`] (`name` is the
/// entry's name, kept when loading failed): lets the caller size a progress bar from
/// `Sequence::frames` first.
pub fn run_loaded(
    name: &str,
    loaded: Result<Sequence, DatasetError>,
    tracker: &mut dyn Tracker,
    on_frame: impl FnMut(usize, Option<&TrackOutput>),
) -> SequenceRun {
    run_perturbed(name, loaded, None, Decode::Ahead, tracker, on_frame)
}

/// A sequence under `--perturb`: the moved truth and the transformed frames.
struct Perturbed<I> {
    truth: Vec<Option<BBox>>,
    frames: I,
}

/// Every frame `i` of `seq` and its truth through `sp` (`bevt eval --perturb`): the truth
/// is moved with the frame, sized from the first frame's header; each decoded frame must
/// have that size.
fn perturb_sequence(
    seq: Sequence,
    sp: SequencePerturbation,
    decode: Decode,
) -> Result<Perturbed<Frames>, String> {
    let first = seq
        .frames
        .first()
        .ok_or_else(|| "no frames to perturb".to_string())?;
    let (w, h) = image::image_dimensions(first)
        .map(|(w, h)| (w as usize, h as usize))
        .map_err(|e| format!("{}: {e}", first.display()))?;
    let truth = seq
        .truth
        .iter()
        .enumerate()
        .map(|(t, b)| match b {
            Some(b) => sp.apply_box(t, w, h, *b),
            None => Ok(None),
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| format!("--perturb: {e}"))?;
    // The look-alike: the first annotated frame's target, pasted beside the target.
    let boxes = truth.clone();
    let template = std::sync::Mutex::new(None);
    let frames = decode_frames(seq.frames, decode, move |t, img| {
        let (iw, ih) = (img.width() as usize, img.height() as usize);
        if (iw, ih) != (w, h) {
            return Err(format!("frame is {iw}x{ih}, the sequence's first {w}x{h}"));
        }
        let (mut rgb, ow, oh) = sp
            .apply_frame(t, img.into_raw(), w, h)
            .map_err(|e| format!("--perturb: {e}"))?;
        if let (true, Some(Some(b))) = (sp.has_lookalike(), boxes.get(t)) {
            let mut template = template
                .lock()
                .map_err(|_| "--perturb: look-alike state poisoned".to_string())?;
            if template.is_none() {
                *template = sp.cut_patch(&rgb, ow, oh, *b);
            }
            if let Some(patch) = template.as_ref() {
                sp.paste_lookalike(&mut rgb, ow, oh, *b, patch);
            }
        }
        RgbFrame::from_raw(ow as u32, oh as u32, rgb)
            .ok_or_else(|| "--perturb: perturbed frame has the wrong size".to_string())
    });
    Ok(Perturbed { truth, frames })
}

/// [`run_loaded`] with every frame and its ground truth transformed by `perturb` (the
/// returned truth is the transformed one, so scores compare like with like), the frames
/// decoded as `decode` says.
pub fn run_perturbed(
    name: &str,
    loaded: Result<Sequence, DatasetError>,
    perturb: Option<&Perturbation>,
    decode: Decode,
    tracker: &mut dyn Tracker,
    on_frame: impl FnMut(usize, Option<&TrackOutput>),
) -> SequenceRun {
    let failed = |name: String, truth: Vec<Option<BBox>>, e: String| SequenceRun {
        name,
        truth,
        run: TrackRun {
            error: Some(e),
            ..TrackRun::default()
        },
    };
    let seq: Sequence = match loaded {
        Ok(s) => s,
        Err(e) => {
            return SequenceRun {
                name: name.to_string(),
                truth: Vec::new(),
                run: TrackRun {
                    error: Some(e.to_string()),
                    ..TrackRun::default()
                },
            }
        }
    };
    let Some((init_index, init)) = seq
        .truth
        .iter()
        .enumerate()
        .find_map(|(i, b)| b.map(|b| (i, b)))
    else {
        return SequenceRun {
            name: seq.name,
            truth: seq.truth,
            run: TrackRun {
                error: Some("no annotated frame to initialise on".into()),
                ..TrackRun::default()
            },
        };
    };
    let Some(p) = perturb else {
        let run = track_feed(
            tracker,
            decode_frames(seq.frames, decode, |_, img| Ok(img)),
            init_index,
            init,
            on_frame,
        );
        return SequenceRun {
            name: seq.name,
            truth: seq.truth,
            run,
        };
    };
    let name = seq.name.clone();
    let original = seq.truth.clone();
    let sp = p.for_sequence(&name);
    let Perturbed { truth, frames } = match perturb_sequence(seq, sp, decode) {
        Ok(x) => x,
        Err(e) => return failed(name, original, e),
    };
    // The first annotated frame is unchanged by the time-varying terms, but `tiny` rescales
    // its box: initialise on the transformed one.
    let Some(init) = truth.get(init_index).copied().flatten() else {
        return failed(
            name,
            truth,
            "--perturb moved the initial box off the frame".into(),
        );
    };
    let run = track_feed(tracker, frames, init_index, init, on_frame);
    SequenceRun { name, truth, run }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three 4×2 PNG frames in a fresh folder, the third not an image.
    fn frames(tag: &str) -> Vec<PathBuf> {
        let dir = std::env::temp_dir().join(format!("bevt_runner_{tag}_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        (0..3)
            .map(|i| {
                let p = dir.join(format!("{i}.png"));
                if i == 2 {
                    std::fs::write(&p, b"not a png").unwrap();
                } else {
                    RgbFrame::from_pixel(4, 2, image::Rgb([i as u8 * 50, 7, 9]))
                        .save(&p)
                        .unwrap();
                }
                p
            })
            .collect()
    }

    /// `Inline` decodes on the thread that takes the frames, `Ahead` on another; both give
    /// the same frames, in order, through `map`, and the same error for the bad one.
    #[test]
    fn inline_decodes_on_the_callers_thread_and_ahead_beside_it() {
        let me = std::thread::current().id();
        let paths = frames("decode");
        let mut got = Vec::new();
        for decode in [Decode::Ahead, Decode::Inline] {
            let seen = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
            let s = seen.clone();
            let items: Vec<_> = decode_frames(paths.clone(), decode, move |i, img| {
                s.lock().unwrap().push((i, std::thread::current().id()));
                Ok(img)
            })
            .map(|r| r.map(|f| f.get_pixel(0, 0).0))
            .collect();
            let seen = seen.lock().unwrap().clone();
            assert_eq!(seen.iter().map(|s| s.0).collect::<Vec<_>>(), [0, 1]);
            assert_eq!(
                seen.iter().all(|s| s.1 == me),
                decode == Decode::Inline,
                "{decode:?}"
            );
            assert_eq!(items.len(), 3);
            assert!(
                items[2].as_ref().is_err_and(|e| e.contains("2.png")),
                "{items:?}"
            );
            got.push(items);
        }
        assert_eq!(got[0], got[1]);
        assert_eq!(got[1][1], Ok([50, 7, 9]));
    }

    #[test]
    fn decode_names_round_trip_and_others_are_refused() {
        for d in [Decode::Ahead, Decode::Inline] {
            assert_eq!(d.name().parse::<Decode>(), Ok(d));
        }
        assert!("prefetch"
            .parse::<Decode>()
            .is_err_and(|e| e.contains("'inline'")));
        assert_eq!(Decode::default(), Decode::Ahead);
    }
}
