//! The node among ROS tools: image_transport's topic naming and (with a peer on an
//! independent DDS implementation) the `rcl_interfaces` parameter services.

use bevt_core::eval::synth::SynthParams;
use bevt_core::TrackerConfig;
use bevt_msgs::sensor_msgs::CompressedImage;
use bevt_node::node::app::{NodeCore, NodeSettings};
use bevt_node::node::ros::{camera_qos, context, run, RosSettings};
use bevt_node::node::sim::GroundStation;
use bevt_tests::{synth_image, wait_status};
use ros2_client::{MessageTypeName, Name, NodeName, NodeOptions};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The node in a thread; stopped and joined when dropped.
struct Node {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Drop for Node {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn start(settings: &RosSettings) -> Node {
    let stop = Arc::new(AtomicBool::new(false));
    let core = NodeCore::new(
        TrackerConfig::default().validate().unwrap(),
        NodeSettings::default(),
    );
    let (s2, st2) = (settings.clone(), stop.clone());
    let thread = std::thread::Builder::new()
        .name("bevt-node-under-test".into())
        .spawn(move || run(core, &s2, st2, |_| {}).unwrap())
        .unwrap();
    Node {
        stop,
        thread: Some(thread),
    }
}

/// A PNG `sensor_msgs/CompressedImage` of synthetic frame `t`, stamped now.
fn png(seq: &SynthParams, t: usize) -> CompressedImage {
    bevt_tests::png_image(&synth_image(seq, t).0)
}

#[test]
fn a_remapped_raw_topic_takes_the_compressed_input_with_it() {
    // `ros2 run bevt_node bevt_node --ros-args -r image_raw:=/camera/image_raw`
    let settings = RosSettings {
        domain_id: bevt_tests::dds_domain(),
        remaps: vec![("image_raw".into(), "/camera/image_raw".into())],
        image_transport: bevt_node::node::ros::ImageTransport::Compressed,
        ..RosSettings::default()
    };
    let _node = start(&settings);
    let gs = GroundStation::new(&settings).unwrap();
    // A camera publishing as image_transport does, the topic named here independently of
    // the node's code: raw on /camera/image_raw, compressed on /camera/image_raw/compressed.
    let ctx = context(&settings).unwrap();
    let mut cam = ctx
        .new_node(
            NodeName::new("/", "remapped_camera").unwrap(),
            NodeOptions::new().enable_rosout(false),
        )
        .unwrap();
    let mut publisher = |ns: &str| {
        let t = cam
            .create_topic(
                &Name::new(ns, "compressed").unwrap(),
                MessageTypeName::new("sensor_msgs", "CompressedImage"),
                &camera_qos(),
            )
            .unwrap();
        cam.create_publisher::<CompressedImage>(&t, Some(camera_qos()))
            .unwrap()
    };
    let moved = publisher("/camera/image_raw");
    let old = publisher("/image_raw");
    let seq = SynthParams::default();
    let end = Instant::now() + Duration::from_secs(15);
    loop {
        let m = png(&seq, 0);
        moved.publish(m.clone()).unwrap();
        if wait_status(&gs, Duration::from_millis(300), |s| {
            s.header.stamp == m.header.stamp
        })
        .is_some()
        {
            break;
        }
        assert!(
            Instant::now() < end,
            "no status for frames on /camera/image_raw/compressed"
        );
    }
    // Discovery is done (the same participant's other writer matched): frames on the old
    // name are not read any more.
    let mut stamps = Vec::new();
    for t in 1..10 {
        let m = png(&seq, t);
        stamps.push(m.header.stamp);
        old.publish(m).unwrap();
        std::thread::sleep(Duration::from_millis(200));
    }
    assert!(
        wait_status(&gs, Duration::from_secs(1), |s| stamps
            .contains(&s.header.stamp))
        .is_none(),
        "the node still reads /image_raw/compressed"
    );
}

/// The Python parameter client (tests/interop/param_peer.py) as a child process: one JSON
/// command per line in, one JSON answer per line out.
struct ParamPeer {
    child: std::process::Child,
    out: std::io::BufReader<std::process::ChildStdout>,
}

impl ParamPeer {
    fn start(domain: u16, node: &str) -> Result<Self, String> {
        use std::process::{Command, Stdio};
        let py = crate::interop::python()?;
        let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("interop/param_peer.py");
        let mut child = Command::new(py)
            .arg(script)
            .arg(domain.to_string())
            .arg(node)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(|e| e.to_string())?;
        let out = std::io::BufReader::new(child.stdout.take().ok_or("no stdout")?);
        let mut p = Self { child, out };
        let ready = p.read();
        assert_eq!(ready["ready"], true, "parameter peer: {ready}");
        Ok(p)
    }

    fn read(&mut self) -> serde_json::Value {
        use std::io::BufRead;
        let mut line = String::new();
        self.out.read_line(&mut line).unwrap();
        assert!(!line.is_empty(), "the parameter peer exited");
        serde_json::from_str(&line).unwrap()
    }

    fn ask(&mut self, cmd: serde_json::Value) -> serde_json::Value {
        use std::io::Write;
        let stdin = self.child.stdin.as_mut().unwrap();
        writeln!(stdin, "{cmd}").unwrap();
        stdin.flush().unwrap();
        let v = self.read();
        assert!(v.get("error").is_none(), "{cmd}: {v}");
        v
    }

    fn get(&mut self, name: &str) -> serde_json::Value {
        self.ask(serde_json::json!({"cmd": "get", "names": [name]}))["values"][0].clone()
    }

    fn set(&mut self, name: &str, value: serde_json::Value) -> (bool, String) {
        let r = self.ask(serde_json::json!({"cmd": "set", "name": name, "value": value}));
        (
            r["successful"].as_bool().unwrap(),
            r["reason"].as_str().unwrap().to_string(),
        )
    }
}

impl Drop for ParamPeer {
    fn drop(&mut self) {
        drop(self.child.stdin.take());
        let _ = self.child.wait();
    }
}

#[test]
fn ros2_param_round_trip_with_an_independent_cyclone_dds_client() {
    use bevt_msgs::bevt::TrackStatus;
    use bevt_node::node::sim::spawn_camera;
    let settings = RosSettings {
        domain_id: bevt_tests::dds_domain(),
        // The peer speaks rmw_cyclonedds' service mapping.
        service_mapping: ros2_client::ServiceMapping::Cyclone,
        ..RosSettings::default()
    };
    if let Err(e) = crate::interop::python() {
        bevt_tests::skip(
            "ros2_param_round_trip_with_an_independent_cyclone_dds_client",
            format!("no Python environment ({e})"),
        );
        return;
    }
    let node = start(&settings);
    let mut peer = ParamPeer::start(settings.domain_id, "/bevt_node").unwrap();
    let seq = SynthParams {
        frames: 4000,
        ..SynthParams::default()
    };
    // Tracking, whether or not the frame was learned.
    let tracking = |s: &TrackStatus| {
        s.state == TrackStatus::STATE_TRACKING || s.state == TrackStatus::STATE_LOW_CONSENSUS
    };
    let (camera, truth) = spawn_camera(&settings, seq, 20.0, node.stop.clone()).unwrap();
    let gs = GroundStation::new(&settings).unwrap();

    // ros2 param list / describe / get
    let names = peer.ask(serde_json::json!({"cmd": "list"}));
    let names: Vec<&str> = names["names"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    for n in [
        "reinit_rate_hz",
        "debug_image_rate_hz",
        "domain_id",
        "use_sim_time",
        "tracker.learning.rate",
        "tracker.window.padding",
    ] {
        assert!(names.contains(&n), "{n} not listed: {names:?}");
    }
    let d = peer.ask(serde_json::json!({"cmd": "describe",
        "names": ["tracker.track_state.lost_threshold", "tracker.window.padding"]}));
    let (live, fixed) = (&d["descriptors"][0], &d["descriptors"][1]);
    println!("describe: {live}\n          {fixed}");
    assert!(live["description"].as_str().unwrap().len() > 20, "{live}");
    assert_eq!(live["read_only"], false);
    assert_eq!(live["floating_point_range"][0][0], 0.0);
    assert_eq!(live["floating_point_range"][0][1], 1.0);
    assert_eq!(fixed["read_only"], true);
    assert_eq!(peer.get("tracker.track_state.lost_threshold"), 0.3);

    // Start a track on the newest frame the camera published.
    let r = gs
        .start_track_on_newest(&truth, Duration::from_secs(30))
        .expect("reinit answered");
    assert!(r.success, "{}", r.message);
    let track_id = wait_status(&gs, Duration::from_secs(5), tracking)
        .expect("tracking after reinit")
        .track_id;

    // A parameter that shapes the tracker: refused with the reason, old value kept, the
    // node tracking on with the same track.
    let (ok, reason) = peer.set("tracker.window.padding", serde_json::json!(1.5));
    println!("set tracker.window.padding 1.5: {ok} {reason:?}");
    assert!(!ok);
    assert!(reason.contains("read-only while running"), "{reason}");
    assert_eq!(peer.get("tracker.window.padding"), 1.2);
    let (ok, reason) = peer.set("tracker.track_state.lost_threshold", serde_json::json!(2.0));
    println!("set tracker.track_state.lost_threshold 2.0: {ok} {reason:?}");
    assert!(!ok && reason.contains("[0, 1]"), "{reason}");
    let (ok, reason) = peer.set("reinit_rate_hz", serde_json::json!("fast"));
    assert!(!ok && reason.contains("wrong type"), "{reason}");
    gs.take_status();
    let s = wait_status(&gs, Duration::from_secs(5), tracking)
        .expect("still tracking after the refused sets");
    assert_eq!(s.track_id, track_id);

    // A live parameter: accepted, visible in get, in effect on the running track (a
    // confidence threshold no frame reaches makes the same track uncertain at once).
    let (ok, reason) = peer.set("tracker.track_state.lost_threshold", serde_json::json!(1.0));
    assert!(ok, "{reason}");
    assert_eq!(peer.get("tracker.track_state.lost_threshold"), 1.0);
    gs.take_status();
    let s = wait_status(&gs, Duration::from_secs(5), |s| {
        s.state == TrackStatus::STATE_UNCERTAIN || s.state == TrackStatus::STATE_LOST
    })
    .expect("the new threshold did not take effect");
    assert_eq!(s.track_id, track_id, "the same track, not a new one");
    // An integer for a double, as `ros2 param set bevt_node reinit_rate_hz 2` sends.
    let (ok, reason) = peer.set("reinit_rate_hz", serde_json::json!(2));
    assert!(ok, "{reason}");
    assert_eq!(peer.get("reinit_rate_hz"), 2.0);

    // /parameter_events: the two accepted changes, none of the refused ones. Events reach
    // the peer asynchronously (on a loaded machine the second can come seconds after its
    // set was answered): ask until two have come or 20 s passed, then compare exactly (a
    // refused set's event, arriving in between, would show as a third).
    let expected = vec![
        (
            "tracker.track_state.lost_threshold".to_string(),
            serde_json::json!(1.0),
        ),
        ("reinit_rate_hz".to_string(), serde_json::json!(2.0)),
    ];
    let end = Instant::now() + Duration::from_secs(20);
    let changed = loop {
        let ev = peer.ask(serde_json::json!({"cmd": "events"}));
        let changed: Vec<(String, serde_json::Value)> = ev["events"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|e| e["node"] == "/bevt_node")
            .flat_map(|e| e["changed"].as_array().unwrap().clone())
            .map(|c| (c[0].as_str().unwrap().to_string(), c[1].clone()))
            .collect();
        if changed.len() >= expected.len() || Instant::now() >= end {
            println!("events: {ev}");
            break changed;
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    assert_eq!(changed, expected);
    drop(node);
    let _ = camera.join();
}
