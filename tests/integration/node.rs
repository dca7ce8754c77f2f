//! The ROS 2 node over real DDS (RustDDS on loopback), in-process: a synthetic camera
//! publishes frames, a ground station calls `reinit` and reads `detections`. Each test uses
//! its own DDS domain; every wait has a timeout.

use bevt_core::eval::synth::SynthParams;
use bevt_core::{BBox, TrackerConfig};
use bevt_msgs::bevt::ReinitRequest;
use bevt_msgs::builtin_interfaces::Time;
use bevt_node::convert::bbox_from_detection;
use bevt_node::node::app::{NodeCore, NodeSettings};
use bevt_node::node::ros::{run, RosSettings};
use bevt_node::node::sim::{spawn_camera, GroundStation, TruthLog};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// These tests send several requests back to back (and the ground station retries), so
/// the bucket is deeper than the default; the rate limit itself is tested in
/// node_limits.rs.
fn node_settings() -> NodeSettings {
    NodeSettings {
        reinit_burst: 10,
        ..NodeSettings::default()
    }
}

struct Running {
    stop: Arc<AtomicBool>,
    node: Option<std::thread::JoinHandle<()>>,
    camera: Option<std::thread::JoinHandle<()>>,
    truth: TruthLog,
    gs: GroundStation,
}

impl Drop for Running {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.camera.take() {
            let _ = h.join();
        }
        if let Some(h) = self.node.take() {
            let _ = h.join();
        }
    }
}

fn start() -> Running {
    start_with(SynthParams {
        frames: 200,
        ..SynthParams::default()
    })
}

fn start_with(seq: SynthParams) -> Running {
    let settings = RosSettings {
        domain_id: bevt_tests::dds_domain(),
        ..RosSettings::default()
    };
    let stop = Arc::new(AtomicBool::new(false));
    let core = NodeCore::new(
        TrackerConfig::default().validate().unwrap(),
        node_settings(),
    );
    let (s2, st2) = (settings.clone(), stop.clone());
    let node = std::thread::Builder::new()
        .name("bevt-node-under-test".into())
        .spawn(move || run(core, &s2, st2, |_| {}).unwrap())
        .unwrap();
    let (camera, truth) = spawn_camera(&settings, seq, 20.0, stop.clone()).unwrap();
    let gs = GroundStation::new(&settings).unwrap();
    Running {
        stop,
        node: Some(node),
        camera: Some(camera),
        truth,
        gs,
    }
}

/// Time for DDS discovery to match the node's subscription with the camera: frames
/// before that are lost (first-sample loss), so an operator's stamp must be newer.
const DISCOVERY: Duration = Duration::from_millis(1500);

/// The truth of a frame about `age` old, once the camera has run for `age + DISCOVERY`.
fn delayed_truth(r: &Running, age: Duration) -> (i64, BBox) {
    let end = Instant::now() + Duration::from_secs(10);
    loop {
        {
            let log = r.truth.lock().unwrap();
            if let Some(&newest) = log.keys().next_back() {
                let oldest = *log.keys().next().unwrap();
                if newest - oldest > (age + DISCOVERY).as_nanos() as i64 {
                    let (k, v) = log.range(newest - age.as_nanos() as i64..).next().unwrap();
                    return (*k, *v);
                }
            }
        }
        assert!(Instant::now() < end, "the camera published nothing");
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn request(b: BBox, stamp: i64) -> ReinitRequest {
    bevt_node::convert::reinit_request(b, Time::from_nanos(stamp), "")
}

/// Collects detections for `dur`; returns (count, count within `tol` px of the truth).
fn collect(r: &Running, dur: Duration, tol: f32) -> (usize, usize) {
    let end = Instant::now() + dur;
    let (mut n, mut good) = (0, 0);
    while Instant::now() < end {
        for d in r.gs.take_detections() {
            let Some(det) = d.detections.first() else {
                continue;
            };
            n += 1;
            let truth = r
                .truth
                .lock()
                .unwrap()
                .get(&d.header.stamp.as_nanos())
                .copied();
            if let Some(t) = truth {
                if bbox_from_detection(det).center().distance(&t.center()) < tol {
                    good += 1;
                }
            }
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    (n, good)
}

#[test]
fn node_tracks_after_a_delayed_reinit_over_dds() {
    let r = start();
    let (stamp, b) = delayed_truth(&r, Duration::from_millis(300));
    let resp =
        r.gs.reinit(&request(b, stamp), Duration::from_secs(10))
            .expect("reinit answered");
    assert!(resp.success, "{}", resp.message);
    assert!(resp.message.contains("fast-forwarded"), "{}", resp.message);
    let (n, good) = collect(&r, Duration::from_secs(3), 5.0);
    println!("{n} detections, {good} within 5 px of the truth");
    assert!(n >= 20, "only {n} detections in 3 s at 20 Hz");
    assert!(good * 10 >= n * 9, "{good}/{n} within 5 px");
}

#[test]
fn bad_reinit_requests_are_refused_and_the_node_keeps_running() {
    let r = start();
    let (stamp, b) = delayed_truth(&r, Duration::from_millis(100));
    for bad in [
        request(BBox::new(f32::NAN, 1.0, 10.0, 10.0), 0),
        request(BBox::new(10.0, 10.0, -5.0, 10.0), 0),
        request(BBox::new(-900.0, -900.0, 20.0, 20.0), 0),
        request(b, 12_345),
    ] {
        let resp =
            r.gs.reinit(&bad, Duration::from_secs(10))
                .expect("answered");
        assert!(!resp.success, "{bad:?} accepted: {}", resp.message);
        assert!(
            resp.message.contains("current track kept"),
            "{}",
            resp.message
        );
    }
    // Still alive and able to track.
    let resp =
        r.gs.reinit(&request(b, stamp), Duration::from_secs(10))
            .expect("answered");
    assert!(resp.success, "{}", resp.message);
    let (n, good) = collect(&r, Duration::from_secs(2), 5.0);
    assert!(n >= 10 && good * 10 >= n * 9, "{good}/{n}");
}

#[test]
fn lost_target_is_published_with_empty_detections_and_reinit_clears_it_over_dds() {
    use bevt_msgs::bevt::TrackStatus;
    // The target disappears 3 s into the sequence (20 Hz) and does not come back.
    let r = start_with(SynthParams {
        frames: 600,
        hidden: Some((60, 600)),
        ..SynthParams::default()
    });
    let (stamp, b) = delayed_truth(&r, Duration::from_millis(100));
    let resp =
        r.gs.reinit(&request(b, stamp), Duration::from_secs(10))
            .expect("reinit answered");
    assert!(resp.success, "{}", resp.message);
    let end = Instant::now() + Duration::from_secs(15);
    let mut lost = None;
    let mut detections = Vec::new();
    while lost.is_none() && Instant::now() < end {
        lost =
            r.gs.take_status()
                .into_iter()
                .find(|s| s.state == TrackStatus::STATE_LOST);
        detections.extend(r.gs.take_detections());
        std::thread::sleep(Duration::from_millis(10));
    }
    let lost = lost.expect("no lost state published");
    assert!(
        lost.reason.starts_with("target lost: confidence"),
        "{}",
        lost.reason
    );
    assert!(lost.confidence < 0.5, "{}", lost.confidence);
    // The detections of that frame: an empty array with the image's header.
    let end = Instant::now() + Duration::from_secs(5);
    let frame = loop {
        if let Some(d) = detections
            .iter()
            .find(|d| d.header.stamp == lost.header.stamp)
        {
            break d.clone();
        }
        assert!(Instant::now() < end, "no detections for the lost frame");
        detections.extend(r.gs.take_detections());
        std::thread::sleep(Duration::from_millis(10));
    };
    assert!(frame.detections.is_empty(), "{frame:?}");
    // A reinit (on the newest frame) clears it: tracking again, with a detection.
    let resp =
        r.gs.reinit(&request(b, 0), Duration::from_secs(10))
            .expect("reinit answered");
    assert!(resp.success, "{}", resp.message);
    let end = Instant::now() + Duration::from_secs(10);
    let after = loop {
        if let Some(s) =
            r.gs.take_status()
                .into_iter()
                .find(|s| s.track_id > lost.track_id)
        {
            break s;
        }
        assert!(Instant::now() < end, "no status after the reinit");
        std::thread::sleep(Duration::from_millis(10));
    };
    assert_ne!(after.state, TrackStatus::STATE_LOST, "{}", after.reason);
    let end = Instant::now() + Duration::from_secs(10);
    loop {
        let found = r.gs.take_detections().into_iter().any(|d| {
            d.detections
                .first()
                .is_some_and(|d| d.id == after.track_id.to_string())
        });
        if found {
            break;
        }
        assert!(Instant::now() < end, "no detection after the reinit");
        std::thread::sleep(Duration::from_millis(10));
    }
}

mod topics_and_bad_input {
    use super::*;
    use bevt_msgs::bevt::TrackStatus;
    use bevt_msgs::vision_msgs::Detection2D;
    use bevt_node::convert::bbox_2d;
    use bevt_node::node::sim::{wall_stamp, RawPeer};
    use bevt_tests::{synth_image as image, wait_status};

    /// The node with `settings` in a thread; set the flag to stop it, then join.
    fn node_thread(settings: &RosSettings) -> (Arc<AtomicBool>, std::thread::JoinHandle<()>) {
        let stop = Arc::new(AtomicBool::new(false));
        let core = NodeCore::new(
            TrackerConfig::default().validate().unwrap(),
            node_settings(),
        );
        let (s2, st2) = (settings.clone(), stop.clone());
        let node = std::thread::spawn(move || run(core, &s2, st2, |_| {}).unwrap());
        (stop, node)
    }

    /// `image_transport` subscribes exactly the configured input: with `raw` (the
    /// default) a compressed frame gets no status while a raw one does; with `compressed`
    /// the other way round.
    #[test]
    fn image_transport_subscribes_only_the_configured_input() {
        use bevt_node::node::ros::ImageTransport;
        let seq = SynthParams::default();
        for (transport, raw_taken) in [
            (ImageTransport::Raw, true),
            (ImageTransport::Compressed, false),
        ] {
            let settings = RosSettings {
                domain_id: bevt_tests::dds_domain(),
                image_transport: transport,
                ..RosSettings::default()
            };
            let (stop, node) = node_thread(&settings);
            let peer = RawPeer::new(&settings).unwrap();
            let gs = GroundStation::new(&settings).unwrap();
            let png = |t: usize| bevt_tests::png_image(&image(&seq, t).0);
            // The configured input: sent until reported (discovery, first samples).
            let end = Instant::now() + Duration::from_secs(15);
            loop {
                let stamp = if raw_taken {
                    let (m, _) = image(&seq, 0);
                    peer.image(m.clone());
                    m.header.stamp
                } else {
                    let c = png(0);
                    peer.compressed(c.clone());
                    c.header.stamp
                };
                if wait_status(&gs, Duration::from_millis(200), |s| s.header.stamp == stamp)
                    .is_some()
                {
                    break;
                }
                assert!(
                    Instant::now() < end,
                    "{transport:?}: the configured input was never reported"
                );
            }
            // Discovery is done: the other input is not read.
            let mut stamps = Vec::new();
            for t in 1..8 {
                if raw_taken {
                    let c = png(t);
                    stamps.push(c.header.stamp);
                    peer.compressed(c);
                } else {
                    let (m, _) = image(&seq, t);
                    stamps.push(m.header.stamp);
                    peer.image(m);
                }
                std::thread::sleep(Duration::from_millis(100));
            }
            assert!(
                wait_status(&gs, Duration::from_secs(1), |s| stamps
                    .contains(&s.header.stamp))
                .is_none(),
                "{transport:?}: the other input was read"
            );
            stop.store(true, Ordering::Relaxed);
            node.join().unwrap();
        }
    }

    #[test]
    fn init_topic_compressed_input_and_bad_images_over_dds() {
        let settings = RosSettings {
            domain_id: bevt_tests::dds_domain(),
            image_transport: bevt_node::node::ros::ImageTransport::Both,
            ..RosSettings::default()
        };
        let (stop, node) = node_thread(&settings);
        let peer = RawPeer::new(&settings).unwrap();
        let gs = GroundStation::new(&settings).unwrap();
        let seq = SynthParams::default();
        // Keep sending frame 0 until the node reports it (first samples may be lost).
        let (m0, t0) = image(&seq, 0);
        let end = Instant::now() + Duration::from_secs(15);
        loop {
            peer.image(m0.clone());
            if wait_status(&gs, Duration::from_millis(200), |s| {
                s.header.stamp == m0.header.stamp
            })
            .is_some()
            {
                break;
            }
            assert!(Instant::now() < end, "the node never reported frame 0");
        }
        // Initialise through the init topic, on frame 0's stamp.
        let det = Detection2D {
            header: m0.header.clone(),
            bbox: bbox_2d(t0),
            ..Detection2D::default()
        };
        let end = Instant::now() + Duration::from_secs(10);
        while gs.take_detections().iter().all(|d| d.detections.is_empty()) {
            peer.init(det.clone());
            std::thread::sleep(Duration::from_millis(200));
            assert!(
                Instant::now() < end,
                "the init topic did not start tracking"
            );
        }
        // Compressed frames are tracked too.
        let (m1, t1) = image(&seq, 1);
        let cm = bevt_tests::png_image(&m1);
        peer.compressed(cm.clone());
        let s = wait_status(&gs, Duration::from_secs(5), |s| {
            s.header.stamp == m1.header.stamp
        })
        .expect("status for the png frame");
        assert_eq!(s.state, TrackStatus::STATE_TRACKING, "{}", s.reason);
        let b = BBox::new(s.x, s.y, s.width, s.height);
        assert!(b.center().distance(&t1.center()) < 5.0, "{b:?} vs {t1:?}");
        // Bad inputs: each is reported with its reason; the node keeps running.
        let mut short = image(&seq, 2).0;
        short.data.truncate(100);
        let mut odd = image(&seq, 2).0;
        odd.encoding = "32FC1".into();
        for (bad, why) in [(short, "data has 100 bytes"), (odd, "32FC1")] {
            let stamp = bad.header.stamp;
            peer.image(bad);
            let s = wait_status(&gs, Duration::from_secs(5), |s| s.header.stamp == stamp)
                .expect("status for a bad image");
            assert_eq!(s.state, TrackStatus::STATE_ERROR);
            assert!(s.reason.contains(why), "{}", s.reason);
        }
        let mut corrupt = cm;
        corrupt.header.stamp = wall_stamp();
        corrupt.data.truncate(40);
        let stamp = corrupt.header.stamp;
        peer.compressed(corrupt);
        let s = wait_status(&gs, Duration::from_secs(5), |s| s.header.stamp == stamp)
            .expect("status for a corrupt png");
        assert_eq!(s.state, TrackStatus::STATE_ERROR);
        // Still tracking on the next good frame; then a resolution change resets it.
        let (m3, _) = image(&seq, 3);
        peer.image(m3.clone());
        let s = wait_status(&gs, Duration::from_secs(5), |s| {
            s.header.stamp == m3.header.stamp
        })
        .expect("status");
        assert_eq!(s.state, TrackStatus::STATE_TRACKING, "{}", s.reason);
        let small = SynthParams {
            width: 160,
            height: 120,
            ..SynthParams::default()
        };
        let (m4, _) = image(&small, 4);
        peer.image(m4.clone());
        let s = wait_status(&gs, Duration::from_secs(5), |s| {
            s.header.stamp == m4.header.stamp
        })
        .expect("status");
        assert_eq!(s.state, TrackStatus::STATE_LOST);
        assert!(s.reason.contains("re-initialise"), "{}", s.reason);
        stop.store(true, Ordering::Relaxed);
        let _ = node.join();
    }
}
