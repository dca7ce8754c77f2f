//! # bevt_msgs: the wire types of the BEVT-rs node
//!
//! Plain serde structs whose field order follows the `.msg` definitions, which is the
//! CDR layout: serialised with a CDR serializer (as `ros2-client` does) they are
//! byte-identical to what `rclcpp`/`rclpy` send (pinned by golden files made with the
//! Python `rosbags` serializer, `tests/golden/`). No logic lives here.
//!
//! Standard types used by the node are mirrored in modules named after their ROS
//! packages; the project's own types are in [`bevt`] and match `msg/` and `srv/`, which
//! also make this folder a ROS 2 interface package (`package.xml`, `CMakeLists.txt`).
//!
//! With feature `ros2`, the service types implement `ros2_client::Message`.
#![deny(missing_docs)]

use serde::{Deserialize, Serialize};

pub mod ros2msg;

/// A ROS type name: package and type, e.g. `("sensor_msgs", "Image")`.
pub trait RosType {
    /// ROS package, e.g. `sensor_msgs`.
    const PACKAGE: &'static str;
    /// Type name, e.g. `Image`.
    const NAME: &'static str;
}

macro_rules! ros_type {
    ($t:ty, $pkg:literal, $name:literal) => {
        impl RosType for $t {
            const PACKAGE: &'static str = $pkg;
            const NAME: &'static str = $name;
        }
    };
}

/// `builtin_interfaces`.
pub mod builtin_interfaces {
    use super::*;
    /// `builtin_interfaces/Time`.
    #[derive(
        Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default, Serialize, Deserialize,
    )]
    pub struct Time {
        /// Seconds.
        pub sec: i32,
        /// Nanoseconds, 0..1e9.
        pub nanosec: u32,
    }
    impl Time {
        /// Total nanoseconds.
        pub fn as_nanos(&self) -> i64 {
            self.sec as i64 * 1_000_000_000 + self.nanosec as i64
        }
        /// From total nanoseconds (negative values clamp to 0).
        pub fn from_nanos(ns: i64) -> Self {
            let ns = ns.max(0);
            Self {
                sec: (ns / 1_000_000_000).min(i32::MAX as i64) as i32,
                nanosec: (ns % 1_000_000_000) as u32,
            }
        }
        /// True for the zero stamp.
        pub fn is_zero(&self) -> bool {
            self.sec == 0 && self.nanosec == 0
        }
    }
    ros_type!(Time, "builtin_interfaces", "Time");
}

/// `std_msgs`.
pub mod std_msgs {
    use super::*;
    /// `std_msgs/Header`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct Header {
        /// Acquisition time.
        pub stamp: builtin_interfaces::Time,
        /// Coordinate frame.
        pub frame_id: String,
    }
    ros_type!(Header, "std_msgs", "Header");
}

/// `sensor_msgs`.
pub mod sensor_msgs {
    use super::*;
    /// `sensor_msgs/Image`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct Image {
        /// Stamp and camera frame.
        pub header: std_msgs::Header,
        /// Rows.
        pub height: u32,
        /// Columns.
        pub width: u32,
        /// Pixel encoding, e.g. `rgb8`.
        pub encoding: String,
        /// Byte order of multi-byte pixels.
        pub is_bigendian: u8,
        /// Row length, bytes.
        pub step: u32,
        /// Pixels (`sequence<uint8>`).
        #[serde(with = "serde_bytes")]
        pub data: Vec<u8>,
    }
    ros_type!(Image, "sensor_msgs", "Image");

    /// `sensor_msgs/CompressedImage`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct CompressedImage {
        /// Stamp and camera frame.
        pub header: std_msgs::Header,
        /// `jpeg` or `png` (image_transport may prefix the raw encoding, e.g. `rgb8; jpeg compressed bgr8`).
        pub format: String,
        /// The compressed bytes.
        #[serde(with = "serde_bytes")]
        pub data: Vec<u8>,
    }
    ros_type!(CompressedImage, "sensor_msgs", "CompressedImage");

    /// A `sensor_msgs/Image` whose pixels are borrowed from the serialised message (a
    /// recorded bag's buffer): decoding it copies no pixel data.
    #[derive(Debug, Clone, PartialEq, Default, Deserialize)]
    pub struct ImageView<'a> {
        /// Stamp and camera frame.
        pub header: std_msgs::Header,
        /// Rows.
        pub height: u32,
        /// Columns.
        pub width: u32,
        /// Pixel encoding, e.g. `rgb8`.
        pub encoding: String,
        /// Byte order of multi-byte pixels.
        pub is_bigendian: u8,
        /// Row length, bytes.
        pub step: u32,
        /// Pixels, borrowed.
        pub data: &'a [u8],
    }

    /// A `sensor_msgs/CompressedImage` whose bytes are borrowed (see [`ImageView`]).
    #[derive(Debug, Clone, PartialEq, Default, Deserialize)]
    pub struct CompressedImageView<'a> {
        /// Stamp and camera frame.
        pub header: std_msgs::Header,
        /// `jpeg` or `png`.
        pub format: String,
        /// The compressed bytes, borrowed.
        pub data: &'a [u8],
    }

    impl Image {
        /// A borrowed view (the header and encoding are cloned, the pixels are not).
        pub fn view(&self) -> ImageView<'_> {
            ImageView {
                header: self.header.clone(),
                height: self.height,
                width: self.width,
                encoding: self.encoding.clone(),
                is_bigendian: self.is_bigendian,
                step: self.step,
                data: &self.data,
            }
        }
    }

    impl CompressedImage {
        /// A borrowed view (the header and format are cloned, the bytes are not).
        pub fn view(&self) -> CompressedImageView<'_> {
            CompressedImageView {
                header: self.header.clone(),
                format: self.format.clone(),
                data: &self.data,
            }
        }
    }
}

/// `geometry_msgs`.
pub mod geometry_msgs {
    use super::*;
    use serde::de::{SeqAccess, Visitor};
    use serde::ser::SerializeTuple;

    /// `geometry_msgs/Point`.
    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct Point {
        /// x.
        pub x: f64,
        /// y.
        pub y: f64,
        /// z.
        pub z: f64,
    }
    /// `geometry_msgs/Quaternion`.
    #[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
    pub struct Quaternion {
        /// x.
        pub x: f64,
        /// y.
        pub y: f64,
        /// z.
        pub z: f64,
        /// w.
        pub w: f64,
    }
    impl Default for Quaternion {
        fn default() -> Self {
            Self {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 1.0,
            }
        }
    }
    /// `geometry_msgs/Pose`.
    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct Pose {
        /// Position.
        pub position: Point,
        /// Orientation.
        pub orientation: Quaternion,
    }
    /// `float64[36]`: a fixed-size CDR array (no length prefix).
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct Covariance36(pub [f64; 36]);
    impl Default for Covariance36 {
        fn default() -> Self {
            Self([0.0; 36])
        }
    }
    impl Serialize for Covariance36 {
        fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
            let mut t = s.serialize_tuple(36)?;
            for v in &self.0 {
                t.serialize_element(v)?;
            }
            t.end()
        }
    }
    impl<'de> Deserialize<'de> for Covariance36 {
        fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
            struct V;
            impl<'de> Visitor<'de> for V {
                type Value = Covariance36;
                fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                    f.write_str("36 float64 values")
                }
                fn visit_seq<A: SeqAccess<'de>>(
                    self,
                    mut seq: A,
                ) -> Result<Covariance36, A::Error> {
                    let mut out = [0.0; 36];
                    for (i, slot) in out.iter_mut().enumerate() {
                        *slot = seq
                            .next_element()?
                            .ok_or_else(|| serde::de::Error::invalid_length(i, &self))?;
                    }
                    Ok(Covariance36(out))
                }
            }
            d.deserialize_tuple(36, V)
        }
    }
    /// `geometry_msgs/PoseWithCovariance`.
    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct PoseWithCovariance {
        /// Pose.
        pub pose: Pose,
        /// Row-major 6×6 covariance.
        pub covariance: Covariance36,
    }
}

/// `vision_msgs` (ROS 2 Humble and later: 4.x layout).
pub mod vision_msgs {
    use super::*;
    /// `vision_msgs/Point2D`.
    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct Point2D {
        /// x, pixels.
        pub x: f64,
        /// y, pixels.
        pub y: f64,
    }
    /// `vision_msgs/Pose2D`.
    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct Pose2D {
        /// Position.
        pub position: Point2D,
        /// Rotation, radians.
        pub theta: f64,
    }
    /// `vision_msgs/BoundingBox2D`: centre and size, pixels.
    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct BoundingBox2D {
        /// Centre.
        pub center: Pose2D,
        /// Width.
        pub size_x: f64,
        /// Height.
        pub size_y: f64,
    }
    /// `vision_msgs/ObjectHypothesis`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct ObjectHypothesis {
        /// Class.
        pub class_id: String,
        /// Score (the node puts the track's confidence here).
        pub score: f64,
    }
    /// `vision_msgs/ObjectHypothesisWithPose`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct ObjectHypothesisWithPose {
        /// Class and score.
        pub hypothesis: ObjectHypothesis,
        /// 3-D pose (unused by a 2-D tracker: identity).
        pub pose: geometry_msgs::PoseWithCovariance,
    }
    /// `vision_msgs/Detection2D`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct Detection2D {
        /// Header of the image.
        pub header: std_msgs::Header,
        /// Hypotheses.
        pub results: Vec<ObjectHypothesisWithPose>,
        /// The box.
        pub bbox: BoundingBox2D,
        /// Track id.
        pub id: String,
    }
    /// `vision_msgs/Detection2DArray`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct Detection2DArray {
        /// Header of the image.
        pub header: std_msgs::Header,
        /// Detections (one while tracking, none while idle).
        pub detections: Vec<Detection2D>,
    }
    ros_type!(Detection2DArray, "vision_msgs", "Detection2DArray");
}

/// `foxglove_msgs` (the ROS 2 package of the Foxglove schemas): image annotations drawn
/// over a camera image in Foxglove's Image panel.
pub mod foxglove_msgs {
    use super::*;
    /// `foxglove_msgs/Point2`: pixels, origin at the top-left corner of the top-left pixel.
    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct Point2 {
        /// x.
        pub x: f64,
        /// y.
        pub y: f64,
    }
    /// `foxglove_msgs/Color`: RGBA, each in `[0, 1]`.
    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct Color {
        /// Red.
        pub r: f64,
        /// Green.
        pub g: f64,
        /// Blue.
        pub b: f64,
        /// Alpha.
        pub a: f64,
    }
    /// `foxglove_msgs/CircleAnnotation`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct CircleAnnotation {
        /// Stamp of the image it belongs to.
        pub timestamp: builtin_interfaces::Time,
        /// Centre.
        pub position: Point2,
        /// Diameter, pixels.
        pub diameter: f64,
        /// Line thickness, pixels.
        pub thickness: f64,
        /// Fill.
        pub fill_color: Color,
        /// Outline.
        pub outline_color: Color,
    }
    /// `foxglove_msgs/PointsAnnotation`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct PointsAnnotation {
        /// Stamp of the image it belongs to.
        pub timestamp: builtin_interfaces::Time,
        /// One of the `POINTS`, `LINE_LOOP`, ... constants.
        pub r#type: u8,
        /// Points, pixels.
        pub points: Vec<Point2>,
        /// Outline colour.
        pub outline_color: Color,
        /// Per-point outline colours (empty: `outline_color`).
        pub outline_colors: Vec<Color>,
        /// Fill colour.
        pub fill_color: Color,
        /// Line thickness, pixels.
        pub thickness: f64,
    }
    impl PointsAnnotation {
        /// Unknown.
        pub const UNKNOWN: u8 = 0;
        /// Individual points.
        pub const POINTS: u8 = 1;
        /// A closed polygon.
        pub const LINE_LOOP: u8 = 2;
        /// An open polyline.
        pub const LINE_STRIP: u8 = 3;
        /// Independent segments.
        pub const LINE_LIST: u8 = 4;
    }
    /// `foxglove_msgs/TextAnnotation`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct TextAnnotation {
        /// Stamp of the image it belongs to.
        pub timestamp: builtin_interfaces::Time,
        /// Bottom-left of the text, pixels.
        pub position: Point2,
        /// The text.
        pub text: String,
        /// Font size, pixels.
        pub font_size: f64,
        /// Text colour.
        pub text_color: Color,
        /// Background colour.
        pub background_color: Color,
    }
    /// `foxglove_msgs/ImageAnnotations`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct ImageAnnotations {
        /// Circles.
        pub circles: Vec<CircleAnnotation>,
        /// Points, polygons and lines.
        pub points: Vec<PointsAnnotation>,
        /// Texts.
        pub texts: Vec<TextAnnotation>,
    }
    ros_type!(ImageAnnotations, "foxglove_msgs", "ImageAnnotations");
}

/// `diagnostic_msgs`.
pub mod diagnostic_msgs {
    use super::*;
    /// `diagnostic_msgs/KeyValue`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct KeyValue {
        /// Key.
        pub key: String,
        /// Value.
        pub value: String,
    }
    /// `diagnostic_msgs/DiagnosticStatus`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct DiagnosticStatus {
        /// 0 OK, 1 WARN, 2 ERROR, 3 STALE.
        pub level: u8,
        /// Component name.
        pub name: String,
        /// Summary.
        pub message: String,
        /// Hardware id.
        pub hardware_id: String,
        /// Details.
        pub values: Vec<KeyValue>,
    }
    impl DiagnosticStatus {
        /// Level OK.
        pub const OK: u8 = 0;
        /// Level WARN.
        pub const WARN: u8 = 1;
        /// Level ERROR.
        pub const ERROR: u8 = 2;
        /// Level STALE.
        pub const STALE: u8 = 3;
    }
    /// `diagnostic_msgs/DiagnosticArray`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct DiagnosticArray {
        /// Header.
        pub header: std_msgs::Header,
        /// One status per component.
        pub status: Vec<DiagnosticStatus>,
    }
    ros_type!(DiagnosticArray, "diagnostic_msgs", "DiagnosticArray");
}

/// `std_srvs`.
pub mod std_srvs {
    use super::*;
    /// `std_srvs/Trigger` request: empty, which ROS 2 encodes as one placeholder byte.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct TriggerRequest {
        /// The placeholder ROS 2 adds to empty structures.
        pub structure_needs_at_least_one_member: u8,
    }
    /// `std_srvs/Trigger` response.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct TriggerResponse {
        /// Whether it worked.
        pub success: bool,
        /// Why not, or what happened.
        pub message: String,
    }
}

/// The project's own types (`msg/`, `srv/`).
pub mod bevt {
    use super::*;
    /// `bevt_msgs/TrackStatus` (see `msg/TrackStatus.msg` for the meaning of each field).
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct TrackStatus {
        /// Header of the image.
        pub header: std_msgs::Header,
        /// One of the `STATE_*` constants.
        pub state: u8,
        /// Why the state is what it is.
        pub reason: String,
        /// Box left, pixels.
        pub x: f32,
        /// Box top, pixels.
        pub y: f32,
        /// Box width, pixels.
        pub width: f32,
        /// Box height, pixels.
        pub height: f32,
        /// Consensus score.
        pub consensus: f32,
        /// Confidence that the box is on the target, `[0, 1]`.
        pub confidence: f32,
        /// Learned from this frame.
        pub learned: bool,
        /// Response peak.
        pub peak: f32,
        /// Scale relative to the initial box.
        pub scale: f32,
        /// Image stamp to publication, ms.
        pub latency_ms: f32,
        /// Frames processed.
        pub frames_processed: u32,
        /// Frames dropped.
        pub frames_dropped: u32,
        /// Track id.
        pub track_id: u32,
    }
    impl TrackStatus {
        /// No target.
        pub const STATE_IDLE: u8 = 0;
        /// Tracking; the frame was learned.
        pub const STATE_TRACKING: u8 = 1;
        /// Tracking; the learning gate did not learn the frame (by default on the
        /// confidence's drop against its recent level, not on the consensus score).
        pub const STATE_LOW_CONSENSUS: u8 = 2;
        /// Target lost (or track dropped).
        pub const STATE_LOST: u8 = 3;
        /// Last input unusable.
        pub const STATE_ERROR: u8 = 4;
        /// Tracking with low confidence.
        pub const STATE_UNCERTAIN: u8 = 5;
        /// The lost target was found again on this frame.
        pub const STATE_REACQUIRED: u8 = 6;
    }
    ros_type!(TrackStatus, "bevt_msgs", "TrackStatus");

    /// `bevt_msgs/Reinit` request.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct ReinitRequest {
        /// Box left, pixels.
        pub x: f64,
        /// Box top, pixels.
        pub y: f64,
        /// Box width, pixels.
        pub width: f64,
        /// Box height, pixels.
        pub height: f64,
        /// Stamp of the frame the box was drawn on (zero = the newest frame).
        pub stamp: builtin_interfaces::Time,
        /// Optional camera frame id.
        pub frame_id: String,
    }
    /// `bevt_msgs/Reinit` response.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct ReinitResponse {
        /// Whether tracking (re)started.
        pub success: bool,
        /// Why not, or on which frame it started.
        pub message: String,
    }
}

#[cfg(feature = "ros2")]
mod ros2_impls {
    use super::*;
    impl ros2_client::Message for bevt::ReinitRequest {}
    impl ros2_client::Message for bevt::ReinitResponse {}
    impl ros2_client::Message for std_srvs::TriggerRequest {}
    impl ros2_client::Message for std_srvs::TriggerResponse {}
}
