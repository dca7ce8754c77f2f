//! Our CDR bytes equal those of an independent serializer (Python `rosbags`), for every
//! type the node puts on the wire. Regenerate the files with
//! `$(scripts/python-env.sh) scripts/cdr_golden.py` after changing a `.msg`.
#![allow(clippy::unwrap_used, missing_docs)]

use bevt_msgs::builtin_interfaces::Time;
use bevt_msgs::geometry_msgs::{Covariance36, PoseWithCovariance};
use bevt_msgs::std_msgs::Header;
use bevt_msgs::*;
use byteorder::LittleEndian;
use serde::{de::DeserializeOwned, Serialize};
use std::fmt::Debug;

/// CDR little-endian encapsulation header.
const CDR_LE: [u8; 4] = [0, 1, 0, 0];

fn header() -> Header {
    Header {
        stamp: Time {
            sec: 1_700_000_000,
            nanosec: 123_456_789,
        },
        frame_id: "camera_optical".into(),
    }
}

fn check<T: Serialize + DeserializeOwned + PartialEq + Debug>(name: &str, msg: &T) {
    let path = format!("{}/tests/golden/{name}.cdr", env!("CARGO_MANIFEST_DIR"));
    let golden = std::fs::read(&path).unwrap();
    let mut ours = CDR_LE.to_vec();
    ours.extend(cdr_encoding::to_vec::<T, LittleEndian>(msg).unwrap());
    assert_eq!(ours, golden, "{name}: our CDR differs from rosbags'");
    let (back, _) = cdr_encoding::from_bytes::<T, LittleEndian>(&golden[4..]).unwrap();
    assert_eq!(&back, msg, "{name}: decoding the reference bytes");
}

#[test]
fn image_types_match_the_reference_cdr() {
    check(
        "image",
        &sensor_msgs::Image {
            header: header(),
            height: 2,
            width: 3,
            encoding: "rgb8".into(),
            is_bigendian: 0,
            step: 9,
            data: (0..18).collect(),
        },
    );
    check(
        "compressed_image",
        &sensor_msgs::CompressedImage {
            header: header(),
            format: "jpeg".into(),
            data: vec![0xFF, 0xD8, 0xFF, 0xD9],
        },
    );
}

#[test]
fn detections_and_diagnostics_match_the_reference_cdr() {
    let mut cov = [0.0; 36];
    for (i, c) in cov.iter_mut().enumerate() {
        *c = i as f64 * 0.5;
    }
    let det = vision_msgs::Detection2D {
        header: header(),
        results: vec![vision_msgs::ObjectHypothesisWithPose {
            hypothesis: vision_msgs::ObjectHypothesis {
                class_id: "target".into(),
                score: 0.875,
            },
            pose: PoseWithCovariance {
                covariance: Covariance36(cov),
                ..Default::default()
            },
        }],
        bbox: vision_msgs::BoundingBox2D {
            center: vision_msgs::Pose2D {
                position: vision_msgs::Point2D { x: 100.5, y: 50.25 },
                theta: 0.0,
            },
            size_x: 40.0,
            size_y: 30.0,
        },
        id: "7".into(),
    };
    check(
        "detection2d_array",
        &vision_msgs::Detection2DArray {
            header: header(),
            detections: vec![det],
        },
    );
    check(
        "diagnostic_array",
        &diagnostic_msgs::DiagnosticArray {
            header: header(),
            status: vec![diagnostic_msgs::DiagnosticStatus {
                level: diagnostic_msgs::DiagnosticStatus::WARN,
                name: "bevt_node: tracker".into(),
                message: "low consensus".into(),
                hardware_id: "camera".into(),
                values: vec![
                    diagnostic_msgs::KeyValue {
                        key: "fps".into(),
                        value: "30.0".into(),
                    },
                    diagnostic_msgs::KeyValue {
                        key: "dropped".into(),
                        value: "2".into(),
                    },
                ],
            }],
        },
    );
}

#[test]
fn project_types_match_the_reference_cdr() {
    check(
        "track_status",
        &bevt::TrackStatus {
            header: header(),
            state: bevt::TrackStatus::STATE_LOW_CONSENSUS,
            reason: "consensus 0.15 <= 0.20".into(),
            x: 1.5,
            y: 2.5,
            width: 40.0,
            height: 30.0,
            consensus: 0.15,
            confidence: 0.42,
            learned: false,
            peak: 0.012,
            scale: 1.25,
            latency_ms: 4.5,
            frames_processed: 100,
            frames_dropped: 3,
            track_id: 2,
        },
    );
    check(
        "reinit_request",
        &bevt::ReinitRequest {
            x: 10.0,
            y: 20.0,
            width: 30.0,
            height: 40.0,
            stamp: Time { sec: 5, nanosec: 6 },
            frame_id: "cam".into(),
        },
    );
    check(
        "reinit_response",
        &bevt::ReinitResponse {
            success: true,
            message: "ok".into(),
        },
    );
    check("trigger_request", &std_srvs::TriggerRequest::default());
    check(
        "trigger_response",
        &std_srvs::TriggerResponse {
            success: true,
            message: "stopped".into(),
        },
    );
}

#[test]
fn a_truncated_image_is_an_error_not_a_panic_or_a_huge_allocation() {
    let golden = std::fs::read(format!(
        "{}/tests/golden/image.cdr",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap();
    // Claim 4 GB of pixel data in a short message: decoding must fail cleanly.
    let mut bad = golden[4..].to_vec();
    let n = bad.len();
    bad[n - 22..n - 18].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(cdr_encoding::from_bytes::<sensor_msgs::Image, LittleEndian>(&bad).is_err());
    for cut in [0, 5, 30, n - 1] {
        assert!(cdr_encoding::from_bytes::<sensor_msgs::Image, LittleEndian>(&bad[..cut]).is_err());
    }
}

#[test]
fn foxglove_image_annotations_match_the_reference_cdr() {
    use foxglove_msgs::*;
    let stamp = header().stamp;
    let green = Color {
        r: 0.0,
        g: 1.0,
        b: 0.25,
        a: 1.0,
    };
    let clear = Color::default();
    let p = |x, y| Point2 { x, y };
    check(
        "image_annotations",
        &ImageAnnotations {
            circles: vec![CircleAnnotation {
                timestamp: stamp,
                position: p(120.5, 65.25),
                diameter: 4.0,
                thickness: 1.5,
                fill_color: green,
                outline_color: clear,
            }],
            points: vec![PointsAnnotation {
                timestamp: stamp,
                r#type: PointsAnnotation::LINE_LOOP,
                points: vec![
                    p(100.5, 50.25),
                    p(140.5, 50.25),
                    p(140.5, 80.25),
                    p(100.5, 80.25),
                ],
                outline_color: green,
                outline_colors: vec![],
                fill_color: clear,
                thickness: 2.0,
            }],
            texts: vec![TextAnnotation {
                timestamp: stamp,
                position: p(100.5, 48.0),
                text: "track 7 0.88".into(),
                font_size: 14.0,
                text_color: green,
                background_color: clear,
            }],
        },
    );
}

#[test]
fn image_views_borrow_the_reference_bytes() {
    let dir = format!("{}/tests/golden", env!("CARGO_MANIFEST_DIR"));
    let raw = std::fs::read(format!("{dir}/image.cdr")).unwrap();
    let (owned, _) =
        cdr_encoding::from_bytes::<sensor_msgs::Image, LittleEndian>(&raw[4..]).unwrap();
    let (view, _) =
        cdr_encoding::from_bytes::<sensor_msgs::ImageView, LittleEndian>(&raw[4..]).unwrap();
    assert_eq!(view, owned.view());
    // The pixels are the serialised bytes themselves, not a copy.
    let inside = raw.as_ptr_range();
    assert!(inside.contains(&view.data.as_ptr()));
    assert_eq!(view.data, &(0..18).collect::<Vec<u8>>()[..]);

    let raw = std::fs::read(format!("{dir}/compressed_image.cdr")).unwrap();
    let (owned, _) =
        cdr_encoding::from_bytes::<sensor_msgs::CompressedImage, LittleEndian>(&raw[4..]).unwrap();
    let (view, _) =
        cdr_encoding::from_bytes::<sensor_msgs::CompressedImageView, LittleEndian>(&raw[4..])
            .unwrap();
    assert_eq!(view, owned.view());
    assert!(raw.as_ptr_range().contains(&view.data.as_ptr()));
    // A view of a truncated message is an error, as for the owned type.
    assert!(
        cdr_encoding::from_bytes::<sensor_msgs::CompressedImageView, LittleEndian>(
            &raw[4..raw.len() - 1]
        )
        .is_err()
    );
}
