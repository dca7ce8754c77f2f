//! Fuzz target bodies (issue 11), shared by the libFuzzer targets of `fuzz/` (cargo-fuzz,
//! nightly) and the bounded stable harness of the integration tests
//! (`integration/fuzz.rs`), which also replays every saved crash input in
//! `fuzz/regressions/<target>/`.
//!
//! Each body takes arbitrary bytes, builds the input of one parser from them and runs it:
//! any panic (or abort, or runaway allocation under the fuzzer's limits) is a finding.
//! Errors are the expected outcome for most inputs; where a parser accepts its input the
//! body checks what it returned against what was declared.

use bevt_core::TrackerConfig;
use bevt_msgs::bevt::ReinitRequest;
use bevt_msgs::builtin_interfaces::Time;
use bevt_msgs::sensor_msgs::{CompressedImage, Image};
use bevt_msgs::std_msgs::Header;
use bevt_msgs::std_srvs::TriggerRequest;
use bevt_msgs::vision_msgs::Detection2D;
use bevt_node::convert::{frame_from_compressed, frame_from_image, ImageLimits, PixelBuffer};
use bevt_node::node::app::{CameraMsg, NodeCore, NodeSettings};
use ros2_client::dds::rustdds::serialization::deserialize_from_cdr_with_rep_id;
use ros2_client::dds::rustdds::RepresentationIdentifier;
use std::path::PathBuf;
use std::time::Instant;

/// A fuzz target: its name (the folder of its corpus and regressions) and body.
pub struct Target {
    /// Name, as in `cargo fuzz run NAME`.
    pub name: &'static str,
    /// The body.
    pub run: fn(&[u8]),
    /// Seed inputs (valid or nearly valid examples).
    pub seeds: fn() -> Vec<Vec<u8>>,
}

/// Every target.
pub const TARGETS: &[Target] = &[
    Target {
        name: "image_raw",
        run: image_raw,
        seeds: seeds_image_raw,
    },
    Target {
        name: "image_compressed",
        run: image_compressed,
        seeds: seeds_image_compressed,
    },
    Target {
        name: "cdr_messages",
        run: cdr_messages,
        seeds: seeds_cdr,
    },
    Target {
        name: "node_requests",
        run: node_requests,
        seeds: seeds_node_requests,
    },
    Target {
        name: "param_requests",
        run: param_requests,
        seeds: seeds_param_requests,
    },
    Target {
        name: "ros_args",
        run: ros_args,
        seeds: seeds_ros_args,
    },
    Target {
        name: "params_file",
        run: params_file,
        seeds: seeds_params_file,
    },
    Target {
        name: "tracker_config",
        run: tracker_config,
        seeds: seeds_tracker_config,
    },
    Target {
        name: "dataset_manifest",
        run: dataset_manifest,
        seeds: seeds_dataset_manifest,
    },
    Target {
        name: "annotation",
        run: annotation,
        seeds: seeds_annotation,
    },
    Target {
        name: "bag_reader",
        run: bag_reader,
        seeds: seeds_bag_reader,
    },
];

/// Small limits for the fuzz bodies: inputs stay fast to convert (the default limits are
/// checked by the `huge` branches, which never decode).
fn small_limits() -> ImageLimits {
    ImageLimits {
        max_width: 512,
        max_height: 512,
        max_pixels: 1 << 18,
    }
}

/// Reads structured values off the front of fuzz input; past the end everything is zero.
struct Bytes<'a>(&'a [u8]);

impl<'a> Bytes<'a> {
    fn u8(&mut self) -> u8 {
        match self.0.split_first() {
            Some((b, rest)) => {
                self.0 = rest;
                *b
            }
            None => 0,
        }
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes([self.u8(), self.u8(), self.u8(), self.u8()])
    }
    fn f64(&mut self) -> f64 {
        let mut b = [0u8; 8];
        for x in &mut b {
            *x = self.u8();
        }
        f64::from_le_bytes(b)
    }
    /// Up to `max` bytes.
    fn take(&mut self, max: usize) -> &'a [u8] {
        let n = max.min(self.0.len());
        let (a, b) = self.0.split_at(n);
        self.0 = b;
        a
    }
    /// A string of length given by the next byte (lossy UTF-8).
    fn string(&mut self) -> String {
        let n = self.u8() as usize;
        String::from_utf8_lossy(self.take(n)).into_owned()
    }
    fn rest(&mut self) -> &'a [u8] {
        self.take(usize::MAX)
    }
}

const ENCODINGS: [&str; 12] = [
    "rgb8",
    "bgr8",
    "rgba8",
    "bgra8",
    "mono8",
    "8UC1",
    "yuv422",
    "yuv422_yuy2",
    "uyvy",
    "yuyv",
    "RGB8",
    "mono16",
];

fn header() -> Header {
    Header {
        stamp: Time { sec: 1, nanosec: 0 },
        frame_id: "fuzz".into(),
    }
}

/// Converts `m` with the small limits; an accepted frame must have the declared size.
fn check_image(m: &Image) {
    let mut buf = PixelBuffer::default();
    if let Ok(f) = frame_from_image(m, &mut buf, &small_limits()) {
        assert_eq!(
            (f.width(), f.height()),
            (m.width as usize, m.height as usize)
        );
    }
}

/// Converts `m` with the small limits; an accepted frame is within them.
fn check_compressed(m: &CompressedImage) {
    let mut buf = PixelBuffer::default();
    let l = small_limits();
    if let Ok(f) = frame_from_compressed(m, &mut buf, &l) {
        assert!(f.width() <= l.max_width as usize && f.height() <= l.max_height as usize);
        assert!((f.width() * f.height()) as u64 <= l.max_pixels);
    }
}

/// `sensor_msgs/Image` conversion: encoding, sizes, step, data (optionally fitted to
/// step × height so the converters themselves are reached).
pub fn image_raw(data: &[u8]) {
    let mut b = Bytes(data);
    let sel = b.u8();
    let encoding = match ENCODINGS.get(sel as usize) {
        Some(e) => (*e).to_string(),
        None => b.string(),
    };
    let flags = b.u8();
    let (width, height) = if flags & 1 == 0 {
        (u32::from(b.u8()), u32::from(b.u8()))
    } else {
        (b.u32(), b.u32())
    };
    let bpp = match encoding.as_str() {
        "mono8" | "8UC1" => 1,
        "rgba8" | "bgra8" => 4,
        "yuv422" | "yuv422_yuy2" | "uyvy" | "yuyv" | "mono16" => 2,
        _ => 3,
    };
    let step = if flags & 2 == 0 {
        width.wrapping_mul(bpp).wrapping_add(u32::from(b.u8() % 8))
    } else {
        b.u32()
    };
    let mut pixels = b.rest().to_vec();
    let want = step as u64 * height as u64;
    if flags & 4 != 0 && want <= 1 << 20 {
        pixels.resize(want as usize, 0x80);
    }
    let m = Image {
        header: header(),
        height,
        width,
        encoding,
        is_bigendian: flags >> 7,
        step,
        data: pixels,
    };
    check_image(&m);
    // The default limits refuse or accept the declared size without decoding anything.
    let _ = ImageLimits::default().check(width, height);
}

const FORMATS: [&str; 6] = [
    "jpeg",
    "png",
    "jpg",
    "rgb8; jpeg compressed bgr8",
    "bgr8; png compressed ",
    "",
];

/// `sensor_msgs/CompressedImage` decoding: format and bytes.
pub fn image_compressed(data: &[u8]) {
    let mut b = Bytes(data);
    let sel = b.u8();
    let format = match FORMATS.get(sel as usize) {
        Some(f) => (*f).to_string(),
        None => b.string(),
    };
    check_compressed(&CompressedImage {
        header: header(),
        format,
        data: b.rest().to_vec(),
    });
}

/// CDR decoding of every message the node reads (`image_raw`, `image_raw/compressed`,
/// `init`, the `reinit` and `stop` requests): the first 4 bytes are the encapsulation
/// header (as in a DDS serialized payload), the rest the CDR body. Decoded images go on
/// to conversion.
pub fn cdr_messages(data: &[u8]) {
    if data.len() < 4 {
        return;
    }
    let Ok(rep) = RepresentationIdentifier::from_bytes(&data[..2]) else {
        return;
    };
    let body = &data[4..];
    if let Ok((m, n)) = deserialize_from_cdr_with_rep_id::<Image>(body, rep) {
        assert!(n <= body.len());
        check_image(&m);
    }
    if let Ok((m, n)) = deserialize_from_cdr_with_rep_id::<CompressedImage>(body, rep) {
        assert!(n <= body.len());
        check_compressed(&m);
    }
    if let Ok((d, _)) = deserialize_from_cdr_with_rep_id::<Detection2D>(body, rep) {
        let b = bevt_node::convert::bbox_from_detection(&d);
        let _ = bevt_node::convert::reinit_request(b, d.header.stamp, &d.header.frame_id);
    }
    let _ = deserialize_from_cdr_with_rep_id::<ReinitRequest>(body, rep);
    let _ = deserialize_from_cdr_with_rep_id::<TriggerRequest>(body, rep);
}

/// The node logic under a sequence of requests: small camera frames, `reinit` requests
/// (arbitrary boxes and stamps), `init` detections, `stop`, ticks. A request with a
/// non-finite or empty box must be refused.
pub fn node_requests(data: &[u8]) {
    let Ok(spec) = TrackerConfig::default().validate() else {
        return;
    };
    let settings = NodeSettings {
        reinit_buffer_frames: 4,
        reinit_buffer_bytes: 1 << 20,
        reinit_rate_hz: 1000.0,
        reinit_burst: 1000,
        image_limits: small_limits(),
        ..NodeSettings::default()
    };
    let mut core = NodeCore::new(spec, settings);
    let mut b = Bytes(data);
    let mut stamp = 1i32;
    // A bounded number of operations keeps one input fast.
    for _ in 0..12 {
        if b.0.is_empty() {
            break;
        }
        match b.u8() % 5 {
            0 => {
                let (w, h) = (16 + u32::from(b.u8() % 112), 16 + u32::from(b.u8() % 112));
                let shade = b.u8();
                let data: Vec<u8> = (0..w * h * 3)
                    .map(|i| shade.wrapping_add((i % 251) as u8))
                    .collect();
                stamp += 1;
                let m = Image {
                    header: Header {
                        stamp: Time {
                            sec: stamp,
                            nanosec: 0,
                        },
                        frame_id: "fuzz".into(),
                    },
                    height: h,
                    width: w,
                    encoding: "rgb8".into(),
                    is_bigendian: 0,
                    step: w * 3,
                    data,
                };
                let _ = core.on_image(CameraMsg::Raw(&m), Instant::now());
            }
            1 | 2 => {
                let req = ReinitRequest {
                    x: b.f64(),
                    y: b.f64(),
                    width: b.f64(),
                    height: b.f64(),
                    stamp: Time {
                        sec: i32::from(b.u8() as i8) + stamp,
                        nanosec: b.u32(),
                    },
                    frame_id: b.string(),
                };
                let bad = !(req.x.is_finite()
                    && req.y.is_finite()
                    && req.width.is_finite()
                    && req.height.is_finite())
                    || req.width <= 0.0
                    || req.height <= 0.0;
                if core.admit_reinit(Instant::now()).is_ok() {
                    let (resp, _) = core.on_reinit(&req);
                    assert!(
                        !(bad && resp.success),
                        "a bad box was accepted: {req:?} -> {resp:?}"
                    );
                }
            }
            3 => {
                let _ = core.on_stop();
            }
            _ => {
                let _ = core.on_tick(Instant::now());
                let _ = core.diagnostics();
                let _ = core.debug_image();
            }
        }
    }
}

/// The parameter services' requests (`list`, `get`, `get_types`, `describe`, `set`):
/// CDR-decoded as in [`cdr_messages`], then answered by the node's parameter table; a
/// set is checked and, when accepted, committed.
pub fn param_requests(data: &[u8]) {
    use bevt_node::node::param_services::NodeParams;
    use ros2_client::rcl_interfaces::{
        DescribeParametersRequest, GetParameterTypesRequest, GetParametersRequest,
        ListParametersRequest, SetParametersRequest,
    };
    if data.len() < 4 {
        return;
    }
    let Ok(rep) = RepresentationIdentifier::from_bytes(&data[..2]) else {
        return;
    };
    let body = &data[4..];
    let mut params = NodeParams::new(
        &bevt_node::node::ros::RosSettings::default(),
        &NodeSettings::default(),
        &TrackerConfig::default(),
    );
    if let Ok((r, _)) = deserialize_from_cdr_with_rep_id::<ListParametersRequest>(body, rep) {
        let _ = params.list(&r.prefixes, r.depth);
    }
    if let Ok((r, _)) = deserialize_from_cdr_with_rep_id::<GetParametersRequest>(body, rep) {
        assert_eq!(params.get(&r.names).len(), r.names.len());
    }
    if let Ok((r, _)) = deserialize_from_cdr_with_rep_id::<GetParameterTypesRequest>(body, rep) {
        assert_eq!(params.types(&r.names).len(), r.names.len());
    }
    if let Ok((r, _)) = deserialize_from_cdr_with_rep_id::<DescribeParametersRequest>(body, rep) {
        let _ = params.describe(&r.names);
    }
    if let Ok((r, _)) = deserialize_from_cdr_with_rep_id::<SetParametersRequest>(body, rep) {
        for p in &r.parameter {
            if let Ok((v, change)) = params.check(&p.name, &p.value) {
                params.commit(&p.name, v, &change);
            }
        }
    }
}

fn seeds_param_requests() -> Vec<Vec<u8>> {
    use ros2_client::parameters::raw;
    use ros2_client::rcl_interfaces::{ListParametersRequest, SetParametersRequest};
    let set = |name: &str, v: ros2_client::ParameterValue| raw::Parameter {
        name: name.into(),
        value: v.into(),
    };
    vec![
        cdr(&ListParametersRequest {
            prefixes: vec!["tracker".into()],
            depth: 0,
        }),
        cdr(&vec![
            "reinit_rate_hz".to_string(),
            "tracker.track_state.lost_threshold".into(),
        ]),
        cdr(&SetParametersRequest {
            parameter: vec![
                set("reinit_rate_hz", ros2_client::ParameterValue::Double(2.0)),
                set("reinit_burst", ros2_client::ParameterValue::Integer(5)),
                set(
                    "class_id",
                    ros2_client::ParameterValue::String("car".into()),
                ),
                set(
                    "tracker.track_state.lost_threshold",
                    ros2_client::ParameterValue::Double(0.1),
                ),
                set("domain_id", ros2_client::ParameterValue::Integer(9)),
            ],
        }),
    ]
}

/// A folder private to this process and `what`, created on first use.
fn scratch(what: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("bevt_fuzz_{}_{what}", std::process::id()));
    let _ = std::fs::create_dir_all(&d);
    d
}

/// Splits `data` into lines (lossy UTF-8).
fn lines(data: &[u8]) -> Vec<String> {
    String::from_utf8_lossy(data)
        .split('\n')
        .map(str::to_string)
        .collect()
}

/// `bevt_node` command-line arguments (one per line; `--params-file` values are replaced
/// by a fixed empty file, since they name files to read) and the ROS environment
/// variables (the first line, `NAME=value` separated by `;`).
pub fn ros_args(data: &[u8]) {
    let mut all = lines(data);
    if all.is_empty() {
        return;
    }
    let env_line = all.remove(0);
    let empty = scratch("ros_args").join("empty.yaml");
    let _ = std::fs::write(&empty, "");
    let mut args = Vec::with_capacity(all.len());
    let mut it = all.into_iter();
    while let Some(a) = it.next() {
        let is_file = a == "--params-file";
        args.push(a);
        if is_file {
            let _ = it.next();
            args.push(empty.display().to_string());
        }
    }
    let env: Vec<(String, String)> = env_line
        .split(';')
        .filter_map(|kv| kv.split_once('='))
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    let _ = bevt_node::node::node_params::launch_from_args(&args, |k| {
        env.iter().find(|(n, _)| n == k).map(|(_, v)| v.clone())
    });
}

/// A ROS 2 parameters file (`--params-file`), read as `bevt_node` reads it. Parameters
/// naming files (a tracker config) are not followed outside the scratch folder: the
/// input is refused if it mentions `/` paths other than node names.
pub fn params_file(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    let _ = bevt_node::node::node_params::params_from_file(&text, "bevt_node");
    // Through the launch path too, unless it could name a file to read.
    if text.contains("config") || text.contains("file") || text.contains("path") {
        return;
    }
    let path = scratch("params_file").join("params.yaml");
    if std::fs::write(&path, data).is_ok() {
        let args = [
            "--ros-args".to_string(),
            "--params-file".to_string(),
            path.display().to_string(),
        ];
        let _ = bevt_node::node::node_params::launch_from_args(&args, |_| None);
    }
}

/// The YAML tracker configuration with `key.path=value` overrides: the text up to the
/// first NUL byte is the file, the lines after it the overrides. Accepted configurations
/// must validate (they came through `validate`).
pub fn tracker_config(data: &[u8]) {
    let (text, rest) = match data.iter().position(|&c| c == 0) {
        Some(i) => (&data[..i], &data[i + 1..]),
        None => (data, &[][..]),
    };
    let overrides: Vec<String> = if rest.is_empty() {
        Vec::new()
    } else {
        lines(rest)
    };
    let path = scratch("tracker_config").join("tracker.yaml");
    if std::fs::write(&path, text).is_ok() {
        let _ = bevt_node::params::load_config(Some(&path), &overrides);
    }
}

/// A dataset folder with a `sequences.json` manifest (the input up to the first NUL) and
/// one annotation file `anno.txt` (the rest); every sequence whose annotation is that
/// file is loaded.
pub fn dataset_manifest(data: &[u8]) {
    let (manifest, anno) = match data.iter().position(|&c| c == 0) {
        Some(i) => (&data[..i], &data[i + 1..]),
        None => (data, &[][..]),
    };
    let root = scratch("dataset_manifest");
    if std::fs::write(root.join("sequences.json"), manifest).is_err()
        || std::fs::write(root.join("anno.txt"), anno).is_err()
    {
        return;
    }
    let Ok(ds) = bevt_node::tool::dataset::open_dataset(&root) else {
        return;
    };
    let anno_path = root.join("anno.txt");
    for s in &ds.sequences {
        assert!(bevt_node::tool::dataset::check_sequence_name(&s.name).is_ok());
        if s.anno == anno_path {
            if let Ok(seq) = s.load() {
                assert_eq!(seq.frames.len(), seq.truth.len());
            }
        }
    }
}

/// An annotation file (`x,y,w,h` rows; NaN rows for absent targets).
pub fn annotation(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    if let Ok(rows) =
        bevt_node::tool::dataset::parse_annotation(&text, std::path::Path::new("a.txt"))
    {
        for b in rows.iter().flatten() {
            let row = bevt_node::tool::dataset::format_annotation_row(Some(b));
            assert!(!row.is_empty());
        }
    }
}

fn seeds_image_raw() -> Vec<Vec<u8>> {
    // sel, flags (bit 2: fit the data), w, h, step delta, data.
    (0..ENCODINGS.len() as u8)
        .map(|e| {
            let mut s = vec![e, 4, 8, 6, 0];
            s.extend((0..64u8).map(|i| i.wrapping_mul(37)));
            s
        })
        .collect()
}

fn encoded(kind: image::ImageFormat) -> Vec<u8> {
    let (w, h) = (24u32, 16u32);
    let rgb: Vec<u8> = (0..w * h * 3).map(|i| (i * 7 % 256) as u8).collect();
    let mut out = std::io::Cursor::new(Vec::new());
    let img = image::RgbImage::from_raw(w, h, rgb);
    if let Some(img) = img {
        let _ = img.write_to(&mut out, kind);
    }
    out.into_inner()
}

fn seeds_image_compressed() -> Vec<Vec<u8>> {
    let mut j = vec![0u8];
    j.extend(encoded(image::ImageFormat::Jpeg));
    let mut p = vec![1u8];
    p.extend(encoded(image::ImageFormat::Png));
    vec![j, p]
}

/// `value` as a DDS serialized payload (CDR little-endian with its header).
fn cdr<T: serde::Serialize>(value: &T) -> Vec<u8> {
    let mut out = vec![0, 1, 0, 0];
    let _ = ros2_client::dds::rustdds::serialization::to_writer_with_rep_id(
        &mut out,
        value,
        RepresentationIdentifier::CDR_LE,
    );
    out
}

fn seeds_cdr() -> Vec<Vec<u8>> {
    let img = Image {
        header: header(),
        height: 4,
        width: 4,
        encoding: "rgb8".into(),
        is_bigendian: 0,
        step: 12,
        data: vec![7; 48],
    };
    let cmp = CompressedImage {
        header: header(),
        format: "png".into(),
        data: encoded(image::ImageFormat::Png),
    };
    let req = ReinitRequest {
        x: 1.0,
        y: 2.0,
        width: 10.0,
        height: 12.0,
        stamp: Time { sec: 1, nanosec: 5 },
        frame_id: "cam".into(),
    };
    vec![
        cdr(&img),
        cdr(&cmp),
        cdr(&Detection2D::default()),
        cdr(&req),
        cdr(&TriggerRequest::default()),
    ]
}

fn seeds_node_requests() -> Vec<Vec<u8>> {
    let mut s = vec![0u8, 40, 40, 9, 0, 40, 40, 10, 1];
    for v in [8.0f64, 8.0, 12.0, 12.0] {
        s.extend(v.to_le_bytes());
    }
    s.extend([0, 0, 0, 0, 0, 0, 0, 40, 40, 11, 4, 3]);
    vec![s]
}

fn seeds_ros_args() -> Vec<Vec<u8>> {
    vec![
        b"ROS_DOMAIN_ID=7;ROS_LOCALHOST_ONLY=1\n--ros-args\n-p\ndomain_id:=3\n-r\n__ns:=/drone\n-p\nnetwork_interfaces:=[127.0.0.1]\n-p\nmax_image_width:=640".to_vec(),
        b"\n--demo\n--duration\n2.5".to_vec(),
        b"\n--ros-args\n--params-file\nx\n-r\nimage_raw:=/cam/image\n--log-level\ninfo\n--enclave\n/e".to_vec(),
    ]
}

fn seeds_params_file() -> Vec<Vec<u8>> {
    vec![
        b"bevt_node:\n  ros__parameters:\n    domain_id: 4\n    reinit_rate_hz: 2.0\n    max_image_width: 1920\n    admm:\n      penalty: none\n".to_vec(),
        b"/**:\n  ros__parameters:\n    network_interfaces: [\"127.0.0.1\"]\n    service_mapping: cyclone\n".to_vec(),
    ]
}

fn seeds_tracker_config() -> Vec<Vec<u8>> {
    vec![
        bevt_node::params::DEFAULT_CONFIG_YAML.as_bytes().to_vec(),
        b"admm:\n  penalty: none\n\0admm.iterations=3\nfeatures.kind=hog".to_vec(),
    ]
}

fn seeds_dataset_manifest() -> Vec<Vec<u8>> {
    vec![
        b"{\"sequences\":[{\"name\":\"s1\",\"img_dir\":\"img\",\"anno\":\"anno.txt\",\"start_frame\":1,\"end_frame\":3,\"nz\":6,\"ext\":\"jpg\",\"attributes\":{\"SV\":true}}],\"attribute_order\":[\"SV\"]}\x001,2,3,4\n5,6,7,8\nNaN,NaN,NaN,NaN\n".to_vec(),
    ]
}

fn seeds_annotation() -> Vec<Vec<u8>> {
    vec![
        b"1,2,3,4\n5,6,7,8\nNaN,NaN,NaN,NaN\n".to_vec(),
        b"1\t2\t3\t4\r\n0 0 0 0\n".to_vec(),
    ]
}

/// The topic the `bag_reader` seeds record and the body reads.
const BAG_TOPIC: &str = "/camera/image_raw";

/// The `bevt replay` reading path on an MCAP stream: records, chunks (uncompressed, zstd,
/// lz4; their declared sizes are untrusted), messages of the topic decoded into frames as
/// replay does. The reader runs with its real limit (1 GiB records): an allocation from a
/// declared length would show as memory (`scripts/fuzz.sh` gives this target a 512 MB RSS
/// limit). Errors are fine; a panic, a hang or memory is the finding.
pub fn bag_reader(data: &[u8]) {
    use bevt_node::tool::bag::{read_mcap_bytes, BagLimits};
    let limits = small_limits();
    let mut buf = PixelBuffer::default();
    let mut handed = 0u64;
    let r = read_mcap_bytes(data, BAG_TOPIC, BagLimits::default(), |m| {
        handed += 1;
        assert!(
            m.data.len() <= data.len() * 64 + (1 << 20),
            "a message larger than its input could make"
        );
        if let Ok((w, h)) = bevt_node::tool::replay::decode_message(&m, &mut buf, &limits) {
            assert!(
                w >= 1
                    && h >= 1
                    && w <= limits.max_width as usize
                    && h <= limits.max_height as usize
            );
        }
        std::ops::ControlFlow::Continue(())
    });
    match r {
        Ok(n) => assert_eq!(n, handed, "count of messages handed out"),
        Err(e) => assert!(!e.to_string().is_empty()),
    }
}

/// A small MCAP recording of `BAG_TOPIC` (two 8×8 rgb8 frames and a PNG one on another
/// topic) with `compression`, chunked or not.
fn mcap_seed(compression: Option<mcap::Compression>, chunked: bool) -> Vec<u8> {
    let mut out = std::io::Cursor::new(Vec::new());
    let write = |out: &mut std::io::Cursor<Vec<u8>>| -> mcap::McapResult<()> {
        let mut w = mcap::WriteOptions::new()
            .compression(compression)
            .use_chunks(chunked)
            .chunk_size(Some(512))
            .create(out)?;
        let meta = std::collections::BTreeMap::new();
        let s = w.add_schema("sensor_msgs/msg/Image", "ros2msg", b"")?;
        let c = w.add_channel(s, BAG_TOPIC, "cdr", &meta)?;
        let s2 = w.add_schema("sensor_msgs/msg/CompressedImage", "ros2msg", b"")?;
        let c2 = w.add_channel(s2, "/camera/image_raw/compressed", "cdr", &meta)?;
        for i in 0..2u8 {
            let img = Image {
                header: header(),
                height: 8,
                width: 8,
                encoding: "rgb8".into(),
                is_bigendian: 0,
                step: 24,
                data: vec![40 * i; 192],
            };
            let h = mcap::records::MessageHeader {
                channel_id: c,
                sequence: u32::from(i),
                log_time: 1_000 + u64::from(i),
                publish_time: 1_000 + u64::from(i),
            };
            w.write_to_known_channel(&h, &cdr(&img))?;
        }
        let png = CompressedImage {
            header: header(),
            format: "png".into(),
            data: encoded(image::ImageFormat::Png),
        };
        let h = mcap::records::MessageHeader {
            channel_id: c2,
            sequence: 0,
            log_time: 2_000,
            publish_time: 2_000,
        };
        w.write_to_known_channel(&h, &cdr(&png))?;
        w.finish()?;
        Ok(())
    };
    match write(&mut out) {
        Ok(()) => out.into_inner(),
        Err(_) => Vec::new(),
    }
}

fn seeds_bag_reader() -> Vec<Vec<u8>> {
    vec![
        mcap_seed(None, false),
        mcap_seed(None, true),
        mcap_seed(Some(mcap::Compression::Zstd), true),
        mcap_seed(Some(mcap::Compression::Lz4), true),
    ]
}
