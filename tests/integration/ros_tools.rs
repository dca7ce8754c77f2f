//! The node among ROS tools: image_transport's topic naming and (with a peer on an
//! independent DDS implementation) the `rcl_interfaces` parameter services.

use bevt_core::eval::synth::SynthParams;
use bevt_core::TrackerConfig;
use bevt_msgs::sensor_msgs::CompressedImage;
use bevt_node::node::app::{NodeCore, NodeSettings};
use bevt_node::node::ros::{camera_qos, context, run, RosSettings};
use bevt_node::node::sim::{wall_stamp, GroundStation};
use bevt_tests::{synth_image, wait_status};
use ros2_client::{MessageTypeName, Name, NodeName, NodeOptions};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A domain none of the other tests of this process uses (node_limits 1..18, the DDS
/// hardening tests 20..94, fastdds_interop 95..99, node.rs 100..219, interop 200..229).
fn domain(k: u16) -> u16 {
    230 + (std::process::id() % 2) as u16 + k
}

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
    let (m, _) = synth_image(seq, t);
    let mut data = Vec::new();
    image::RgbImage::from_raw(m.width, m.height, m.data)
        .unwrap()
        .write_to(
            &mut std::io::Cursor::new(&mut data),
            image::ImageFormat::Png,
        )
        .unwrap();
    CompressedImage {
        header: bevt_msgs::std_msgs::Header {
            stamp: wall_stamp(),
            frame_id: "cam".into(),
        },
        format: "png".into(),
        data,
    }
}

#[test]
fn a_remapped_raw_topic_takes_the_compressed_input_with_it() {
    // `ros2 run bevt_node bevt_node --ros-args -r image_raw:=/camera/image_raw`
    let settings = RosSettings {
        domain_id: domain(0),
        remaps: vec![("image_raw".into(), "/camera/image_raw".into())],
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
