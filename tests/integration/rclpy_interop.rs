//! The node against the real ROS 2 client library: rclpy over rcl and rmw_fastrtps_cpp
//! (Fast DDS 3.2) from the PyPI ROS wheels in the project-local venv
//! (`scripts/requirements-ros.txt`), driven by `tests/interop/rclpy_peer.py` as `ros2 param`,
//! `ros2 topic` and a ROS 2 camera use it, with ROS 2's default discovery settings, against
//! the node as its own process (`bevt_node_under_test`, what `ros2 run` starts).
//!
//! Checked: the node, its topics and services in the ROS graph; `list_parameters` with
//! depth 0 (what `ros2 param list` sends) returns every declared parameter; get and describe
//! of all of them in one request; a set and its `/parameter_events`; 1 MB `Image`s published
//! by rclpy are tracked (the ground station here initialises the track, the peer knows the
//! truth); the debug image, a large message *from* the node, arrives intact.

use bevt_core::{BBox, TrackerConfig};
use bevt_msgs::bevt::TrackStatus;
use bevt_node::node::app::NodeSettings;
use bevt_node::node::param_services::NodeParams;
use bevt_node::node::ros::RosSettings;
use bevt_node::node::sim::GroundStation;
use serde_json::{json, Value};
use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::time::{Duration, Instant};

const TEST: &str = "rclpy_client_lists_sets_streams_and_receives_large_messages";
/// 800×450 rgb8 = 1 080 000 bytes: at least 1 MB, about 17 datagrams of fragments.
const WIDTH: u32 = 800;
const HEIGHT: u32 = 450;

struct Peer {
    child: Child,
    out: BufReader<ChildStdout>,
}

impl Peer {
    fn start(domain: u16) -> Result<Self, String> {
        let py = crate::interop::python()?;
        let venv = py
            .parent()
            .and_then(|bin| bin.parent())
            .ok_or("no venv")?
            .to_path_buf();
        let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("interop/rclpy_peer.py");
        let mut cmd = Command::new(&py);
        cmd.arg(script)
            .arg("/bevt_node")
            // The wheels' shared libraries (rcl, rmw_fastrtps_cpp, Fast DDS).
            .env("LD_LIBRARY_PATH", venv.join("lib"))
            .env("ROS_DOMAIN_ID", domain.to_string())
            .env("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit());
        // ROS 2's defaults, whatever the calling shell set.
        for var in [
            "ROS_LOCALHOST_ONLY",
            "ROS_AUTOMATIC_DISCOVERY_RANGE",
            "ROS_STATIC_PEERS",
            "FASTRTPS_DEFAULT_PROFILES_FILE",
            "FASTDDS_DEFAULT_PROFILES_FILE",
            "ROS_DISCOVERY_SERVER",
        ] {
            cmd.env_remove(var);
        }
        // Socket buffers large enough for a burst of 1 MB image fragments (the profile
        // says why); discovery and transports otherwise as by default.
        cmd.env(
            "FASTDDS_DEFAULT_PROFILES_FILE",
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("interop/fastdds_large_data.xml"),
        );
        let mut child = cmd.spawn().map_err(|e| e.to_string())?;
        let out = BufReader::new(child.stdout.take().ok_or("no stdout")?);
        let mut p = Self { child, out };
        let ready = p.read();
        if ready["ready"] != true {
            return Err(format!("rclpy peer did not start: {ready}"));
        }
        Ok(p)
    }

    fn read(&mut self) -> Value {
        let mut line = String::new();
        self.out.read_line(&mut line).unwrap();
        assert!(!line.is_empty(), "the rclpy peer exited");
        serde_json::from_str(&line).unwrap()
    }

    fn ask(&mut self, cmd: Value) -> Value {
        let stdin = self.child.stdin.as_mut().unwrap();
        writeln!(stdin, "{cmd}").unwrap();
        stdin.flush().unwrap();
        let v = self.read();
        assert!(v.get("error").is_none(), "{cmd}: {v}");
        v
    }
}

impl Drop for Peer {
    fn drop(&mut self) {
        if let Some(mut stdin) = self.child.stdin.take() {
            let _ = writeln!(stdin, "{}", json!({"cmd": "quit"}));
        }
        let end = Instant::now() + Duration::from_secs(5);
        while Instant::now() < end {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn strings(v: &Value) -> Vec<String> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap().to_string())
        .collect()
}

#[test]
fn rclpy_client_lists_sets_streams_and_receives_large_messages() {
    let settings = RosSettings {
        domain_id: bevt_tests::dds_domain(),
        debug_image_rate_hz: 5.0,
        ..RosSettings::default()
    };
    let mut peer = match Peer::start(settings.domain_id) {
        Ok(p) => p,
        Err(e) => {
            bevt_tests::skip(TEST, format!("no rclpy from the PyPI ROS wheels ({e})"));
            return;
        }
    };
    let declared: Vec<String> = NodeParams::new(
        &settings,
        &NodeSettings::default(),
        &TrackerConfig::default(),
    )
    .declared()
    .keys()
    .cloned()
    .collect();
    // The node as its own process, as `ros2 run` starts it; it stops when its stdin closes.
    let mut node = Command::new(env!("CARGO_BIN_EXE_bevt_node_under_test"))
        .args(["--ros-args", "-p", "debug_image_rate_hz:=5.0"])
        .env("ROS_DOMAIN_ID", settings.domain_id.to_string())
        .env_remove("ROS_SECURITY_ENABLE")
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    let gs = GroundStation::new(&settings).unwrap();

    // The graph, as `ros2 node list` / `topic list` / `service list` see it.
    let t0 = Instant::now();
    let g = peer.ask(json!({"cmd": "graph", "timeout": 30}));
    println!("in the graph after {:.1} s", t0.elapsed().as_secs_f64());
    let topics = strings(&g["topics"]);
    let services = strings(&g["services"]);
    for t in ["/image_raw", "/track_status", "/detections", "/debug_image"] {
        assert!(topics.contains(&t.to_string()), "{t} not in {topics:?}");
    }
    for s in ["get", "set", "list", "describe"] {
        let s = format!("/bevt_node/{s}_parameters");
        assert!(services.contains(&s), "{s} not in {services:?}");
    }
    assert!(services.contains(&"/reinit".to_string()), "{services:?}");

    // `ros2 param list`: depth 0, every declared parameter.
    let mut listed = strings(&peer.ask(json!({"cmd": "list", "depth": 0}))["names"]);
    listed.sort();
    assert_eq!(listed, declared, "list_parameters depth 0");
    println!("list_parameters depth 0: {} names", listed.len());
    // `ros2 param dump`: all of them in one get and one describe (replies of several KB,
    // sent as DATA_FRAGs with the request's identity as inline QoS).
    let values = peer.ask(json!({"cmd": "get", "names": declared}))["values"].clone();
    assert_eq!(values.as_array().unwrap().len(), declared.len());
    let at = |name: &str| declared.iter().position(|n| n == name).unwrap();
    assert_eq!(values[at("tracker.track_state.lost_threshold")], 0.3);
    assert_eq!(values[at("debug_image_rate_hz")], 5.0);
    let d = peer.ask(json!({"cmd": "describe", "names": declared}))["descriptors"].clone();
    let d = d.as_array().unwrap();
    assert_eq!(d.len(), declared.len());
    for (desc, name) in d.iter().zip(&declared) {
        assert_eq!(desc["name"], name.as_str());
        assert!(!desc["description"].as_str().unwrap().is_empty(), "{desc}");
    }
    assert_eq!(d[at("tracker.window.padding")]["read_only"], true);
    assert_eq!(
        d[at("tracker.track_state.lost_threshold")]["floating_point_range"][0],
        json!([0.0, 1.0, 0.0])
    );

    // `ros2 param set` and the event it causes.
    let r = peer.ask(json!({"cmd": "set", "name": "reinit_rate_hz", "value": 3.0}));
    assert_eq!(r["successful"], true, "{r}");
    let r = peer.ask(json!({"cmd": "set", "name": "tracker.window.padding", "value": 1.5}));
    assert_eq!(r["successful"], false, "{r}");
    let end = Instant::now() + Duration::from_secs(5);
    loop {
        let ev = peer.ask(json!({"cmd": "events"}));
        let changed: Vec<Value> = ev["events"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|e| e["node"] == "/bevt_node")
            .flat_map(|e| e["changed"].as_array().unwrap().clone())
            .collect();
        if !changed.is_empty() {
            assert_eq!(changed, vec![json!(["reinit_rate_hz", 3.0])]);
            break;
        }
        assert!(
            Instant::now() < end,
            "no /parameter_events from the node: {ev}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }

    // A ROS 2 camera: 1 MB rgb8 frames at 10 Hz, published by rclpy.
    let reliable = std::env::var("BEVT_DEBUG_BE").is_err();
    peer.ask(json!({"cmd": "debug", "topic": "/debug_image", "reliable": reliable}));
    let cam = peer.ask(json!({"cmd": "camera", "topic": "/image_raw",
        "width": WIDTH, "height": HEIGHT, "rate": 10.0}));
    assert!(cam["frame_bytes"].as_u64().unwrap() >= 1_000_000);
    // Initialise on a frame the node has received (its status carries the stamp).
    let end = Instant::now() + Duration::from_secs(20);
    let seen = loop {
        if let Some(s) = gs.take_status().pop() {
            break s;
        }
        assert!(
            Instant::now() < end,
            "no status: the node got no frame from rclpy"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    let truth = peer.ask(json!({"cmd": "truth"}))["frames"].clone();
    let box_at = |truth: &Value, stamp: i64| -> Option<BBox> {
        truth.as_array().unwrap().iter().find_map(|f| {
            (f[0].as_i64() == Some(stamp)).then(|| {
                let b: Vec<f32> = f[1]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|v| v.as_f64().unwrap() as f32)
                    .collect();
                BBox::new(b[0], b[1], b[2], b[3])
            })
        })
    };
    let stamp = seen.header.stamp.as_nanos();
    let b = box_at(&truth, stamp).expect("the status's stamp is a published frame");
    let req = bevt_node::convert::reinit_request(b, seen.header.stamp, "");
    let r = gs
        .reinit(&req, Duration::from_secs(5))
        .expect("reinit reply");
    assert!(r.success, "{}", r.message);

    // Track for 4 s, then score every status against the peer's truth.
    std::thread::sleep(Duration::from_secs(4));
    let statuses: Vec<TrackStatus> = gs.take_status();
    let truth = peer.ask(json!({"cmd": "truth"}))["frames"].clone();
    let mut errors = Vec::new();
    for s in statuses
        .iter()
        .filter(|s| s.state == TrackStatus::STATE_TRACKING)
    {
        if let Some(t) = box_at(&truth, s.header.stamp.as_nanos()) {
            let (cx, cy) = (s.x + s.width / 2.0, s.y + s.height / 2.0);
            let (tx, ty) = (t.x + t.w / 2.0, t.y + t.h / 2.0);
            errors.push(((cx - tx).powi(2) + (cy - ty).powi(2)).sqrt());
        }
    }
    let hits = errors.iter().filter(|e| **e < 10.0).count();
    println!(
        "tracked {} frames from rclpy, {hits} within 10 px (of {} statuses)",
        errors.len(),
        statuses.len()
    );
    assert!(errors.len() >= 15, "too few tracked frames: {statuses:?}");
    assert!(hits * 10 >= errors.len() * 9, "centre errors {errors:?}");

    // The debug image: ~1 MB from the node, fragmented, equal to the frame outside the
    // drawn box.
    let dbg = peer.ask(json!({"cmd": "debug", "topic": "/debug_image", "reliable": reliable}));
    println!(
        "debug images: {} received, {} of the last {} checked intact",
        dbg["received"], dbg["intact"], dbg["kept"]
    );
    // Every image that arrives is whole. How many arrive depends on the subscriber's
    // socket receive buffer (docs/ros.md, Interoperability): measured 1-11 of ~20 at
    // Linux's default 208 KiB, 20 of 20 with 4 MiB (the peer's Fast DDS profile).
    // 4 s at 5 Hz: about 20 published.
    let received = dbg["received"].as_u64().unwrap();
    let kept = dbg["kept"].as_u64().unwrap();
    let intact = dbg["intact"].as_u64().unwrap();
    assert!(received >= 12, "{dbg}");
    assert_eq!(intact, kept, "{dbg}");

    // The camera stops: so does the debug image (no repeats of the last frame).
    peer.ask(json!({"cmd": "camera_stop"}));
    std::thread::sleep(Duration::from_millis(800));
    let before = peer.ask(json!({"cmd": "debug", "topic": "/debug_image"}))["received"].clone();
    std::thread::sleep(Duration::from_secs(2));
    let after = peer.ask(json!({"cmd": "debug", "topic": "/debug_image"}))["received"].clone();
    assert_eq!(before, after, "debug images after the camera stopped");

    assert!(
        node.try_wait().unwrap().is_none(),
        "the node exited during the test"
    );
    drop(node.stdin.take());
    let status = node.wait().unwrap();
    assert!(status.success(), "the node's exit: {status}");
}
