//! Shared by the integration tests of `bevt_node`: a recording written as a camera's
//! rosbag2 MCAP would be (ros2 profile, CDR little-endian, one topic).

use serde::Serialize;
use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::Path;

/// A bare MCAP file being written: one channel, messages in order.
pub struct Recording {
    writer: mcap::Writer<BufWriter<std::fs::File>>,
    channel: u16,
    sequence: u32,
}

impl Recording {
    /// A new file at `path` with `topic` of ROS type `ty` (e.g. `sensor_msgs/msg/Image`).
    pub fn create(path: &Path, topic: &str, ty: &str) -> Self {
        let mut writer = mcap::WriteOptions::new()
            .profile("ros2")
            .create(BufWriter::new(std::fs::File::create(path).unwrap()))
            .unwrap();
        let schema = writer.add_schema(ty, "ros2msg", b"").unwrap();
        let channel = writer
            .add_channel(schema, topic, "cdr", &BTreeMap::new())
            .unwrap();
        Self {
            writer,
            channel,
            sequence: 0,
        }
    }

    /// Appends `msg` (CDR with its encapsulation header), logged at `stamp_ns`.
    pub fn write<T: Serialize>(&mut self, stamp_ns: i64, msg: &T) {
        let mut data = vec![0, 1, 0, 0];
        data.extend(cdr_encoding::to_vec::<_, byteorder::LittleEndian>(msg).unwrap());
        let h = mcap::records::MessageHeader {
            channel_id: self.channel,
            sequence: self.sequence,
            log_time: stamp_ns as u64,
            publish_time: stamp_ns as u64,
        };
        self.sequence += 1;
        self.writer.write_to_known_channel(&h, &data).unwrap();
    }

    /// Writes the summary and footer.
    pub fn finish(mut self) {
        self.writer.finish().unwrap();
    }
}
