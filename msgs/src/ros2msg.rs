//! `ros2msg` schema texts of the types `bevt replay` writes to MCAP: the message's own
//! definition followed by every type it uses, each after a line of 80 `=` and `MSG: pkg/Type`
//! (the format of rosbag2's MCAP storage, which Foxglove and `mcap-ros2-support` read).

macro_rules! sep {
    ($name:literal) => {
        concat!(
            "================================================================================\nMSG: ",
            $name,
            "\n"
        )
    };
}

macro_rules! def {
    (Time) => { concat!(sep!("builtin_interfaces/Time"), "int32 sec\nuint32 nanosec\n") };
    (Header) => {
        concat!(sep!("std_msgs/Header"), "builtin_interfaces/Time stamp\nstring frame_id\n")
    };
    (Point2D) => { concat!(sep!("vision_msgs/Point2D"), "float64 x\nfloat64 y\n") };
    (Pose2D) => {
        concat!(sep!("vision_msgs/Pose2D"), "vision_msgs/Point2D position\nfloat64 theta\n")
    };
    (BoundingBox2D) => {
        concat!(
            sep!("vision_msgs/BoundingBox2D"),
            "vision_msgs/Pose2D center\nfloat64 size_x\nfloat64 size_y\n"
        )
    };
    (ObjectHypothesis) => {
        concat!(sep!("vision_msgs/ObjectHypothesis"), "string class_id\nfloat64 score\n")
    };
    (ObjectHypothesisWithPose) => {
        concat!(
            sep!("vision_msgs/ObjectHypothesisWithPose"),
            "vision_msgs/ObjectHypothesis hypothesis\ngeometry_msgs/PoseWithCovariance pose\n"
        )
    };
    (Detection2D) => {
        concat!(
            sep!("vision_msgs/Detection2D"),
            "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\n",
            "vision_msgs/BoundingBox2D bbox\nstring id\n"
        )
    };
    (PoseWithCovariance) => {
        concat!(
            sep!("geometry_msgs/PoseWithCovariance"),
            "geometry_msgs/Pose pose\nfloat64[36] covariance\n"
        )
    };
    (Pose) => {
        concat!(
            sep!("geometry_msgs/Pose"),
            "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n"
        )
    };
    (Point) => { concat!(sep!("geometry_msgs/Point"), "float64 x\nfloat64 y\nfloat64 z\n") };
    (Quaternion) => {
        concat!(
            sep!("geometry_msgs/Quaternion"),
            "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
        )
    };
    (Point2) => { concat!(sep!("foxglove_msgs/Point2"), "float64 x\nfloat64 y\n") };
    (Color) => {
        concat!(sep!("foxglove_msgs/Color"), "float64 r\nfloat64 g\nfloat64 b\nfloat64 a\n")
    };
    (CircleAnnotation) => {
        concat!(
            sep!("foxglove_msgs/CircleAnnotation"),
            "builtin_interfaces/Time timestamp\nfoxglove_msgs/Point2 position\n",
            "float64 diameter\nfloat64 thickness\nfoxglove_msgs/Color fill_color\n",
            "foxglove_msgs/Color outline_color\n"
        )
    };
    (PointsAnnotation) => {
        concat!(
            sep!("foxglove_msgs/PointsAnnotation"),
            "builtin_interfaces/Time timestamp\n",
            "uint8 UNKNOWN=0\nuint8 POINTS=1\nuint8 LINE_LOOP=2\nuint8 LINE_STRIP=3\nuint8 LINE_LIST=4\n",
            "uint8 type\nfoxglove_msgs/Point2[] points\nfoxglove_msgs/Color outline_color\n",
            "foxglove_msgs/Color[] outline_colors\nfoxglove_msgs/Color fill_color\n",
            "float64 thickness\n"
        )
    };
    (TextAnnotation) => {
        concat!(
            sep!("foxglove_msgs/TextAnnotation"),
            "builtin_interfaces/Time timestamp\nfoxglove_msgs/Point2 position\nstring text\n",
            "float64 font_size\nfoxglove_msgs/Color text_color\n",
            "foxglove_msgs/Color background_color\n"
        )
    };
}

/// `sensor_msgs/msg/Image`.
pub const IMAGE: &str = concat!(
    "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n",
    "uint8 is_bigendian\nuint32 step\nuint8[] data\n",
    def!(Header),
    def!(Time)
);

/// `sensor_msgs/msg/CompressedImage`.
pub const COMPRESSED_IMAGE: &str = concat!(
    "std_msgs/Header header\nstring format\nuint8[] data\n",
    def!(Header),
    def!(Time)
);

/// `vision_msgs/msg/Detection2DArray` (vision_msgs 4.x, ROS 2 Humble and later).
pub const DETECTION2D_ARRAY: &str = concat!(
    "std_msgs/Header header\nvision_msgs/Detection2D[] detections\n",
    def!(Header),
    def!(Time),
    def!(Detection2D),
    def!(ObjectHypothesisWithPose),
    def!(ObjectHypothesis),
    def!(PoseWithCovariance),
    def!(Pose),
    def!(Point),
    def!(Quaternion),
    def!(BoundingBox2D),
    def!(Pose2D),
    def!(Point2D)
);

/// `bevt_msgs/msg/TrackStatus` (`msg/TrackStatus.msg`).
pub const TRACK_STATUS: &str = concat!(
    include_str!("../msg/TrackStatus.msg"),
    def!(Header),
    def!(Time)
);

/// `foxglove_msgs/msg/ImageAnnotations`, in the layout of the `foxglove_msgs` package of the
/// ROS 2 distributions (without the `metadata` fields later Foxglove SDKs added).
pub const IMAGE_ANNOTATIONS: &str = concat!(
    "foxglove_msgs/CircleAnnotation[] circles\nfoxglove_msgs/PointsAnnotation[] points\n",
    "foxglove_msgs/TextAnnotation[] texts\n",
    def!(CircleAnnotation),
    def!(PointsAnnotation),
    def!(TextAnnotation),
    def!(Time),
    def!(Point2),
    def!(Color)
);
