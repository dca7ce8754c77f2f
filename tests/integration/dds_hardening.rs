//! Issue 6 §1: the DDS transport under hostile traffic, over the wire. The node runs as a
//! separate process (`bevt_node_under_test`, the node's own launch path) so that its
//! memory (`/proc/<pid>/status`) and sockets (`/proc/<pid>/fd`, `/proc/net/udp`) are its
//! own. Crafted RTPS DATA_FRAG packets, written by hand here, go from a raw UDP socket to
//! every UDP port of the node on 127.0.0.1. Before the fix (patched RustDDS,
//! `vendor/rustdds/BEVT_PATCH.md`) one such packet made the node allocate the size it
//! declares (up to 4 GiB) and a few of them aborted it; its sockets were bound to 0.0.0.0.
//! Linux only (`/proc`).

use bevt_core::eval::synth::SynthParams;
use bevt_msgs::bevt::ReinitRequest;
use bevt_msgs::builtin_interfaces::Time;
use bevt_node::convert::bbox_from_detection;
use bevt_node::node::ros::RosSettings;
use bevt_node::node::sim::{spawn_camera, GroundStation, TruthLog};
use std::collections::BTreeSet;
use std::io::ErrorKind;
use std::net::{Ipv4Addr, SocketAddrV4, UdpSocket};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Address space the node may use at all (`ulimit -v`): a safety net so that a node
/// without the fix aborts after a few packets instead of taking the machine's memory.
/// Well above the bound asserted below.
const ADDRESS_SPACE_CAP_KIB: u64 = 4 * 1024 * 1024;

/// Allowed growth: 2× the steady value plus this.
const MEMORY_MARGIN_KIB: u64 = 256 * 1024;

/// Discovery and matching take about this long on loopback.
const DISCOVERY: Duration = Duration::from_millis(1500);

/// The node process; killed (and its stdin closed) when dropped.
struct NodeProcess(Child);

impl NodeProcess {
    fn spawn(domain: u16) -> Self {
        let exe = env!("CARGO_BIN_EXE_bevt_node_under_test");
        let child = Command::new("sh")
            .arg("-c")
            .arg(format!(
                "ulimit -v {ADDRESS_SPACE_CAP_KIB} && exec \"$0\" \"$@\""
            ))
            .arg(exe)
            .args([
                "--ros-args",
                "-p",
                &format!("domain_id:={domain}"),
                "-p",
                "network_interfaces:=[127.0.0.1]",
            ])
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .spawn()
            .expect("start bevt_node_under_test");
        Self(child)
    }

    fn pid(&self) -> u32 {
        self.0.id()
    }

    fn alive(&mut self) -> bool {
        matches!(self.0.try_wait(), Ok(None))
    }

    /// `VmSize`, `VmRSS`, `VmPeak`, `VmHWM` in KiB.
    fn memory(&self) -> Memory {
        let s =
            std::fs::read_to_string(format!("/proc/{}/status", self.pid())).expect("node status");
        let field = |name: &str| -> u64 {
            s.lines()
                .find_map(|l| l.strip_prefix(name))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
                .expect("a memory field of /proc/<pid>/status")
        };
        Memory {
            size: field("VmSize:"),
            rss: field("VmRSS:"),
            peak: field("VmPeak:"),
            hwm: field("VmHWM:"),
        }
    }

    /// The node's UDP sockets: (local address, port) from `/proc/net/udp{,6}` for the
    /// socket inodes among its open files.
    fn udp_sockets(&self) -> Vec<(String, u16)> {
        let mut inodes = BTreeSet::new();
        if let Ok(dir) = std::fs::read_dir(format!("/proc/{}/fd", self.pid())) {
            for e in dir.flatten() {
                if let Ok(t) = std::fs::read_link(e.path()) {
                    let t = t.to_string_lossy().into_owned();
                    if let Some(i) = t.strip_prefix("socket:[").and_then(|r| r.strip_suffix(']')) {
                        inodes.insert(i.to_string());
                    }
                }
            }
        }
        let mut out = Vec::new();
        for (table, v6) in [("/proc/net/udp", false), ("/proc/net/udp6", true)] {
            let text = std::fs::read_to_string(table).unwrap_or_default();
            for line in text.lines().skip(1) {
                let cols: Vec<&str> = line.split_whitespace().collect();
                if cols.len() < 10 || !inodes.contains(cols[9]) {
                    continue;
                }
                let (addr, port) = cols[1].split_once(':').expect("address:port");
                let port = u16::from_str_radix(port, 16).expect("port");
                let addr = if v6 {
                    format!("[{addr}]")
                } else {
                    // /proc/net/udp prints the address as a native-endian u32 in hex.
                    let raw = u32::from_str_radix(addr, 16).expect("ipv4");
                    Ipv4Addr::from(raw.to_ne_bytes()).to_string()
                };
                out.push((addr, port));
            }
        }
        out
    }

    /// Waits until the node has opened its unicast DDS sockets.
    fn wait_for_sockets(&self) -> Vec<(String, u16)> {
        let end = Instant::now() + Duration::from_secs(20);
        loop {
            let s = self.udp_sockets();
            if s.len() >= 3 {
                return s;
            }
            assert!(
                Instant::now() < end,
                "the node opened no DDS sockets: {s:?}"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for NodeProcess {
    fn drop(&mut self) {
        drop(self.0.stdin.take());
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[derive(Debug, Clone, Copy)]
struct Memory {
    size: u64,
    rss: u64,
    peak: u64,
    hwm: u64,
}

/// RTPS entity ids (entityKey, kind) as on the wire.
mod entity {
    pub const UNKNOWN: [u8; 4] = [0, 0, 0, 0];
    pub const SPDP_WRITER: [u8; 4] = [0x00, 0x01, 0x00, 0xc2];
    pub const SPDP_READER: [u8; 4] = [0x00, 0x01, 0x00, 0xc7];
    pub const SEDP_PUB_WRITER: [u8; 4] = [0x00, 0x00, 0x03, 0xc2];
    pub const SEDP_PUB_READER: [u8; 4] = [0x00, 0x00, 0x03, 0xc7];
    pub const SEDP_SUB_WRITER: [u8; 4] = [0x00, 0x00, 0x04, 0xc2];
    pub const SEDP_SUB_READER: [u8; 4] = [0x00, 0x00, 0x04, 0xc7];
    pub const P2P_WRITER: [u8; 4] = [0x00, 0x02, 0x00, 0xc2];
    pub const P2P_READER: [u8; 4] = [0x00, 0x02, 0x00, 0xc7];
    /// A made-up user writer (with key).
    pub const USER_WRITER: [u8; 4] = [0x00, 0x0b, 0xad, 0x02];
}

/// One DATA_FRAG as a sender would put it on the wire.
struct Frag {
    prefix: [u8; 12],
    reader: [u8; 4],
    writer: [u8; 4],
    sn: u32,
    declared_size: u32,
    fragment_size: u16,
    start: u32,
}

/// An RTPS message: header (made-up participant), INFO_DST (any participant), DATA_FRAG
/// carrying fragment `start` (`fragment_size` bytes) of a sample declared
/// `declared_size` bytes. Little-endian submessages.
fn rtps_datafrag(f: &Frag) -> Vec<u8> {
    let mut m = Vec::new();
    m.extend_from_slice(b"RTPS");
    m.extend_from_slice(&[2, 3]); // protocol version 2.3
    m.extend_from_slice(&[0x01, 0x99]); // vendor id: none registered
    m.extend_from_slice(&f.prefix);
    // INFO_DST, flags E, 12 bytes: guid prefix 0 = every participant
    m.extend_from_slice(&[0x0e, 0x01]);
    m.extend_from_slice(&12u16.to_le_bytes());
    m.extend_from_slice(&[0; 12]);
    // DATA_FRAG, flags E
    let payload = vec![0xa5u8; usize::from(f.fragment_size)];
    let body_len = 4 + 28 + payload.len();
    m.extend_from_slice(&[0x16, 0x01]);
    m.extend_from_slice(&(body_len as u16).to_le_bytes());
    m.extend_from_slice(&0u16.to_le_bytes()); // extraFlags
    m.extend_from_slice(&28u16.to_le_bytes()); // octetsToInlineQos
    m.extend_from_slice(&f.reader);
    m.extend_from_slice(&f.writer);
    m.extend_from_slice(&0i32.to_le_bytes()); // writerSN high
    m.extend_from_slice(&f.sn.to_le_bytes()); // writerSN low
    m.extend_from_slice(&f.start.to_le_bytes()); // fragmentStartingNum
    m.extend_from_slice(&1u16.to_le_bytes()); // fragmentsInSubmessage
    m.extend_from_slice(&f.fragment_size.to_le_bytes());
    m.extend_from_slice(&f.declared_size.to_le_bytes()); // sampleSize
    m.extend_from_slice(&payload);
    m
}

fn prefix(k: u32) -> [u8; 12] {
    let mut p = [0xbe, 0xef, 0xba, 0xd0, 0, 0, 0, 0, 0, 0, 0, 0];
    p[4..8].copy_from_slice(&k.to_be_bytes());
    p
}

/// The attack of issue 6 §1, and variants within the node's limits: sent to every port.
/// Returns the number of datagrams sent.
fn attack(ports: &[u16]) -> usize {
    let sock = UdpSocket::bind("127.0.0.1:0").expect("attacker socket");
    let mut frags = Vec::new();
    let builtin = [
        (entity::SPDP_READER, entity::SPDP_WRITER),
        (entity::SEDP_PUB_READER, entity::SEDP_PUB_WRITER),
        (entity::SEDP_SUB_READER, entity::SEDP_SUB_WRITER),
        (entity::P2P_READER, entity::P2P_WRITER),
    ];
    for i in 0..500u32 {
        for (reader, writer) in builtin {
            // ~140-byte packets declaring 1 GiB and 4 GiB - 1 (the reported crash).
            for declared_size in [1 << 30, u32::MAX] {
                frags.push(Frag {
                    prefix: prefix(i % 8),
                    reader,
                    writer,
                    sn: i + 1,
                    declared_size,
                    fragment_size: 64,
                    start: 1,
                });
            }
            // Within the built-in limit, from ever new participants: bounded per reader.
            frags.push(Frag {
                prefix: prefix(1000 + i),
                reader,
                writer,
                sn: 1,
                declared_size: 200 * 1024,
                fragment_size: 1024,
                start: 1 + i % 150,
            });
        }
        // Within the image limit, to guessed user readers and to "any reader": the writer
        // is not matched.
        let key = (i % 64) as u8;
        for reader in [[0, 0, key, 0x04], [0, 0, key, 0x07], entity::UNKNOWN] {
            frags.push(Frag {
                prefix: prefix(i % 8),
                reader,
                writer: entity::USER_WRITER,
                sn: i + 1,
                declared_size: 60 << 20,
                fragment_size: 1024,
                start: 1,
            });
        }
    }
    let mut sent = 0;
    for (n, f) in frags.iter().enumerate() {
        let msg = rtps_datafrag(f);
        for &p in ports {
            if sock
                .send_to(&msg, SocketAddrV4::new(Ipv4Addr::LOCALHOST, p))
                .is_ok()
            {
                sent += 1;
            }
        }
        // Pace so that the kernel's receive buffers do not simply drop the flood.
        if n % 16 == 15 {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    sent
}

struct Peers {
    stop: Arc<AtomicBool>,
    camera: Option<std::thread::JoinHandle<()>>,
    truth: TruthLog,
    gs: GroundStation,
}

impl Drop for Peers {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.camera.take() {
            let _ = h.join();
        }
    }
}

fn peers(domain: u16) -> Peers {
    let settings = RosSettings {
        domain_id: domain,
        ..RosSettings::default()
    };
    let stop = Arc::new(AtomicBool::new(false));
    let seq = SynthParams {
        frames: 200,
        ..SynthParams::default()
    };
    let (camera, truth) = spawn_camera(&settings, seq, 20.0, stop.clone()).unwrap();
    let gs = GroundStation::new(&settings).unwrap();
    Peers {
        stop,
        camera: Some(camera),
        truth,
        gs,
    }
}

/// The node's answer to a reinit with a box of a frame ~100 ms old: success, and the message.
fn reinit(p: &Peers) -> (bool, String) {
    let end = Instant::now() + Duration::from_secs(20);
    loop {
        let recent = {
            let log = p.truth.lock().unwrap();
            let newest = log.keys().next_back().copied();
            let oldest = log.keys().next().copied();
            match (oldest, newest) {
                (Some(o), Some(n)) if n - o > DISCOVERY.as_nanos() as i64 => {
                    log.range(n - 100_000_000..).next().map(|(k, v)| (*k, *v))
                }
                _ => None,
            }
        };
        if let Some((stamp, b)) = recent {
            let req: ReinitRequest =
                bevt_node::convert::reinit_request(b, Time::from_nanos(stamp), "");
            if let Some(r) = p.gs.reinit(&req, Duration::from_secs(5)) {
                // The node keeps the last 30 frames (1.5 s at 20 Hz); a request that reaches
                // it later than that (the service's first request can wait for DDS matching,
                // seconds on a loaded machine) is refused for its stale stamp, the current
                // track kept. A ground station then asks again with a newer frame, as here.
                if r.success || !r.message.contains("no buffered frame") {
                    return (r.success, r.message);
                }
                println!(
                    "reinit refused for a stale stamp, asking again: {}",
                    r.message
                );
            }
        }
        assert!(Instant::now() < end, "no reinit answer from the node");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Detections in `dur`, and how many are within `tol` px of the truth.
fn detections(p: &Peers, dur: Duration, tol: f32) -> (usize, usize) {
    let _ = p.gs.take_detections();
    let end = Instant::now() + dur;
    let (mut n, mut good) = (0, 0);
    while Instant::now() < end {
        for d in p.gs.take_detections() {
            let Some(det) = d.detections.first() else {
                continue;
            };
            n += 1;
            let truth = p
                .truth
                .lock()
                .unwrap()
                .get(&d.header.stamp.as_nanos())
                .copied();
            if truth.is_some_and(|t| bbox_from_detection(det).center().distance(&t.center()) < tol)
            {
                good += 1;
            }
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    (n, good)
}

#[test]
fn crafted_datafrag_floods_leave_the_node_alive_bounded_and_tracking() {
    let d = bevt_tests::dds_domain();
    let mut node = NodeProcess::spawn(d);
    let p = peers(d);
    let (ok, why) = reinit(&p);
    assert!(ok, "the node refused a valid reinit: {why}");
    let (n, good) = detections(&p, Duration::from_secs(2), 5.0);
    assert!(
        n >= 10 && good * 10 >= n * 9,
        "before: {good}/{n} within 5 px"
    );
    let steady = node.memory();
    let ports: Vec<u16> = node.wait_for_sockets().iter().map(|s| s.1).collect();

    let sent = attack(&ports);
    // Let the node drain its sockets, then look.
    std::thread::sleep(Duration::from_millis(500));
    assert!(node.alive(), "the node died under {sent} crafted datagrams");
    let after = node.memory();
    println!("steady {steady:?}, after {sent} datagrams to ports {ports:?}: {after:?}");
    let bound = |steady: u64| 2 * steady + MEMORY_MARGIN_KIB;
    assert!(
        after.peak <= bound(steady.peak) && after.size <= bound(steady.size),
        "virtual memory grew from {steady:?} to {after:?}"
    );
    assert!(
        after.hwm <= bound(steady.hwm) && after.rss <= bound(steady.rss),
        "resident memory grew from {steady:?} to {after:?}"
    );

    // Still tracking, on the same track.
    let (n, good) = detections(&p, Duration::from_secs(2), 5.0);
    println!("after the flood: {good}/{n} detections within 5 px");
    assert!(
        n >= 10 && good * 10 >= n * 9,
        "after: {good}/{n} within 5 px"
    );
    assert!(node.alive());
}

#[test]
fn with_loopback_configured_no_socket_listens_elsewhere() {
    let node = NodeProcess::spawn(bevt_tests::dds_domain());
    let sockets = node.wait_for_sockets();
    println!("node sockets: {sockets:?}");
    for (addr, port) in &sockets {
        assert_eq!(addr, "127.0.0.1", "socket on {addr}:{port}");
    }
    // Over the wire: another loopback address (which a wildcard socket would accept)
    // reaches no socket of the node, so the kernel refuses the datagram.
    for (_, port) in &sockets {
        let probe = UdpSocket::bind("127.0.0.2:0").expect("probe socket");
        probe
            .set_read_timeout(Some(Duration::from_secs(2)))
            .unwrap();
        probe.connect(("127.0.0.2", *port)).unwrap();
        let msg = rtps_datafrag(&Frag {
            prefix: prefix(7),
            reader: entity::SPDP_READER,
            writer: entity::SPDP_WRITER,
            sn: 1,
            declared_size: 1 << 30,
            fragment_size: 64,
            start: 1,
        });
        let refused = probe.send(&msg).is_ok()
            && matches!(
                probe.recv(&mut [0u8; 16]).map_err(|e| e.kind()),
                Err(ErrorKind::ConnectionRefused)
            );
        assert!(refused, "127.0.0.2:{port} was not refused");
    }
}
