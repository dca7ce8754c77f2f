//! Issue 6 §2, §3 and §5 over real DDS (RustDDS on loopback, the node in-process on its
//! own domain): image bombs and truncated frames are refused without resetting the track
//! or keeping memory; a burst of re-initialisation requests is answered in full while the
//! camera keeps being tracked; big-endian CDR images are read.

use bevt_core::eval::synth::SynthParams;
use bevt_core::{BBox, TrackerConfig};
use bevt_msgs::bevt::TrackStatus;
use bevt_msgs::builtin_interfaces::Time;
use bevt_msgs::sensor_msgs::{CompressedImage, Image};
use bevt_msgs::std_msgs::Header;
use bevt_msgs::RosType;
use bevt_node::convert::reinit_request;
use bevt_node::node::app::{NodeCore, NodeSettings};
use bevt_node::node::ros::{camera_qos, context, ros_name, run, ImageTransport, RosSettings};
use bevt_node::node::sim::{spawn_camera, wall_stamp, GroundStation, RawPeer};
use bevt_tests::{synth_image as image, wait_status};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The node in a thread; stopped and joined when dropped.
struct Node {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Node {
    fn start(settings: &RosSettings, node: NodeSettings) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let core = NodeCore::new(TrackerConfig::default().validate().unwrap(), node);
        let (s2, st2) = (settings.clone(), stop.clone());
        let thread = std::thread::Builder::new()
            .name("bevt-node-under-test".into())
            .spawn(move || run(core, &s2, st2, |_| {}).unwrap())
            .unwrap();
        Self {
            stop,
            thread: Some(thread),
        }
    }
}

impl Drop for Node {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn settings() -> RosSettings {
    RosSettings {
        domain_id: bevt_tests::dds_domain(),
        // The bomb set has raw and compressed images.
        image_transport: ImageTransport::Both,
        ..RosSettings::default()
    }
}

/// Publishes `send()` again until the node reports a status with its stamp.
fn send_until_reported(gs: &GroundStation, stamp: Time, send: impl Fn()) -> TrackStatus {
    let end = Instant::now() + Duration::from_secs(40);
    loop {
        send();
        if let Some(s) = wait_status(gs, Duration::from_millis(300), |s| s.header.stamp == stamp) {
            return s;
        }
        assert!(Instant::now() < end, "the node never reported {stamp:?}");
    }
}

/// This process's resident memory, KiB.
fn rss_kib() -> u64 {
    let s = std::fs::read_to_string("/proc/self/status").unwrap();
    s.lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap()
}

fn encode(img: &image::DynamicImage, fmt: image::ImageFormat) -> Vec<u8> {
    let mut out = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut out), fmt)
        .unwrap();
    out
}

/// CRC-32 (IEEE) of PNG chunks.
fn crc32(bytes: &[u8]) -> u32 {
    let mut c = 0xFFFF_FFFFu32;
    for &b in bytes {
        c ^= b as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// The bomb set: (name, format, bytes, what the reason must say). Headers declaring
/// 16000×16000 (a 333-byte-class JPEG, a tiny grey PNG), a JPEG of a real frame cut in
/// half, and a PNG cut short.
fn bombs(frame: &Image) -> Vec<(&'static str, &'static str, Vec<u8>, &'static str)> {
    // Grey, as the red team's: 16000² × 1 byte passed the old 256 MiB decode limit, and
    // the grey-to-RGB conversion then tripled it.
    let mut jpg = encode(
        &image::DynamicImage::ImageLuma8(image::GrayImage::new(16, 16)),
        image::ImageFormat::Jpeg,
    );
    let sof = jpg.windows(2).position(|p| p == [0xFF, 0xC0]).unwrap();
    jpg[sof + 5..sof + 9].copy_from_slice(&[0x3E, 0x80, 0x3E, 0x80]);
    let mut png = encode(
        &image::DynamicImage::ImageLuma8(image::GrayImage::new(8, 8)),
        image::ImageFormat::Png,
    );
    png[16..24].copy_from_slice(&[0, 0, 0x3E, 0x80, 0, 0, 0x3E, 0x80]);
    let crc = crc32(&png[12..29]);
    png[29..33].copy_from_slice(&crc.to_be_bytes());
    let real = image::DynamicImage::ImageRgb8(
        image::RgbImage::from_raw(frame.width, frame.height, frame.data.clone()).unwrap(),
    );
    let real_jpg = encode(&real, image::ImageFormat::Jpeg);
    let real_png = encode(&real, image::ImageFormat::Png);
    vec![
        ("jpeg declaring 16000x16000", "jpeg", jpg, "max_image_width"),
        ("png declaring 16000x16000", "png", png, "max_image_width"),
        (
            "jpeg cut in half",
            "jpeg",
            real_jpg[..real_jpg.len() / 2].to_vec(),
            "truncated",
        ),
        (
            "png cut short",
            "png",
            real_png[..real_png.len() * 3 / 4].to_vec(),
            "png",
        ),
    ]
}

/// Memory above twice the steady state that the in-process tests once asserted; now only
/// named, as their VmRSS is shared with the other tests (see the separate-process test).
const RSS_MARGIN_KIB: u64 = 256 * 1024;
/// Times the bomb set is sent (the red-team check sent fifteen bombs).
const BOMB_ROUNDS: usize = 4;

#[test]
fn image_bombs_and_truncated_frames_are_refused_without_memory_or_track_loss() {
    let s = settings();
    let _node = Node::start(&s, NodeSettings::default());
    let peer = RawPeer::new(&s).unwrap();
    let gs = GroundStation::new(&s).unwrap();
    let seq = SynthParams::default();
    let (m0, t0) = image(&seq, 0);
    send_until_reported(&gs, m0.header.stamp, || peer.image(m0.clone()));
    let resp = gs
        .reinit(
            &reinit_request(t0, m0.header.stamp, ""),
            Duration::from_secs(10),
        )
        .expect("reinit answered");
    assert!(resp.success, "{}", resp.message);
    let mut t = 1;
    let good_frame = |t: &mut usize| {
        let (m, truth) = image(&seq, *t);
        *t += 1;
        let st = send_until_reported(&gs, m.header.stamp, || peer.image(m.clone()));
        (st, truth)
    };
    // Steady state: tracking.
    let mut track_id = 0;
    for _ in 0..5 {
        let (st, truth) = good_frame(&mut t);
        assert_eq!(st.state, TrackStatus::STATE_TRACKING, "{}", st.reason);
        assert!(
            BBox::new(st.x, st.y, st.width, st.height)
                .center()
                .distance(&truth.center())
                < 5.0
        );
        track_id = st.track_id;
    }
    let steady = rss_kib();
    for round in 0..BOMB_ROUNDS {
        let (frame, _) = image(&seq, t);
        for (name, format, data, why) in bombs(&frame) {
            let msg = CompressedImage {
                header: Header {
                    stamp: wall_stamp(),
                    frame_id: "cam".into(),
                },
                format: format.into(),
                data,
            };
            let st = send_until_reported(&gs, msg.header.stamp, || peer.compressed(msg.clone()));
            assert_eq!(st.state, TrackStatus::STATE_ERROR, "{name}: {}", st.reason);
            assert!(
                st.reason.to_lowercase().contains(why),
                "{name}: {}",
                st.reason
            );
            // The track survives the bad frame: the next good one is tracked, same track.
            let (st, truth) = good_frame(&mut t);
            assert_eq!(
                st.state,
                TrackStatus::STATE_TRACKING,
                "round {round}, after {name}: {}",
                st.reason
            );
            assert_eq!(st.track_id, track_id, "{name} reset the track");
            let b = BBox::new(st.x, st.y, st.width, st.height);
            assert!(
                b.center().distance(&truth.center()) < 5.0,
                "after {name}: {b:?} vs {truth:?}"
            );
        }
    }
    let after = rss_kib();
    println!(
        "VmRSS steady {} MiB, after {} bomb sets {} MiB",
        steady / 1024,
        BOMB_ROUNDS,
        after / 1024
    );
    // Memory is printed, not asserted: the other tests share this process (the CNN tests
    // load ONNX Runtime); the bound is asserted on a node process of its own below.
    let _ = RSS_MARGIN_KIB;
}

/// Requests in the burst (the red-team check sent 30, then 1000).
const BURST: usize = 200;
/// The burst is sent in this many waves...
const BURST_WAVES: usize = 4;
/// ...this far apart (2 s in all, 40 camera frames at 20 Hz).
const BURST_WAVE_GAP: Duration = Duration::from_millis(500);
/// Frames that must be processed while the burst lasts (a quarter of those sent).
const MIN_FRAMES_DURING_BURST: u32 = 10;

#[test]
fn a_reinit_burst_is_answered_in_full_while_the_camera_keeps_being_tracked() {
    let s = settings();
    let node_settings = NodeSettings::default();
    let (rate, burst) = (node_settings.reinit_rate_hz, node_settings.reinit_burst);
    let _node = Node::start(&s, node_settings);
    let stop = Arc::new(AtomicBool::new(false));
    let seq = SynthParams {
        frames: 400,
        ..SynthParams::default()
    };
    let (camera, truth) = spawn_camera(&s, seq, 20.0, stop.clone()).unwrap();
    let gs = GroundStation::new(&s).unwrap();
    // Initialise once on a frame the node has (the newest: zero stamp).
    let first = gs
        .start_track_on_newest(&truth, Duration::from_secs(30))
        .expect("the node never answered");
    assert!(first.success, "{}", first.message);
    println!("initialised: {}", first.message);
    // Let the bucket refill, then the burst: requests on frames of every age in the buffer.
    std::thread::sleep(Duration::from_secs_f64(f64::from(burst) / rate + 0.5));
    let _ = gs.take_status();
    let stamps: Vec<(i64, BBox)> = truth
        .lock()
        .unwrap()
        .iter()
        .rev()
        .take(25)
        .map(|(k, v)| (*k, *v))
        .collect();
    let started = Instant::now();
    let mut replies = Vec::new();
    let mut statuses = Vec::new();
    // The burst in BURST_WAVES waves BURST_WAVE_GAP apart, so it spans many camera frames.
    for (i, (stamp, b)) in stamps.iter().cycle().take(BURST).enumerate() {
        assert!(gs.send_reinit(&reinit_request(*b, Time::from_nanos(*stamp), "")));
        if (i + 1) % (BURST / BURST_WAVES) == 0 {
            std::thread::sleep(BURST_WAVE_GAP);
            replies.extend(gs.take_reinit_replies());
            statuses.extend(gs.take_status());
        }
    }
    let end = Instant::now() + Duration::from_secs(60);
    while replies.len() < BURST && Instant::now() < end {
        replies.extend(gs.take_reinit_replies());
        statuses.extend(gs.take_status());
        std::thread::sleep(Duration::from_millis(5));
    }
    let elapsed = started.elapsed().as_secs_f64();
    statuses.extend(gs.take_status());
    stop.store(true, Ordering::Relaxed);
    let _ = camera.join();
    let accepted = replies.iter().filter(|r| r.success).count();
    let refused: Vec<_> = replies.iter().filter(|r| !r.success).collect();
    println!(
        "{} of {BURST} requests answered in {elapsed:.1} s: {accepted} accepted, {} refused; {} statuses meanwhile",
        replies.len(),
        refused.len(),
        statuses.len()
    );
    assert_eq!(replies.len(), BURST, "every request is answered");
    assert!(accepted >= 1, "the burst admits some requests");
    // A bounded share: no more than the bucket plus its refill while the burst lasted.
    assert!(
        accepted as f64 <= f64::from(burst) + rate * elapsed + 1.0,
        "{accepted} accepted in {elapsed:.1} s"
    );
    for r in &refused {
        assert!(
            r.message.contains("rate limit") || r.message.contains("no buffered frame"),
            "{}",
            r.message
        );
    }
    // The camera was never starved: frames were processed all through the burst, and
    // every status after the first reply still reports a tracked frame.
    let processed: Vec<u32> = statuses.iter().map(|s| s.frames_processed).collect();
    let (lo, hi) = (
        processed.iter().min().copied().unwrap_or(0),
        processed.iter().max().copied().unwrap_or(0),
    );
    // The camera runs at 20 Hz: about 40 frames arrive while the waves are sent.
    assert!(
        hi >= lo + MIN_FRAMES_DURING_BURST,
        "frames processed during the burst: {lo}..{hi}"
    );
    let last = statuses.last().expect("statuses during the burst");
    assert!(
        matches!(
            last.state,
            TrackStatus::STATE_TRACKING | TrackStatus::STATE_LOW_CONSENSUS
        ),
        "{}",
        last.reason
    );
}

#[test]
fn big_endian_cdr_images_are_accepted() {
    use bevt_node::node::ros::names;
    use ros2_client::dds::rustdds;
    let s = settings();
    let _node = Node::start(&s, NodeSettings::default());
    let gs = GroundStation::new(&s).unwrap();
    // A plain DDS writer with the CDR_BE encapsulation (ros2-client always writes LE).
    let ctx = context(&s).unwrap();
    let dp = ctx.domain_participant();
    let qos: rustdds::QosPolicies = (&camera_qos()).into();
    let name = ros_name(&s, names::IMAGE).unwrap();
    let node_name = ros2_client::NodeName::new("/", "be_camera").unwrap();
    let topic = dp
        .create_topic(
            name.to_dds_name("rt", &node_name, ""),
            ros2_client::MessageTypeName::new(Image::PACKAGE, Image::NAME).dds_msg_type(),
            &qos,
            rustdds::TopicKind::NoKey,
        )
        .unwrap();
    let publisher = dp.create_publisher(&qos).unwrap();
    let writer = publisher
        .create_datawriter_no_key::<Image, rustdds::serialization::CDRSerializerAdapter<
            Image,
            byteorder::BigEndian,
        >>(&topic, None)
        .unwrap();
    let seq = SynthParams::default();
    for t in 0..2 {
        let (m, _) = image(&seq, t);
        let st = send_until_reported(&gs, m.header.stamp, || {
            let _ = writer.write(m.clone(), None);
        });
        assert_eq!(st.state, TrackStatus::STATE_IDLE, "{}", st.reason);
        assert_eq!(st.frames_processed as usize, t + 1);
    }
}

#[test]
fn hand_built_big_endian_cdr_decodes_as_the_node_reads_it() {
    use byteorder::{BigEndian, WriteBytesExt};
    use ros2_client::dds::rustdds;
    // sensor_msgs/Image, XCDR1 big-endian, built field by field (not by a serializer).
    fn string(b: &mut Vec<u8>, s: &str) {
        while !b.len().is_multiple_of(4) {
            b.push(0);
        }
        b.write_u32::<BigEndian>(s.len() as u32 + 1).unwrap();
        b.extend_from_slice(s.as_bytes());
        b.push(0);
    }
    let mut b = Vec::new();
    b.write_i32::<BigEndian>(1_700_000_000).unwrap();
    b.write_u32::<BigEndian>(123).unwrap();
    string(&mut b, "camera");
    while !b.len().is_multiple_of(4) {
        b.push(0);
    }
    b.write_u32::<BigEndian>(1).unwrap(); // height
    b.write_u32::<BigEndian>(2).unwrap(); // width
    string(&mut b, "rgb8");
    b.push(0); // is_bigendian
    while !b.len().is_multiple_of(4) {
        b.push(0);
    }
    b.write_u32::<BigEndian>(6).unwrap(); // step
    b.write_u32::<BigEndian>(6).unwrap(); // data length
    b.extend_from_slice(&[1, 2, 3, 4, 5, 6]);
    // The same message from an independent serializer: Python rosbags,
    // `serialize_cdr(msg, "sensor_msgs/msg/Image", little_endian=False)`, with its
    // encapsulation header 00 00 (CDR_BE) 00 00.
    let rosbags = "000000006553f1000000007b0000000763616d657261000000000001000000020000000572676238000000000000000600000006010203040506";
    let golden: Vec<u8> = (0..rosbags.len() / 2)
        .map(|i| u8::from_str_radix(&rosbags[2 * i..2 * i + 2], 16).unwrap())
        .collect();
    assert_eq!(&golden[4..], &b[..]);
    let rep = rustdds::RepresentationIdentifier::from_bytes(&golden[..2]).unwrap();
    assert_eq!(rep, rustdds::RepresentationIdentifier::CDR_BE);
    let (m, _) =
        rustdds::serialization::deserialize_from_cdr_with_rep_id::<Image>(&golden[4..], rep)
            .unwrap();
    assert_eq!(
        (m.header.frame_id.as_str(), m.width, m.height, m.step),
        ("camera", 2, 1, 6)
    );
    assert_eq!(m.header.stamp.sec, 1_700_000_000);
    assert_eq!(m.data, vec![1, 2, 3, 4, 5, 6]);
}

/// Rounds of the bomb set sent by the independent peer.
const PEER_ROUNDS: usize = 3;

#[test]
fn an_independent_cyclone_peer_sends_the_bomb_set_and_the_track_survives() {
    use std::process::{Command, Stdio};
    use std::sync::Mutex;
    let py = match crate::interop::python() {
        Ok(p) => p,
        Err(e) => {
            bevt_tests::skip(
                "an_independent_cyclone_peer_sends_the_bomb_set_and_the_track_survives",
                format!("no Python environment ({e})"),
            );
            return;
        }
    };
    let dir = bevt_tests::temp_dir("bomb_peer");
    let seq = SynthParams::default();
    // The plan: each bomb followed by the next good frame.
    let mut messages = Vec::new();
    let mut expect: Vec<(String, Option<&'static str>, usize)> = Vec::new();
    let (warm, t0) = image(&seq, 0);
    std::fs::write(dir.join("frame_00000.rgb"), &warm.data).unwrap();
    let mut k = 1;
    for round in 0..PEER_ROUNDS {
        for (i, (_, format, data, why)) in bombs(&warm).into_iter().enumerate() {
            let file = format!("bomb_{round}_{i}.bin");
            std::fs::write(dir.join(&file), &data).unwrap();
            let id = format!("bomb-{round}-{i}");
            messages.push(
                serde_json::json!({"id": id, "kind": "compressed", "file": file, "format": format}),
            );
            expect.push((id, Some(why), 0));
            let (m, _) = image(&seq, k);
            let file = format!("frame_{k:05}.rgb");
            std::fs::write(dir.join(&file), &m.data).unwrap();
            let id = format!("good-{k}");
            messages.push(serde_json::json!({"id": id, "kind": "raw", "file": file}));
            expect.push((id, None, k));
            k += 1;
        }
    }
    let plan = serde_json::json!({
        "width": seq.width, "height": seq.height, "warmup": "frame_00000.rgb", "messages": messages
    });
    std::fs::write(dir.join("plan.json"), plan.to_string()).unwrap();
    // The node, recording every status it publishes.
    let s = settings();
    let seen: Arc<Mutex<Vec<TrackStatus>>> = Arc::default();
    let stop = Arc::new(AtomicBool::new(false));
    let core = NodeCore::new(
        TrackerConfig::default().validate().unwrap(),
        NodeSettings::default(),
    );
    let (s2, st2, seen2) = (s.clone(), stop.clone(), seen.clone());
    let node = std::thread::spawn(move || {
        run(core, &s2, st2, |o| {
            if let Ok(mut v) = seen2.lock() {
                v.push(o.status.clone());
            }
        })
        .unwrap()
    });
    let gs = GroundStation::new(&s).unwrap();
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("interop/bomb_peer.py");
    let mut peer = Command::new(&py)
        .arg(&script)
        .arg(s.domain_id.to_string())
        .arg(&dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Initialise on the warm-up frame once the node has it (zero stamp = newest).
    let end = Instant::now() + Duration::from_secs(30);
    let resp = loop {
        assert!(
            Instant::now() < end,
            "the peer's warm-up frames never arrived"
        );
        if seen
            .lock()
            .unwrap()
            .iter()
            .any(|st| st.header.frame_id == "warmup")
        {
            if let Some(r) = gs.reinit(
                &reinit_request(t0, Time::default(), "warmup"),
                Duration::from_secs(5),
            ) {
                break r;
            }
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    assert!(resp.success, "{}", resp.message);
    std::thread::sleep(Duration::from_millis(500));
    let steady = rss_kib();
    std::fs::write(dir.join("go"), b"").unwrap();
    let end = Instant::now() + Duration::from_secs(120);
    let status = loop {
        if let Some(st) = peer.try_wait().unwrap() {
            break st;
        }
        if Instant::now() > end {
            let _ = peer.kill();
            panic!("the peer did not finish");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    std::thread::sleep(Duration::from_millis(500));
    let after = rss_kib();
    stop.store(true, Ordering::Relaxed);
    let _ = node.join();
    let out = peer.wait_with_output().unwrap();
    assert!(
        status.success(),
        "peer failed ({status}): {}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let seen = seen.lock().unwrap().clone();
    let track_id = resp_track_id(&seen);
    let (mut bombs_seen, mut good_seen, mut last_good) = (0, 0, None);
    for (id, why, frame) in &expect {
        for st in seen.iter().filter(|st| &st.header.frame_id == id) {
            match why {
                Some(why) => {
                    bombs_seen += 1;
                    assert_eq!(st.state, TrackStatus::STATE_ERROR, "{id}: {}", st.reason);
                    assert!(
                        st.reason.to_lowercase().contains(why),
                        "{id}: {}",
                        st.reason
                    );
                }
                None => {
                    good_seen += 1;
                    assert_eq!(st.state, TrackStatus::STATE_TRACKING, "{id}: {}", st.reason);
                    assert_eq!(st.track_id, track_id, "{id}: the track was reset");
                    let b = BBox::new(st.x, st.y, st.width, st.height);
                    let truth = seq.truth(*frame);
                    assert!(
                        b.center().distance(&truth.center()) < 5.0,
                        "{id}: {b:?} vs {truth:?}"
                    );
                    last_good = Some(*frame);
                }
            }
        }
    }
    println!(
        "bomb peer: {bombs_seen} bomb and {good_seen} good statuses of {} messages; VmRSS {} -> {} MiB",
        expect.len(),
        steady / 1024,
        after / 1024
    );
    // Best effort on loopback: nearly everything arrives; most of it must have.
    assert!(
        bombs_seen * 2 >= expect.len() / 2,
        "{bombs_seen} bomb statuses"
    );
    assert!(
        good_seen * 2 >= expect.len() / 2,
        "{good_seen} good statuses"
    );
    assert!(
        last_good.is_some_and(|f| f + 2 >= k),
        "tracking at the end: {last_good:?}"
    );
    // Memory is printed, not asserted: the other tests share this process (the CNN tests
    // load ONNX Runtime); the bound is asserted on a node process of its own below.
    let _ = RSS_MARGIN_KIB;
    let _ = std::fs::remove_dir_all(&dir);
}

/// The track id of the first tracked status.
fn resp_track_id(seen: &[TrackStatus]) -> u32 {
    seen.iter()
        .find(|s| s.state == TrackStatus::STATE_TRACKING)
        .map_or(0, |s| s.track_id)
}

/// Margin over twice the steady memory of a node process that only this test drives
/// (DDS may queue a few repeated frames when the machine is loaded).
const PROCESS_RSS_MARGIN_KIB: u64 = 128 * 1024;

/// `VmRSS` and `VmHWM` (peak) of process `pid`, KiB.
fn process_memory(pid: u32) -> (u64, u64) {
    let s = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let field = |name: &str| -> u64 {
        s.lines()
            .find_map(|l| l.strip_prefix(name))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
            .unwrap()
    };
    (field("VmRSS:"), field("VmHWM:"))
}

#[test]
fn a_separate_node_process_stays_within_twice_its_steady_memory_under_the_bomb_set() {
    use std::process::{Command, Stdio};
    let s = settings();
    // The node as its own process (stops when its stdin closes).
    let mut child = Command::new(env!("CARGO_BIN_EXE_bevt_node_under_test"))
        .args([
            "--ros-args",
            "-p",
            &format!("domain_id:={}", s.domain_id),
            "-p",
            "image_transport:=both",
        ])
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let pid = child.id();
    let peer = RawPeer::new(&s).unwrap();
    let gs = GroundStation::new(&s).unwrap();
    let seq = SynthParams::default();
    let (m0, t0) = image(&seq, 0);
    send_until_reported(&gs, m0.header.stamp, || peer.image(m0.clone()));
    let resp = gs
        .reinit(
            &reinit_request(t0, m0.header.stamp, ""),
            Duration::from_secs(10),
        )
        .expect("reinit answered");
    assert!(resp.success, "{}", resp.message);
    let mut k = 1;
    let good = |k: &mut usize| {
        let (m, truth) = image(&seq, *k);
        *k += 1;
        let st = send_until_reported(&gs, m.header.stamp, || peer.image(m.clone()));
        assert_eq!(st.state, TrackStatus::STATE_TRACKING, "{}", st.reason);
        let b = BBox::new(st.x, st.y, st.width, st.height);
        assert!(
            b.center().distance(&truth.center()) < 5.0,
            "{b:?} vs {truth:?}"
        );
    };
    // Steady state: the ring buffer full (30 frames), the tracker warm.
    for _ in 0..35 {
        good(&mut k);
    }
    let (steady, _) = process_memory(pid);
    for _ in 0..BOMB_ROUNDS {
        let (frame, _) = image(&seq, k);
        for (name, format, data, why) in bombs(&frame) {
            let msg = CompressedImage {
                header: Header {
                    stamp: wall_stamp(),
                    frame_id: "cam".into(),
                },
                format: format.into(),
                data,
            };
            let st = send_until_reported(&gs, msg.header.stamp, || peer.compressed(msg.clone()));
            assert_eq!(st.state, TrackStatus::STATE_ERROR, "{name}: {}", st.reason);
            assert!(
                st.reason.to_lowercase().contains(why),
                "{name}: {}",
                st.reason
            );
            good(&mut k);
        }
    }
    let (after, peak) = process_memory(pid);
    drop(child.stdin.take());
    let _ = child.wait();
    println!(
        "node process VmRSS: steady {} MiB, after {BOMB_ROUNDS} bomb sets {} MiB, peak {} MiB",
        steady / 1024,
        after / 1024,
        peak / 1024
    );
    let bound = 2 * steady + PROCESS_RSS_MARGIN_KIB;
    assert!(after <= bound, "VmRSS {steady} -> {after} KiB");
    assert!(peak <= bound, "VmHWM {peak} KiB (steady {steady} KiB)");
}
