//! `bevt replay` as a user runs it, on a recording it must never destroy: outputs that name
//! an input (or each other) are refused before anything is written, a failed rerun leaves
//! the earlier outputs untouched, and SIGINT / SIGTERM finish valid outputs of what was
//! processed.

use crate::common;
use bevt_core::eval::synth::SynthParams;
use bevt_msgs::builtin_interfaces::Time;
use bevt_msgs::sensor_msgs::Image;
use bevt_msgs::std_msgs::Header;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

const TOPIC: &str = "/camera/image_raw";
const BEVT: &str = env!("CARGO_BIN_EXE_bevt");

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("bevt_replay_safety_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A bare MCAP recording of `frames` rgb8 frames of the synthetic sequence on [`TOPIC`]
/// (ros2 profile, CDR, 10 Hz); returns the initial box.
fn write_bag(path: &Path, frames: usize) -> String {
    let seq = SynthParams {
        width: 320,
        height: 240,
        frames,
        target: (40.0, 32.0),
        ..SynthParams::default()
    };
    let mut rec = common::Recording::create(path, TOPIC, "sensor_msgs/msg/Image");
    for i in 0..frames {
        let f = seq.frame(i);
        let t = 1_700_000_000_000_000_000i64 + i as i64 * 100_000_000;
        let msg = Image {
            header: Header {
                stamp: Time::from_nanos(t),
                frame_id: "cam".into(),
            },
            height: seq.height as u32,
            width: seq.width as u32,
            encoding: "rgb8".into(),
            is_bigendian: 0,
            step: (seq.width * 3) as u32,
            data: f.rgb,
        };
        rec.write(t, &msg);
    }
    rec.finish();
    let b = seq.frame(0).truth;
    format!("{},{},{},{}", b.x, b.y, b.w, b.h)
}

fn bevt(args: &[&str]) -> Output {
    Command::new(BEVT).args(args).output().unwrap()
}

fn replay_args<'a>(bag: &'a str, init: &'a str, out: &'a str, csv: &'a str) -> Vec<&'a str> {
    vec![
        "replay", "--bag", bag, "--topic", TOPIC, "--init", init, "--out", out, "--csv", csv,
    ]
}

fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// Messages on `/detections` of a finished MCAP file, read through its summary section
/// (a file without a valid footer and summary has none).
fn detections_in(path: &Path) -> u64 {
    let bytes = std::fs::read(path).unwrap();
    let summary = mcap::Summary::read(&bytes)
        .unwrap()
        .expect("a finished MCAP has a summary");
    let stats = summary.stats.expect("statistics");
    let id = summary
        .channels
        .values()
        .find(|c| c.topic == "/detections")
        .expect("the /detections channel")
        .id;
    stats.channel_message_counts[&id]
}

#[test]
fn outputs_naming_an_input_or_each_other_are_refused_and_nothing_is_touched() {
    let d = temp_dir("identity");
    let bag = d.join("flight.mcap");
    let init = write_bag(&bag, 6);
    let recording = std::fs::read(&bag).unwrap();
    let reinit = d.join("reinit.txt");
    std::fs::write(&reinit, "").unwrap();
    let (b, o, c, r) = (
        bag.to_str().unwrap(),
        d.join("out.mcap"),
        d.join("out.csv"),
        reinit.to_str().unwrap(),
    );
    let other_spelling = d.join(".").join("flight.mcap");
    let link = d.join("hard_link.mcap");
    std::fs::hard_link(&bag, &link).unwrap();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (replay_args(b, &init, b, c.to_str().unwrap()), "--out"),
        (
            replay_args(
                b,
                &init,
                o.to_str().unwrap(),
                other_spelling.to_str().unwrap(),
            ),
            "--csv",
        ),
        (
            replay_args(b, &init, link.to_str().unwrap(), c.to_str().unwrap()),
            "--out",
        ),
        (
            replay_args(b, &init, o.to_str().unwrap(), o.to_str().unwrap()),
            "same file as --out",
        ),
        (
            [
                replay_args(b, &init, o.to_str().unwrap(), r),
                vec!["--reinit-file", r],
            ]
            .concat(),
            "--csv",
        ),
    ];
    for (args, what) in cases {
        let out = bevt(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert!(err.contains(what), "{args:?}: {err}");
        assert_eq!(std::fs::read(&bag).unwrap(), recording, "{args:?}");
        assert_eq!(
            files_in(&d),
            ["flight.mcap", "hard_link.mcap", "reinit.txt"],
            "{args:?} wrote a file"
        );
    }
    // A bag that is not there leaves nothing behind either.
    let out = bevt(&replay_args(
        d.join("absent.mcap").to_str().unwrap(),
        &init,
        o.to_str().unwrap(),
        c.to_str().unwrap(),
    ));
    assert!(!out.status.success());
    assert_eq!(
        files_in(&d),
        ["flight.mcap", "hard_link.mcap", "reinit.txt"]
    );
}

#[test]
fn a_failed_rerun_leaves_the_earlier_outputs_untouched() {
    let d = temp_dir("rerun");
    let bag = d.join("flight.mcap");
    let init = write_bag(&bag, 8);
    let (b, o, c) = (
        bag.to_str().unwrap().to_string(),
        d.join("out.mcap"),
        d.join("out.csv"),
    );
    let (os, cs) = (o.to_str().unwrap(), c.to_str().unwrap());
    let good = bevt(&replay_args(&b, &init, os, cs));
    assert!(
        good.status.success(),
        "{}",
        String::from_utf8_lossy(&good.stderr)
    );
    assert_eq!(detections_in(&o), 8);
    let (mcap_before, csv_before) = (std::fs::read(&o).unwrap(), std::fs::read(&c).unwrap());
    // The initial box lies outside the frame: refused, the run fails.
    let bad = bevt(&replay_args(&b, "5000,5000,10,10", os, cs));
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("untouched"), "{err}");
    assert_eq!(std::fs::read(&o).unwrap(), mcap_before);
    assert_eq!(std::fs::read(&c).unwrap(), csv_before);
    // Nothing was tracked, so no partial file is kept.
    assert_eq!(files_in(&d), ["flight.mcap", "out.csv", "out.mcap"]);
}

/// Sends `signal` once the replay has written `rows` CSV rows, then checks that both outputs
/// are finished files holding exactly the frames processed.
fn interrupted_replay_finishes_its_outputs(signal: &str, name: &str) {
    const FRAMES: usize = 600;
    let d = temp_dir(name);
    let bag = d.join("flight.mcap");
    let init = write_bag(&bag, FRAMES);
    let (o, c) = (d.join("out.mcap"), d.join("out.csv"));
    let child = Command::new(BEVT)
        .args(replay_args(
            bag.to_str().unwrap(),
            &init,
            o.to_str().unwrap(),
            c.to_str().unwrap(),
        ))
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until the replay is under way (the partial CSV has rows), then signal it.
    let start = Instant::now();
    loop {
        let rows = std::fs::read_dir(&d)
            .unwrap()
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().ends_with(".csv"))
            .map(|e| {
                std::fs::read_to_string(e.path())
                    .unwrap_or_default()
                    .lines()
                    .count()
            })
            .max()
            .unwrap_or(0);
        if rows > 20 {
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "the replay never got going"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    let killed = Command::new("kill")
        .args([signal, &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "{err}");
    assert!(err.contains("interrupted"), "{err}");
    let rows = std::fs::read_to_string(&c).unwrap().lines().count() - 1;
    assert!(rows > 20 && rows < FRAMES, "{rows} rows");
    assert_eq!(detections_in(&o), rows as u64);
    assert_eq!(files_in(&d), ["flight.mcap", "out.csv", "out.mcap"]);
}

#[test]
fn sigint_finishes_a_valid_mcap_and_csv_of_what_was_processed() {
    interrupted_replay_finishes_its_outputs("-INT", "sigint");
}

#[test]
fn sigterm_finishes_a_valid_mcap_and_csv_of_what_was_processed() {
    interrupted_replay_finishes_its_outputs("-TERM", "sigterm");
}
