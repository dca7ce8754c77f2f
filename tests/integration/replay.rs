//! `bevt replay` on bags written by an independent implementation (Python `rosbags`,
//! `scripts/make_test_bags.py`, both storage plugins) from synthetic frames with exact
//! truth; the output MCAP read back by independent readers (Python `mcap` +
//! `mcap-ros2-support`, `tests/replay/read_mcap.py`); bad input of every kind; and a real
//! dev sequence replayed against `bevt eval`'s own path. Skipped with a printed reason
//! when the Python environment cannot be made.

use crate::interop::python;
use bevt_core::eval::synth::SynthParams;
use bevt_core::{BBox, BevtTracker, TrackerConfig};
use bevt_node::node::app::NodeSettings;
use bevt_node::tool::replay::{
    replay, InitAt, ReinitEntry, ReplayError, ReplayOptions, ReplaySummary,
};
use bevt_tests::{dev_dataset, temp_dir};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// Frames of the synthetic bags (short: the tests stay quick).
const FRAMES: usize = 30;
/// Frames of the per-encoding and bad-input topics.
const ENC_FRAMES: usize = 8;
/// Stamp of the first frame, ns.
const STAMP0: i64 = 1_700_000_000_000_000_000;
/// Frame period, ns (10 Hz).
const PERIOD: i64 = 100_000_000;

struct Bags {
    dir: PathBuf,
    truth: Vec<BBox>,
    py: PathBuf,
}

/// The synthetic bags, made once per test run (None: no Python, reason printed).
fn bags() -> Option<&'static Bags> {
    static BAGS: OnceLock<Option<Bags>> = OnceLock::new();
    BAGS.get_or_init(|| {
        let py = match python() {
            Ok(p) => p,
            Err(e) => {
                bevt_tests::skip("replay tests", format!("no Python environment ({e})"));
                return None;
            }
        };
        let dir = temp_dir("replay_bags");
        let frames = dir.join("frames");
        std::fs::create_dir_all(&frames).unwrap();
        let s = SynthParams {
            frames: FRAMES,
            ..SynthParams::default()
        };
        let mut truth = Vec::new();
        for i in 0..FRAMES {
            let f = s.frame(i);
            std::fs::write(frames.join(format!("frame_{i:05}.rgb")), &f.rgb).unwrap();
            let img =
                image::RgbImage::from_raw(s.width as u32, s.height as u32, f.rgb.clone()).unwrap();
            img.save(frames.join(format!("frame_{i:05}.jpg"))).unwrap();
            truth.push(f.truth);
        }
        let meta = serde_json::json!({"width": s.width, "height": s.height, "count": FRAMES,
            "stamp0_ns": STAMP0, "period_ns": PERIOD, "enc_frames": ENC_FRAMES, "raw": true});
        std::fs::write(frames.join("meta.json"), meta.to_string()).unwrap();
        make_bags(&py, &frames, &dir);
        Some(Bags { dir, truth, py })
    })
    .as_ref()
}

fn make_bags(py: &Path, frames: &Path, out: &Path) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/make_test_bags.py");
    let r = Command::new(py)
        .arg(&script)
        .arg(frames)
        .arg(out)
        .output()
        .unwrap();
    assert!(
        r.status.success(),
        "make_test_bags.py failed: {}",
        String::from_utf8_lossy(&r.stderr)
    );
}

fn options(bag: &Path, topic: &str, out: &Path, init: BBox) -> ReplayOptions {
    ReplayOptions {
        bag: bag.to_path_buf(),
        topic: topic.into(),
        init,
        init_at: InitAt::Frame(0),
        tracker: TrackerConfig::default().validate().unwrap(),
        node: NodeSettings::default(),
        out: out.join("out.mcap"),
        csv: Some(out.join("out.csv")),
        reinit: Vec::new(),
        copy_images: false,
        stop: None,
    }
}

/// CSV rows: (stamp text, box if any, state).
fn csv_rows(path: &Path) -> Vec<(String, Option<BBox>, String)> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("stamp,x,y,w,h,score,state"));
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), 7, "{l}");
            let b = (!f[1].is_empty()).then(|| {
                let v: Vec<f32> = f[1..5].iter().map(|s| s.parse().unwrap()).collect();
                BBox::new(v[0], v[1], v[2], v[3])
            });
            (f[0].to_string(), b, f[6].to_string())
        })
        .collect()
}

fn center_error(a: &BBox, b: &BBox) -> f32 {
    a.center().distance(&b.center())
}

/// Frames whose box centre is within `px` of the truth.
fn within(rows: &[(String, Option<BBox>, String)], truth: &[BBox], px: f32) -> usize {
    rows.iter()
        .zip(truth)
        .filter(|((_, b, _), t)| b.is_some_and(|b| center_error(&b, t) <= px))
        .count()
}

fn mcap_file(dir: &Path) -> PathBuf {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "mcap"))
        .unwrap()
}

fn db3_file(dir: &Path) -> PathBuf {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "db3"))
        .unwrap()
}

#[test]
fn replay_follows_the_target_from_both_storages_both_transports_and_a_bare_mcap() {
    let Some(b) = bags() else { return };
    let cases = [
        (b.dir.join("mcap_bag"), "/camera/image_raw"),
        (b.dir.join("mcap_bag"), "/camera/image_raw/compressed"),
        (b.dir.join("db3_bag"), "/camera/image_raw"),
        (b.dir.join("db3_bag"), "/camera/image_raw/compressed"),
        (mcap_file(&b.dir.join("mcap_bag")), "/camera/image_raw"),
        (
            db3_file(&b.dir.join("db3_bag")),
            "/camera/image_raw/compressed",
        ),
    ];
    for (i, (bag, topic)) in cases.iter().enumerate() {
        let out = temp_dir(&format!("replay_follow_{i}"));
        let s = replay(&options(bag, topic, &out, b.truth[0]), false)
            .unwrap_or_else(|e| panic!("{} {topic}: {e}", bag.display()));
        assert_eq!(s.frames, FRAMES as u64, "{} {topic}: {s:?}", bag.display());
        assert!(s.skipped.is_empty(), "{s:?}");
        let rows = csv_rows(&out.join("out.csv"));
        assert_eq!(rows.len(), FRAMES);
        // The CSV stamps are the images' own.
        let t = STAMP0 + 5 * PERIOD;
        assert_eq!(
            rows[5].0,
            format!("{}.{:09}", t / 1_000_000_000, t % 1_000_000_000)
        );
        let good = within(&rows, &b.truth, 4.0);
        println!("{} {topic}: {good}/{FRAMES} within 4 px", bag.display());
        assert!(
            good >= FRAMES - 1,
            "{} {topic}: {good}/{FRAMES}",
            bag.display()
        );
    }
}

#[test]
fn every_raw_encoding_replays_through_the_node_conversions() {
    let Some(b) = bags() else { return };
    for enc in ["bgr8", "mono8", "rgba8", "bgra8", "yuv422", "yuv422_yuy2"] {
        let out = temp_dir(&format!("replay_enc_{enc}"));
        let topic = format!("/camera/{enc}");
        let s = replay(
            &options(&b.dir.join("mcap_bag"), &topic, &out, b.truth[0]),
            false,
        )
        .unwrap_or_else(|e| panic!("{enc}: {e}"));
        assert_eq!(s.frames, ENC_FRAMES as u64, "{enc}: {s:?}");
        assert!(!s.states.contains_key("error"), "{enc}: {s:?}");
        let rows = csv_rows(&out.join("out.csv"));
        let good = within(&rows, &b.truth, 5.0);
        assert!(good >= ENC_FRAMES - 1, "{enc}: {good}/{ENC_FRAMES}");
    }
}

#[test]
fn the_output_mcap_reads_back_with_independent_readers() {
    let Some(b) = bags() else { return };
    let out = temp_dir("replay_readback");
    let mut o = options(
        &b.dir.join("db3_bag"),
        "/camera/image_raw",
        &out,
        b.truth[0],
    );
    o.copy_images = true;
    replay(&o, false).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("replay/read_mcap.py");
    let r = Command::new(&b.py)
        .arg(&script)
        .arg(&o.out)
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let v: serde_json::Value = serde_json::from_slice(&r.stdout).unwrap();
    assert_eq!(v["profile"], "ros2");
    let topics = &v["topics"];
    for (topic, schema) in [
        ("/detections", "vision_msgs/msg/Detection2DArray"),
        ("/track_status", "bevt_msgs/msg/TrackStatus"),
        ("/track_annotations", "foxglove_msgs/msg/ImageAnnotations"),
        ("/camera/image_raw", "sensor_msgs/msg/Image"),
    ] {
        let t = &topics[topic];
        assert_eq!(t["schema"], schema, "{topic}: {t}");
        assert_eq!(t["schema_encoding"], "ros2msg");
        assert_eq!(t["message_encoding"], "cdr");
        assert_eq!(t["count"], FRAMES as u64, "{topic}");
    }
    let rows = csv_rows(&out.join("out.csv"));
    let dets = v["detections"].as_array().unwrap();
    for (i, (d, (_, b, state))) in dets.iter().zip(&rows).enumerate() {
        // Header copied from the image; log time = the recording's.
        let stamp = STAMP0 + i as i64 * PERIOD;
        assert_eq!(d["stamp"], stamp);
        assert_eq!(d["frame_id"], "camera");
        assert_eq!(d["log_time"], stamp);
        let b = b.unwrap();
        let det = &d["dets"][0];
        assert_eq!(det["id"], "1", "track id");
        assert_eq!(det["stamp"], stamp);
        let c = b.center();
        assert!((det["cx"].as_f64().unwrap() - c.x as f64).abs() < 2e-3);
        assert!((det["w"].as_f64().unwrap() - b.w as f64).abs() < 2e-3);
        let score = det["score"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&score));
        let st = &v["status"][i];
        assert_eq!(st["track_id"], 1);
        assert!((st["confidence"].as_f64().unwrap() - score).abs() < 1e-6);
        assert!(["tracking", "low_consensus", "uncertain"].contains(&state.as_str()));
        // The overlay is the box itself.
        let ann = &v["annotations"][i];
        let p = &ann["points"][0];
        assert_eq!(p.as_array().unwrap().len(), 4);
        assert!((p[0][0].as_f64().unwrap() - b.x as f64).abs() < 2e-3);
        assert!((p[2][1].as_f64().unwrap() - (b.y + b.h) as f64).abs() < 2e-3);
        assert!(ann["texts"][0].as_str().unwrap().starts_with("track 1"));
    }
    assert_eq!(dets.len(), FRAMES);
}

#[test]
fn reinit_requests_follow_the_node_stamp_semantics() {
    let Some(b) = bags() else { return };
    let out = temp_dir("replay_reinit");
    // A wrong initial box on the background: the track is off the target until the
    // ground station's box, drawn on frame 10 and arriving with frame 13, fixes it.
    let mut o = options(
        &b.dir.join("mcap_bag"),
        "/camera/image_raw",
        &out,
        BBox::new(250.0, 180.0, 40.0, 32.0),
    );
    let stamp = |i: i64| STAMP0 + i * PERIOD;
    o.reinit = vec![
        ReinitEntry {
            stamp: stamp(10),
            at: stamp(13) + 1,
            bbox: b.truth[10],
        },
        // Drawn on a frame the node never saw: refused, track kept.
        ReinitEntry {
            stamp: stamp(20) + 7,
            at: stamp(21),
            bbox: BBox::new(1.0, 1.0, 20.0, 20.0),
        },
    ];
    let s = replay(&o, false).unwrap();
    assert_eq!(s.reinit_applied, 2, "{s:?}");
    assert_eq!(s.reinit_refused.len(), 1, "{s:?}");
    assert!(s.reinit_refused[0].contains("no buffered frame"), "{s:?}");
    let rows = csv_rows(&out.join("out.csv"));
    let before = within(&rows[1..13], &b.truth[1..13], 4.0);
    let after = within(&rows[13..], &b.truth[13..], 4.0);
    println!("reinit: before {before}/12, after {after}/{}", FRAMES - 13);
    assert!(before <= 2, "the wrong box was not wrong: {before}");
    assert!(
        after >= FRAMES - 14,
        "after the reinit: {after}/{}",
        FRAMES - 13
    );
    // The output of frame 13 is the fast-forwarded track of the new id.
    let v = std::fs::read_to_string(out.join("out.csv")).unwrap();
    assert!(v.lines().count() == FRAMES + 1);
}

fn replay_err(bag: &Path, topic: &str, name: &str) -> (ReplayError, PathBuf) {
    let out = temp_dir(name);
    let b = BBox::new(140.0, 104.0, 40.0, 32.0);
    let e = replay(&options(bag, topic, &out, b), false).unwrap_err();
    println!("{name}: {e}");
    (e, out)
}

fn replay_ok(bag: &Path, topic: &str, name: &str) -> ReplaySummary {
    let out = temp_dir(name);
    let b = bags().unwrap();
    let s = replay(&options(bag, topic, &out, b.truth[0]), false).unwrap();
    println!("{name}: {s:?}");
    s
}

#[test]
fn bad_input_is_a_clear_error_or_a_counted_skip_and_results_are_kept_apart() {
    let Some(b) = bags() else { return };
    let mb = b.dir.join("mcap_bag");
    // Missing topic: the topics that exist are listed.
    let (e, _) = replay_err(&mb, "/camera/nope", "replay_missing");
    assert!(
        e.reason.contains("\"/camera/nope\" is not in the bag"),
        "{e}"
    );
    assert!(
        e.reason
            .contains("/camera/image_raw (sensor_msgs/msg/Image)"),
        "{e}"
    );
    let (e, _) = replay_err(&mcap_file(&mb), "/camera/nope", "replay_missing_bare");
    assert!(e.reason.contains("/chatter (std_msgs/msg/String)"), "{e}");
    let (e, _) = replay_err(&b.dir.join("no_topics"), "/camera/image_raw", "replay_none");
    assert!(e.reason.contains("its topics: none"), "{e}");
    // Not an image topic; an empty topic.
    let (e, _) = replay_err(&mb, "/chatter", "replay_chatter");
    assert!(e.reason.contains("std_msgs/msg/String"), "{e}");
    let (e, _) = replay_err(&b.dir.join("db3_bag"), "/empty", "replay_empty");
    assert!(e.reason.contains("has no messages"), "{e}");
    // Unsupported encoding, step/size mismatch: every frame unusable, the reason named.
    let (e, _) = replay_err(&mb, "/bad/encoding", "replay_encoding");
    assert!(
        e.reason
            .contains("unsupported image encoding \"bayer_rggb8\""),
        "{e}"
    );
    assert_eq!(e.summary.states.get("error"), Some(&3));
    let (e, _) = replay_err(&mb, "/bad/step", "replay_step");
    assert!(e.reason.contains("malformed image"), "{e}");
    // Out-of-order stamps: the late frame is skipped and counted.
    let s = replay_ok(&mb, "/bad/order", "replay_order");
    assert_eq!(s.frames, ENC_FRAMES as u64 - 1);
    assert_eq!(s.skipped.values().sum::<u64>(), 1, "{s:?}");
    assert!(s.skipped.keys().next().unwrap().contains("out of order"));
    // A size change mid-stream resets the track (the node's rule), counted.
    let s = replay_ok(&mb, "/bad/size_change", "replay_size");
    assert_eq!(s.frames, 2 * ENC_FRAMES as u64);
    assert_eq!(
        s.skipped.get("image size or format changed: track reset"),
        Some(&1),
        "{s:?}"
    );
    assert!(s.states.get("lost").is_some_and(|&n| n >= 1), "{s:?}");

    // A truncated MCAP: an error naming the file, the frames before the cut are written
    // and the output is a valid MCAP.
    let cut = temp_dir("replay_cut_in");
    let src = std::fs::read(mcap_file(&mb)).unwrap();
    let truncated = cut.join("cut.mcap");
    std::fs::write(&truncated, &src[..src.len() * 6 / 10]).unwrap();
    let (e, out) = replay_err(&truncated, "/camera/image_raw", "replay_cut");
    assert!(e.reason.contains("cut.mcap"), "{e}");
    let n = e.summary.frames as usize;
    assert!(n > 3 && n < FRAMES, "{n} frames before the cut");
    // A failed run replaces no output: the frames before the cut are kept in its partial
    // files, which are finished and readable.
    assert!(!out.join("out.csv").exists() && !out.join("out.mcap").exists());
    let partial = |ext: &str| {
        e.partial
            .iter()
            .find(|p| p.extension().is_some_and(|x| x == ext))
            .unwrap_or_else(|| panic!("no partial .{ext}: {:?}", e.partial))
            .clone()
    };
    assert_eq!(csv_rows(&partial("csv")).len(), n);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("replay/read_mcap.py");
    let r = Command::new(&b.py)
        .arg(&script)
        .arg(partial("mcap"))
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let v: serde_json::Value = serde_json::from_slice(&r.stdout).unwrap();
    assert_eq!(v["topics"]["/detections"]["count"], n as u64);

    // Corrupt files: a .db3 with garbage over its pages, an .mcap that is not one.
    let mut db = std::fs::read(db3_file(&b.dir.join("db3_bag"))).unwrap();
    let len = db.len();
    for x in &mut db[len / 4..len * 3 / 4] {
        *x = 0xA5;
    }
    let bad_db = cut.join("bad.db3");
    std::fs::write(&bad_db, &db).unwrap();
    let (e, _) = replay_err(&bad_db, "/camera/image_raw", "replay_bad_db3");
    assert!(e.reason.contains("bad.db3"), "{e}");
    let garbage = cut.join("garbage.mcap");
    std::fs::write(&garbage, b"this is not an mcap file at all").unwrap();
    let (e, _) = replay_err(&garbage, "/camera/image_raw", "replay_garbage");
    assert!(e.reason.contains("garbage.mcap"), "{e}");
    let (e, _) = replay_err(&cut.join("absent"), "/camera/image_raw", "replay_absent");
    assert!(e.reason.contains("no such file"), "{e}");
}

#[test]
fn a_replayed_dev_sequence_gives_the_boxes_of_bevt_eval() {
    const N: usize = 40;
    let Some(root) = dev_dataset() else {
        bevt_tests::skip(
            "a_replayed_dev_sequence_gives_the_boxes_of_bevt_eval",
            "../shared absent",
        );
        return;
    };
    let Some(b) = bags() else { return };
    let ds = bevt_node::tool::dataset::open_dataset(&root).unwrap();
    let seq = ds
        .sequences
        .iter()
        .map(|e| e.load().unwrap())
        .find(|s| s.frames.len() >= N && s.truth[0].is_some())
        .unwrap();
    let init = seq.truth[0].unwrap();
    // eval's path: the same decoder thread and feed over the first N frames.
    let spec = TrackerConfig::default().validate().unwrap();
    let mut tracker = BevtTracker::new(spec.clone());
    let frames: Vec<PathBuf> = seq.frames[..N].to_vec();
    let run = bevt_node::tool::runner::track_feed(
        &mut tracker,
        bevt_node::tool::runner::decode_ahead(frames.clone()),
        0,
        init,
        |_, _| {},
    );
    assert!(run.error.is_none(), "{:?}", run.error);
    // The same JPEG files as a CompressedImage bag.
    let dir = temp_dir("replay_dev");
    let fdir = dir.join("frames");
    std::fs::create_dir_all(&fdir).unwrap();
    for (i, f) in frames.iter().enumerate() {
        std::fs::copy(f, fdir.join(format!("frame_{i:05}.jpg"))).unwrap();
    }
    let meta = serde_json::json!({"width": 0, "height": 0, "count": N, "stamp0_ns": STAMP0,
        "period_ns": PERIOD, "raw": false});
    std::fs::write(fdir.join("meta.json"), meta.to_string()).unwrap();
    make_bags(&b.py, &fdir, &dir);
    let mut o = options(
        &dir.join("seq_bag"),
        "/camera/image_raw/compressed",
        &dir,
        init,
    );
    o.tracker = spec;
    let s = replay(&o, false).unwrap();
    assert_eq!(s.frames, N as u64);
    let rows = csv_rows(&dir.join("out.csv"));
    let mut worst = 0.0f32;
    for (i, ((_, r, _), e)) in rows.iter().zip(&run.boxes).enumerate() {
        let (r, e) = (r.unwrap(), e.unwrap());
        let d = [r.x - e.x, r.y - e.y, r.w - e.w, r.h - e.h]
            .iter()
            .fold(0.0f32, |m, v| m.max(v.abs()));
        worst = worst.max(d);
        // The CSV keeps 3 decimals.
        assert!(
            d < 1e-3,
            "{}: frame {i}: replay {r:?} vs eval {e:?}",
            seq.name
        );
    }
    println!(
        "{}: {N} frames, replay = eval (largest difference {worst:.4} px)",
        seq.name
    );
}
